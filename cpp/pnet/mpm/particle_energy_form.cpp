#include "pnet/mpm/particle_energy_form.hpp"

#include <stdexcept>
#include <chrono>

#include "pnet/math/clock.hpp"
#include "pnet/mpm/incremental_potential.hpp"

namespace pnet {

template <int dim>
void ParticleEnergyForm<dim>::begin_step(std::size_t particles) {
    F_.resize(particles);
    P_.resize(particles);
    psi_.resize(particles);
    K_.resize(particles);
    particle_product_.resize(particles);
    energy_seconds_ = multiply_seconds_ = 0.0;
    energy_.begin_step();
}

template <int dim>
double ParticleEnergyForm<dim>::potential_sum() const {
    const std::vector<double>& volume = problem_.particles().rest_volume;
    double sum = 0.0;
    for (std::size_t p = 0; p < psi_.size(); ++p) sum += volume[p] * psi_[p];
    return sum;
}

template <int dim>
double ParticleEnergyForm<dim>::value(const VecX& v) {
    const auto start = std::chrono::steady_clock::now();
    problem_.deformation(v, F_);
    energy_.evaluate(F_, ParticleEnergy<dim>::Order::Value, psi_.data(), nullptr, nullptr);
    energy_seconds_ += seconds_since(start);
    return potential_sum();
}

template <int dim>
void ParticleEnergyForm<dim>::scatter_gradient(VecX& gradient) const {
    // dpsi/dG = V0 dt P F^E^T per particle; per node, the sum over its stencil entries (p, s) of
    // that times grad w_ip, in the entries' fixed order (two passes, one barrier, as the product).
    const Particles<dim>& particles = problem_.particles();
    const double dt = problem_.dt();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
    const std::ptrdiff_t nodes = static_cast<std::ptrdiff_t>(problem_.nodes());
    const int* entry_start = problem_.node_entry_start();
    const int* entry_particle = problem_.node_entry_particles();
    const Vec<dim>* entry_grad = problem_.node_entry_gradients();
    particle_force_.resize(n);
    double* g = gradient.data();
#pragma omp parallel
    {
#pragma omp for schedule(static)
        for (std::ptrdiff_t p = 0; p < n; ++p)
            particle_force_[p].noalias() =
                (particles.rest_volume[p] * dt) * (P_[p] * particles.F_elastic[p].transpose());
#pragma omp for schedule(static)
        for (std::ptrdiff_t k = 0; k < nodes; ++k) {
            Vec<dim> sum = Vec<dim>::Zero();
            for (int e = entry_start[k]; e < entry_start[k + 1]; ++e)
                sum.noalias() += particle_force_[entry_particle[e]] * entry_grad[e];
            Eigen::Map<Vec<dim>>(g + dim * k) += sum;
        }
    }
}

template <int dim>
double ParticleEnergyForm<dim>::add_gradient(const VecX& v, VecX& g) {
    const auto start = std::chrono::steady_clock::now();
    problem_.deformation(v, F_);
    energy_.evaluate(F_, ParticleEnergy<dim>::Order::Gradient, psi_.data(), P_.data(), nullptr);
    energy_seconds_ += seconds_since(start);
    scatter_gradient(g);
    return potential_sum();
}

template <int dim>
void ParticleEnergyForm<dim>::transform_hessians() {
    // K_p = V0 dt^2 T^T H T with T the map vec(dG) -> vec(dG F^E). In the
    // row-major basis T = I (x) F^E^T is block diagonal, so the d x d block
    // (a, b) of K is V0 dt^2 F^E H_ab F^E^T: 2 d^5 flops instead of 4 d^6.
    const Particles<dim>& particles = problem_.particles();
    const double dt = problem_.dt();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const Mat<dim> FE = particles.F_elastic[p];
        const double scale = particles.rest_volume[p] * dt * dt;
        Tensor4<dim>& K = K_[p];
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b) {
                const Mat<dim> block = scale * (FE * K.template block<dim, dim>(a * dim, b * dim) * FE.transpose());
                K.template block<dim, dim>(a * dim, b * dim) = block;
            }
    }
}

