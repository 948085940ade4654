#include "pnet/mpm/incremental_potential.hpp"

#include "pnet/math/clock.hpp"

#include <chrono>

#include "pnet/mpm/transfer.hpp"

namespace pnet {

template <int dim>
void IncrementalPotential<dim>::begin_step(const Grid<dim>& grid, const Particles<dim>& particles, double dt,
                                           const BoundaryConditions& bc) {
    grid_ = &grid;
    particles_ = &particles;
    dt_ = step_dt_ = dt;
    bdf2_ = false;
    energy_seconds_ = multiply_seconds_ = 0.0;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());

    // Stencils (storage indices for now) and weight gradients.
    stencil_dof_.resize(n * kStencil);
    stencil_grad_.resize(n * kStencil);
    stencil_weight_.resize(n * kStencil);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const StencilNodes<dim> st(grid, particles.x[p]);
        int s = 0;
        st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Vec<dim>&) {
            stencil_dof_[p * kStencil + s] = static_cast<int>(node);
            stencil_grad_[p * kStencil + s] = grad;
            stencil_weight_[p * kStencil + s] = w;
            ++s;
        });
    }

    // Unknowns: the nodes some stencil reaches, numbered in storage order. Only
    // the last step's unknowns are cleared (the map spans the whole grid).
    if (static_cast<std::int64_t>(node_dof_.size()) != grid.storage_size())
        node_dof_.assign(grid.storage_size(), -1);
    else
        for (std::int64_t node : dof_node_) node_dof_[node] = -1;
    for (int node : stencil_dof_) node_dof_[node] = 0;
    dof_node_.clear();
    constexpr int kBlockNodes = Grid<dim>::kBlockNodes;
    for (int block : grid.active_blocks())
        for (int k = 0; k < kBlockNodes; ++k) {
            const std::int64_t node = static_cast<std::int64_t>(block) * kBlockNodes + k;
            if (node_dof_[node] == 0) {
                node_dof_[node] = static_cast<int>(dof_node_.size());
                dof_node_.push_back(node);
            }
        }
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < n * kStencil; ++i) stencil_dof_[i] = node_dof_[stencil_dof_[i]];

    const std::ptrdiff_t dofs = static_cast<std::ptrdiff_t>(dof_node_.size());
    // Stencil entries by node (a counting sort, stable in p * kStencil + s): the order in which
    // hessian_multiply sums a node's terms, the same for every thread count.
    node_entry_start_.assign(dofs + 1, 0);
    for (int k : stencil_dof_) ++node_entry_start_[k + 1];
    for (std::ptrdiff_t k = 0; k < dofs; ++k) node_entry_start_[k + 1] += node_entry_start_[k];
    node_entries_.resize(stencil_dof_.size());
    {
        std::vector<int> next(node_entry_start_.begin(), node_entry_start_.end() - 1);
        for (std::size_t e = 0; e < stencil_dof_.size(); ++e)
            node_entries_[next[stencil_dof_[e]]++] = static_cast<int>(e);
    }
    particle_product_.resize(n);
    mass_.resize(dim * dofs);
    v_star_.resize(dim * dofs);
    free_.resize(dim * dofs);
    residual_scale_.resize(dim * dofs);
    residual_mass_.resize(dim * dofs);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < dofs; ++k) {
        const typename Grid<dim>::Node& node = grid.node(dof_node_[k]);
        int coord[dim];
        bool fixed[dim];
        grid.coordinates(dof_node_[k], coord);
        grid.constrained_components(coord, fixed, bc);
        const bool massless = !(node.mass > 0.0);  // a stencil node with weight exactly 0
        for (int a = 0; a < dim; ++a) {
            const Eigen::Index i = dim * k + a;
            mass_[i] = massless ? 1.0 : node.mass;
            v_star_[i] = massless ? 0.0 : node.momentum[a];
            free_[i] = (fixed[a] || massless) ? 0.0 : 1.0;
            residual_scale_[i] = free_[i] / mass_[i];
            residual_mass_[i] = free_[i] * mass_[i];
        }
    }
    F_.resize(n);
    P_.resize(n);
    psi_.resize(n);
    K_.resize(n);
    masked_.resize(dim * dofs);
}

template <int dim>
void IncrementalPotential<dim>::use_bdf2(const VecX& u, const VecX& v_previous, const Vec<dim>& gravity) {
    const double beta = 2.0 / 3.0, dt = step_dt_;
    offset_.resize(v_star_.size());
    for (Eigen::Index i = 0; i < v_star_.size(); ++i) {
        const double g = gravity[i % dim];
        if (free_[i] > 0.0) v_star_[i] = (4.0 * (v_star_[i] - dt * g) - v_previous[i]) / 3.0 + beta * dt * g;
        offset_[i] = free_[i] * 0.5 * u[i];
    }
    dt_ = beta * dt;
    bdf2_ = true;
}

template <int dim>
void IncrementalPotential<dim>::grid_field(const Grid<dim>& grid, VecX& out) const {
    const std::ptrdiff_t dofs = static_cast<std::ptrdiff_t>(dof_node_.size());
    out.resize(dim * dofs);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < dofs; ++k) {
        const typename Grid<dim>::Node& node = grid.node(dof_node_[k]);
        out.template segment<dim>(dim * k) = node.mass > 0.0 ? Vec<dim>(node.momentum / node.mass) : Vec<dim>::Zero();
    }
}

template <int dim>
const VecX& IncrementalPotential<dim>::displacement_rate(const VecX& v) {
    if (!bdf2_) return v;
    rate_ = (dt_ / step_dt_) * (v + offset_);
    return rate_;
}

template <int dim>
void IncrementalPotential<dim>::deformation(const VecX& v, std::vector<Mat<dim>>& F) const {
    const Particles<dim>& particles = *particles_;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
    F.resize(n);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        Mat<dim> G = Mat<dim>::Zero();
        for (int s = 0; s < kStencil; ++s) {
            const int k = stencil_dof_[p * kStencil + s];
            Vec<dim> vi = v.template segment<dim>(dim * k);
            if (bdf2_) vi += offset_.template segment<dim>(dim * k);
            G.noalias() += vi * stencil_grad_[p * kStencil + s].transpose();
        }
        F[p] = particles.F_elastic[p] + dt_ * (G * particles.F_elastic[p]);
    }
}

template <int dim>
void IncrementalPotential<dim>::set_reference(const std::vector<Mat<dim>>& F0) {
    energy_.set_reference(F0, particles_->hardening, particles_->object);
}

template <int dim>
void IncrementalPotential<dim>::write_velocity(const VecX& v, Grid<dim>& grid) const {
    const std::ptrdiff_t dofs = static_cast<std::ptrdiff_t>(dof_node_.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < dofs; ++k) grid.node(dof_node_[k]).momentum = v.template segment<dim>(dim * k);
}

template <int dim>
double IncrementalPotential<dim>::inertia(const VecX& v) const {
    return 0.5 * (v - v_star_).cwiseAbs2().dot(mass_.cwiseProduct(free_));
}

template <int dim>
double IncrementalPotential<dim>::potential_sum() const {
    // In particle order, serially: the sum must not depend on the thread count.
    double sum = 0.0;
    for (std::size_t p = 0; p < psi_.size(); ++p) sum += particles_->rest_volume[p] * psi_[p];
    return sum;
}

template <int dim>
double IncrementalPotential<dim>::value(const VecX& v) {
    const auto start = std::chrono::steady_clock::now();
    deformation(v, F_);
    energy_.evaluate(F_, ParticleEnergy<dim>::Order::Value, psi_.data(), nullptr, nullptr);
    energy_seconds_ += seconds_since(start);
    return inertia(v) + potential_sum();
}

template <int dim>
void IncrementalPotential<dim>::assemble_gradient(const VecX& v, VecX& gradient) const {
    const Particles<dim>& particles = *particles_;
    gradient = mass_.cwiseProduct(v - v_star_);
    double* g = gradient.data();
    grid_->for_each_particle_coloured([&](int p) {
        // dpsi/dG = dt P F^E^T; its product with grad w is the node force.
        const Mat<dim> Q = (particles.rest_volume[p] * dt_) * (P_[p] * particles.F_elastic[p].transpose());
        for (int s = 0; s < kStencil; ++s) {
            Eigen::Map<Vec<dim>> gi(g + dim * stencil_dof_[p * kStencil + s]);
            gi.noalias() += Q * stencil_grad_[p * kStencil + s];
        }
    });
    gradient.array() *= free_.array();
}

template <int dim>
void IncrementalPotential<dim>::transform_hessians() {
    // K_p = V0 dt^2 T^T H T with T the map vec(dG) -> vec(dG F^E). In the
    // row-major basis T = I (x) F^E^T is block diagonal, so the d x d block
    // (a, b) of K is V0 dt^2 F^E H_ab F^E^T: 2 d^5 flops instead of 4 d^6.
    const Particles<dim>& particles = *particles_;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const Mat<dim> FE = particles.F_elastic[p];
        const double scale = particles.rest_volume[p] * dt_ * dt_;
        Tensor4<dim>& K = K_[p];
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b) {
                const Mat<dim> block = scale * (FE * K.template block<dim, dim>(a * dim, b * dim) * FE.transpose());
                K.template block<dim, dim>(a * dim, b * dim) = block;
            }
    }
}