template <int dim>
void ParticleEnergyForm<dim>::set_hessians(const std::vector<Tensor4<dim>>& hessians) {
    if (hessians.size() != K_.size())
        throw std::invalid_argument("ParticleEnergyForm::set_hessians: one Hessian per particle is needed");
    K_ = hessians;
    transform_hessians();
}

template <int dim>
void ParticleEnergyForm<dim>::prepare_hessian(const VecX& v) {
    const auto start = std::chrono::steady_clock::now();
    problem_.deformation(v, F_);
    energy_.evaluate(F_, ParticleEnergy<dim>::Order::Hessian, psi_.data(), P_.data(), K_.data(), project_psd_);
    transform_hessians();
    energy_seconds_ += seconds_since(start);
}

template <int dim>
double ParticleEnergyForm<dim>::add_gradient_hessian(const VecX& v, VecX& g) {
    prepare_hessian(v);  // the Hessian pass also leaves psi and P at v
    scatter_gradient(g);
    return potential_sum();
}

template <int dim>
void ParticleEnergyForm<dim>::add_hessian_multiply(const VecX& d, VecX& out) const {
    // Two passes without write conflicts in one parallel region (a barrier after the masking and one
    // after the particles; the colour passes of for_each_particle_coloured cost 2^d barriers):
    // y_p = K_p dG_p per particle, with dG_p the velocity gradient of the masked d on p's stencil; then
    // per node, sum over its stencil entries (p, s) of the d rows of y_p dotted with grad w_ip, in a
    // fixed order (IncrementalPotential::node_entry_start()).
    const auto start = std::chrono::steady_clock::now();
    const VecX& free = problem_.free_components();
    masked_.resize(d.size());
    if (held_product_.size() != d.size()) held_product_.setZero(d.size());
    double* dm = masked_.data();
    const double* dd = d.data();
    const double* fr = free.data();
    const std::ptrdiff_t components = d.size();
    double* o = out.data();
    double* held = held_product_.data();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(K_.size());
    const std::ptrdiff_t nodes = static_cast<std::ptrdiff_t>(problem_.nodes());
    const int* entry_start = problem_.node_entry_start();
    const int* entry_particle = problem_.node_entry_particles();
    const Vec<dim>* entry_grad = problem_.node_entry_gradients();
#pragma omp parallel
    {
#pragma omp for schedule(static)
        for (std::ptrdiff_t i = 0; i < components; ++i) dm[i] = dd[i] * fr[i];
#pragma omp for schedule(static)
        for (std::ptrdiff_t p = 0; p < n; ++p) {
            Eigen::Matrix<double, kM, 1> dG = Eigen::Matrix<double, kM, 1>::Zero();
            const int* dof = problem_.stencil_dofs(p);
            const Vec<dim>* grad = problem_.stencil_gradients(p);
            for (int s = 0; s < kStencil; ++s) {
                const Eigen::Map<const Vec<dim>> di(dm + dim * dof[s]);
                for (int a = 0; a < dim; ++a) dG.template segment<dim>(a * dim) += di[a] * grad[s];
            }
            particle_product_[p].noalias() = K_[p] * dG;
        }
#pragma omp for schedule(static)
        for (std::ptrdiff_t k = 0; k < nodes; ++k) {
            // Row a of the sum is sum_e y_e[a d .. a d + d) . g_e: accumulated elementwise against g_e
            // repeated d times (vertical adds only), reduced once per node.
            Eigen::Matrix<double, kM, 1> terms = Eigen::Matrix<double, kM, 1>::Zero();
            for (int e = entry_start[k]; e < entry_start[k + 1]; ++e)
                terms.noalias() +=
                    particle_product_[entry_particle[e]].cwiseProduct(entry_grad[e].template replicate<dim, 1>());
            for (int a = 0; a < dim; ++a) {
                const Eigen::Index i = dim * k + a;
                const double sum = terms.template segment<dim>(a * dim).sum();
                if (free[i] > 0.0)
                    o[i] += sum;
                else
                    held[i] = sum;
            }
        }
    }
    multiply_seconds_ += seconds_since(start);
}