template <int dim>
double IncrementalPotential<dim>::value_gradient(const VecX& v, VecX& gradient) {
    const auto start = std::chrono::steady_clock::now();
    deformation(v, F_);
    energy_.evaluate(F_, ParticleEnergy<dim>::Order::Gradient, psi_.data(), P_.data(), nullptr);
    energy_seconds_ += seconds_since(start);
    assemble_gradient(v, gradient);
    return inertia(v) + potential_sum();
}

template <int dim>
void IncrementalPotential<dim>::prepare_hessian(const VecX& v) {
    const auto start = std::chrono::steady_clock::now();
    deformation(v, F_);
    energy_.evaluate(F_, ParticleEnergy<dim>::Order::Hessian, psi_.data(), P_.data(), K_.data(), project_psd_);
    transform_hessians();
    energy_seconds_ += seconds_since(start);
    if (assemble_) {
        triplets_.clear();
        add_hessian_triplets(triplets_, 0);
        hessian_.resize(size(), size());
        hessian_.setFromTriplets(triplets_.begin(), triplets_.end());  // duplicates summed in triplet order
    }
}

template <int dim>
double IncrementalPotential<dim>::value_gradient_hessian(const VecX& v, VecX& gradient) {
    prepare_hessian(v);  // the Hessian pass also leaves psi and P at v
    assemble_gradient(v, gradient);
    return inertia(v) + potential_sum();
}

template <int dim>
void IncrementalPotential<dim>::hessian_multiply(const VecX& d, VecX& out) const {
    // Two passes without write conflicts (one parallel region, one barrier; the colour passes of
    // for_each_particle_coloured cost 2^d barriers): y_p = K_p dG_p per particle, with dG_p the
    // velocity gradient of the masked d on p's stencil; then per node, sum over its stencil entries
    // (p, s) of the d rows of y_p dotted with grad w_ip, in a fixed order (node_entries_).
    const auto start = std::chrono::steady_clock::now();
    masked_ = d.cwiseProduct(free_);
    out.resize(d.size());
    const double* dm = masked_.data();
    double* o = out.data();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(K_.size());
    const std::ptrdiff_t nodes = static_cast<std::ptrdiff_t>(dof_node_.size());
#pragma omp parallel
    {
#pragma omp for schedule(static)
        for (std::ptrdiff_t p = 0; p < n; ++p) {
            Eigen::Matrix<double, kM, 1> dG = Eigen::Matrix<double, kM, 1>::Zero();
            const int* dof = &stencil_dof_[p * kStencil];
            const Vec<dim>* grad = &stencil_grad_[p * kStencil];
            for (int s = 0; s < kStencil; ++s) {
                const Eigen::Map<const Vec<dim>> di(dm + dim * dof[s]);
                for (int a = 0; a < dim; ++a) dG.template segment<dim>(a * dim) += di[a] * grad[s];
            }
            particle_product_[p].noalias() = K_[p] * dG;
        }
#pragma omp for schedule(static)
        for (std::ptrdiff_t k = 0; k < nodes; ++k) {
            Vec<dim> sum = Vec<dim>::Zero();
            for (int e = node_entry_start_[k]; e < node_entry_start_[k + 1]; ++e) {
                const int entry = node_entries_[e];
                const Eigen::Matrix<double, kM, 1>& y = particle_product_[entry / kStencil];
                const Vec<dim>& g = stencil_grad_[entry];
                for (int a = 0; a < dim; ++a) sum[a] += y.template segment<dim>(a * dim).dot(g);
            }
            for (int a = 0; a < dim; ++a) {
                const Eigen::Index i = dim * k + a;
                o[i] = sum[a] * free_[i] + mass_[i] * d[i];
            }
        }
    }
    multiply_seconds_ += seconds_since(start);
}

template <int dim>
void IncrementalPotential<dim>::hessian_diagonal(VecX& diagonal) const {
    diagonal.setZero(size());
    double* diag = diagonal.data();
    grid_->for_each_particle_coloured([&](int p) {
        const Tensor4<dim>& K = K_[p];
        for (int s = 0; s < kStencil; ++s) {
            const Vec<dim>& g = stencil_grad_[p * kStencil + s];
            double* di = diag + dim * stencil_dof_[p * kStencil + s];
            // d = e_a at this node: dG = e_a g^T, so the entry is g^T K[(a, .), (a, .)] g.
            for (int a = 0; a < dim; ++a) di[a] += g.dot(K.template block<dim, dim>(a * dim, a * dim) * g);
        }
    });
    diagonal.array() = diagonal.array() * free_.array() + mass_.array();
}