template <int dim>
template <bool kDiagonalOnly>
void ParticleEnergyForm<dim>::node_entries(VecX& out) const {
    // Per node, its d x d block (row-major) or the block's diagonal alone (the same sums in the
    // same order): d = e_b at the node gives dG = e_b g^T, so entry (a, b) is g^T K[(a, .), (b, .)] g.
    // A gather per node over its stencil entries in their fixed order (no write conflicts).
    constexpr int kPerNode = kDiagonalOnly ? dim : dim * dim;
    const std::ptrdiff_t nodes = static_cast<std::ptrdiff_t>(problem_.nodes());
    out.resize(nodes * kPerNode);
    double* values = out.data();
    const int* entry_start = problem_.node_entry_start();
    const int* entry_particle = problem_.node_entry_particles();
    const Vec<dim>* entry_grad = problem_.node_entry_gradients();
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < nodes; ++k) {
        double B[kPerNode] = {};
        for (int e = entry_start[k]; e < entry_start[k + 1]; ++e) {
            const Tensor4<dim>& K = K_[entry_particle[e]];
            const Vec<dim>& g = entry_grad[e];
            for (int a = 0; a < dim; ++a)
                for (int b = kDiagonalOnly ? a : 0; b < (kDiagonalOnly ? a + 1 : dim); ++b)
                    B[kDiagonalOnly ? a : a * dim + b] += g.dot(K.template block<dim, dim>(a * dim, b * dim) * g);
        }
        for (int i = 0; i < kPerNode; ++i) values[kPerNode * k + i] = B[i];
    }
}

template <int dim>
void ParticleEnergyForm<dim>::node_blocks(VecX& blocks) const {
    node_entries<false>(blocks);
}

template <int dim>
void ParticleEnergyForm<dim>::node_diagonal(VecX& diagonal) const {
    node_entries<true>(diagonal);
}

template <int dim>
void ParticleEnergyForm<dim>::add_hessian_diagonal(VecX& diagonal) const {
    node_diagonal(scratch_);
    const VecX& free = problem_.free_components();
    for (Eigen::Index i = 0; i < diagonal.size(); ++i) diagonal[i] += scratch_[i] * free[i];
}

template <int dim>
void ParticleEnergyForm<dim>::add_hessian_block_diagonal(VecX& blocks) const {
    constexpr int kB = dim * dim;
    node_blocks(scratch_);
    const VecX& free = problem_.free_components();
    const Eigen::Index nodes = free.size() / dim;
#pragma omp parallel for schedule(static)
    for (Eigen::Index k = 0; k < nodes; ++k)
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b)
                blocks[kB * k + a * dim + b] += scratch_[kB * k + a * dim + b] * (free[dim * k + a] * free[dim * k + b]);
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
void ParticleEnergyForm<dim>::compute_pair_blocks() const {
    constexpr int kOffsets = kPairOffsets;
    constexpr int kB = dim * dim;
    const std::size_t nodes = problem_.nodes();
    pair_dof_.assign(nodes * kOffsets, -1);
    pair_block_.assign(nodes * kOffsets * kB, 0.0);
    problem_.grid().for_each_particle_coloured([&](int p) {
        const Tensor4<dim>& K = K_[p];
        const int* dof = problem_.stencil_dofs(p);
        const Vec<dim>* grad = problem_.stencil_gradients(p);
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
}

template <int dim>
void ParticleEnergyForm<dim>::add_hessian_triplets(std::vector<Triplet>& triplets) const {
    constexpr int kOffsets = kPairOffsets;
    constexpr int kB = dim * dim;
    const std::size_t nodes = problem_.nodes();
    const VecX& free = problem_.free_components();
    compute_pair_blocks();
    triplets.reserve(triplets.size() + nodes * kOffsets * kB / 2);
    for (std::size_t k = 0; k < nodes; ++k)
        for (int o = 0; o < kOffsets; ++o) {
            const int j = pair_dof_[k * kOffsets + o];
            if (j < 0) continue;
            const double* B = &pair_block_[(k * kOffsets + o) * kB];
            for (int a = 0; a < dim; ++a)
                for (int b = 0; b < dim; ++b) {
                    const Eigen::Index row = dim * k + a, col = dim * j + b;
                    if (free[row] > 0.0 && free[col] > 0.0) triplets.emplace_back(row, col, B[a * dim + b]);
                }
        }
}

template class ParticleEnergyForm<2>;
template class ParticleEnergyForm<3>;

}  // namespace pnet