template <int dim>
void IncrementalPotential<dim>::hessian_block_diagonal(VecX& blocks) const {
    constexpr int kB = dim * dim;
    blocks.setZero(size() * dim);
    double* out = blocks.data();
    grid_->for_each_particle_coloured([&](int p) {
        const Tensor4<dim>& K = K_[p];
        for (int s = 0; s < kStencil; ++s) {
            const Vec<dim>& g = stencil_grad_[p * kStencil + s];
            double* B = out + kB * stencil_dof_[p * kStencil + s];  // row-major
            for (int a = 0; a < dim; ++a)
                for (int b = 0; b < dim; ++b) B[a * dim + b] += g.dot(K.template block<dim, dim>(a * dim, b * dim) * g);
        }
    });
    const Eigen::Index nodes = size() / dim;
#pragma omp parallel for schedule(static)
    for (Eigen::Index k = 0; k < nodes; ++k) {
        double* B = out + kB * k;
        for (int a = 0; a < dim; ++a) {
            for (int b = 0; b < dim; ++b) B[a * dim + b] *= free_[dim * k + a] * free_[dim * k + b];
            B[a * dim + a] += mass_[dim * k + a];
        }
    }
}

template <int dim>
void IncrementalPotential<dim>::particle_positions(const VecX& v, std::vector<Vec<dim>>& X, bool displacement) const {
    const Particles<dim>& particles = *particles_;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
    X.resize(n);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        Vec<dim> sum = Vec<dim>::Zero();
        for (int s = 0; s < kStencil; ++s) {
            const int k = stencil_dof_[p * kStencil + s];
            Vec<dim> vi = v.template segment<dim>(dim * k);
            if (bdf2_ && !displacement) vi += offset_.template segment<dim>(dim * k);
            sum += stencil_weight_[p * kStencil + s] * vi;
        }
        X[p] = displacement ? Vec<dim>(dt_ * sum) : Vec<dim>(particles.x[p] + dt_ * sum);
    }
}

namespace {

/// Index of the offset t - s (each axis in [-2, 2]) of two nodes of a 3^d stencil,
/// s and t in StencilNodes::for_each order, among the 5^d offsets.
template <int dim>
constexpr int stencil_offset(int s, int t) {
    int index = 0;
    for (int a = dim - 1, scale = 1, ss = s, tt = t; a >= 0; --a, scale *= 5, ss /= 3, tt /= 3)
        index += (tt % 3 - ss % 3 + 2) * scale;
    return index;
}

}  // namespace

template <int dim>
void IncrementalPotential<dim>::add_hessian_triplets(std::vector<Eigen::Triplet<double>>& triplets,
                                                     Eigen::Index offset) const {
    constexpr int kOffsets = dim == 2 ? 25 : 125;
    constexpr int kB = dim * dim;
    const std::size_t nodes = dof_node_.size();
    pair_dof_.assign(nodes * kOffsets, -1);
    pair_block_.assign(nodes * kOffsets * kB, 0.0);
    grid_->for_each_particle_coloured([&](int p) {
        const Tensor4<dim>& K = K_[p];
        const int* dof = &stencil_dof_[p * kStencil];
        const Vec<dim>* grad = &stencil_grad_[p * kStencil];
        for (int t = 0; t < kStencil; ++t) {
            // W(a d + c, b) = sum_e K(a d + c, b d + e) g_t[e]; block (s, t)(a, b) = sum_c g_s[c] W(a d + c, b).
            Eigen::Matrix<double, kM, dim> W;
            for (int b = 0; b < dim; ++b) W.col(b) = K.template middleCols<dim>(b * dim) * grad[t];
            for (int s = 0; s < kStencil; ++s) {
                const int slot = dof[s] * kOffsets + stencil_offset<dim>(s, t);
                pair_dof_[slot] = dof[t];
                double* B = &pair_block_[static_cast<std::size_t>(slot) * kB];
                for (int a = 0; a < dim; ++a)
                    for (int b = 0; b < dim; ++b) B[a * dim + b] += grad[s].dot(W.template block<dim, 1>(a * dim, b));
            }
        }
    });
    triplets.reserve(triplets.size() + nodes * kOffsets * kB / 2 + size());
    for (std::size_t k = 0; k < nodes; ++k)
        for (int o = 0; o < kOffsets; ++o) {
            const int j = pair_dof_[k * kOffsets + o];
            if (j < 0) continue;
            const double* B = &pair_block_[(k * kOffsets + o) * kB];
            for (int a = 0; a < dim; ++a)
                for (int b = 0; b < dim; ++b) {
                    const Eigen::Index row = dim * k + a, col = dim * j + b;
                    if (free_[row] > 0.0 && free_[col] > 0.0)
                        triplets.emplace_back(offset + row, offset + col, B[a * dim + b]);
                }
        }
    for (Eigen::Index i = 0; i < size(); ++i) triplets.emplace_back(offset + i, offset + i, mass_[i]);
}

template class IncrementalPotential<2>;
template class IncrementalPotential<3>;

}  // namespace pnet
