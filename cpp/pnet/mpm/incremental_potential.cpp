#include "pnet/mpm/incremental_potential.hpp"

#include "pnet/mpm/transfer.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "pnet/contact/friction.hpp"
#include "pnet/solver/bdf2.hpp"

namespace pnet {

template <int dim>
void IncrementalPotential<dim>::begin_step(const Grid<dim>& grid, const Particles<dim>& particles, double dt,
                                           const BoundaryConditions& bc) {
    grid_ = &grid;
    particles_ = &particles;
    dt_ = step_dt_ = dt;
    bdf2_ = false;
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
    // Stencil entries by node (a counting sort, stable in p * kStencil + s): the order in which a node's
    // gathers sum its terms, the same for every thread count; each entry's particle and weight gradient
    // stored in that order.
    node_entry_start_.assign(dofs + 1, 0);
    for (int k : stencil_dof_) ++node_entry_start_[k + 1];
    for (std::ptrdiff_t k = 0; k < dofs; ++k) node_entry_start_[k + 1] += node_entry_start_[k];
    node_entry_particle_.resize(stencil_dof_.size());
    node_entry_grad_.resize(stencil_dof_.size());
    {
        std::vector<int> next(node_entry_start_.begin(), node_entry_start_.end() - 1);
        for (std::size_t e = 0; e < stencil_dof_.size(); ++e) {
            const int slot = next[stencil_dof_[e]]++;
            node_entry_particle_[slot] = static_cast<int>(e / kStencil);
            node_entry_grad_[slot] = stencil_grad_[e];
        }
    }
    VecX& mass = inertia_.mass();
    VecX& v_star = inertia_.target();
    VecX& free = this->free_;
    mass.resize(dim * dofs);
    v_star.resize(dim * dofs);
    inertia_.weight().setOnes(dim * dofs);
    free.resize(dim * dofs);
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
        // The Coulomb floor holds a node's normal velocity at 0 where it presses into the floor (v*
        // comes unprojected there, see floor_friction_contacts()); one moving away is free.
        const bool on_floor = bc.coulomb_floor() && bc.in_floor(coord[1]) && !massless;
        if (on_floor) fixed[1] = node.momentum[1] <= 0.0;
        for (int a = 0; a < dim; ++a) {
            const Eigen::Index i = dim * k + a;
            mass[i] = massless ? 1.0 : node.mass;
            v_star[i] = massless ? 0.0 : node.momentum[a];
            if (on_floor && a == 1 && fixed[1]) v_star[i] = 0.0;
            free[i] = (fixed[a] || massless) ? 0.0 : 1.0;
            residual_scale_[i] = free[i] / mass[i];
            residual_mass_[i] = free[i] * mass[i];
        }
    }
    // The Coulomb floor's contacts: the nodes whose normal velocity is held, in dof order, with the
    // normal velocity v* had (what the floor stops); their friction comes with floor_friction_contacts().
    floor_friction_ = bc.coulomb_floor() ? bc.floor_friction : -1.0;
    floor_dofs_.clear();
    floor_normal_velocity_.clear();
    if (bc.coulomb_floor())
        for (std::ptrdiff_t k = 0; k < dofs; ++k) {
            int coord[dim];
            grid.coordinates(dof_node_[k], coord);
            const typename Grid<dim>::Node& node = grid.node(dof_node_[k]);
            if (bc.in_floor(coord[1]) && node.mass > 0.0 && free[dim * k + 1] == 0.0) {
                floor_dofs_.push_back(static_cast<int>(k));
                floor_normal_velocity_.push_back(node.momentum[1]);
            }
        }
    floor_friction_form_.begin_step({}, free);
    if (bc.coulomb_floor() && floor_friction_newton_)
        floor_friction_form_.begin_newton(floor_dofs_, floor_normal_velocity_, mass, bc.floor_friction,
                                          0.1 * grid.dx(), free, particle_energy_.held_product());
    if (bc.coulomb_floor()) this->set_forms({&inertia_, &particle_energy_, &floor_friction_form_});
    else this->set_forms({&inertia_, &particle_energy_});
    particle_energy_.begin_step(particles.size());
    this->invalidate_pattern();  // a new grid
    multigrid_built_ = multigrid_stale_ = false;
}

template <int dim>
void IncrementalPotential<dim>::hessian_prepared(const VecX& /*x*/) {
    if (multigrid_on_ && multigrid_built_ && multigrid_per_hessian_) multigrid_stale_ = true;
}

template <int dim>
void IncrementalPotential<dim>::apply_preconditioner(const VecX& r, VecX& z) const {
    if (!multigrid_built_ || multigrid_stale_) build_multigrid();
    multigrid_.apply(r, z);
}

template <int dim>
void IncrementalPotential<dim>::build_multigrid() const {
    if (!multigrid_built_) {  // this step's grid
        std::vector<int> coordinates(dim * dof_node_.size());
        for (std::size_t k = 0; k < dof_node_.size(); ++k) grid_->coordinates(dof_node_[k], &coordinates[dim * k]);
        multigrid_.set_grid(dim, coordinates, this->free_);
    }
    const SparseMatrix* assembled = this->hessian_matrix();
    if (!assembled) {
        assemble_by_nodes(multigrid_matrix_);
        assembled = &multigrid_matrix_;
    }
    multigrid_.set_operator(*assembled, this->hessian_symmetric());
    multigrid_built_ = true;
    multigrid_stale_ = false;
}

template <int dim>
void IncrementalPotential<dim>::assemble_by_nodes(SparseMatrix& out) const {
    // H^T in column-major storage (H's rows as columns; H itself where it is symmetric): column
    // d k + a holds row d k + a of H, its entries sorted by the neighbour's dof. Built node by node
    // from the particle form's pair blocks, without triplets: the inertia's mass and the Coulomb
    // floor's friction (both on the diagonal) added in place; fixed components keep their mass alone.
    constexpr int kOffsets = ParticleEnergyForm<dim>::kPairOffsets;
    particle_energy_.compute_pair_blocks();
    const std::vector<int>& pair_dof = particle_energy_.pair_dofs();
    const std::vector<double>& pair_block = particle_energy_.pair_blocks();
    const std::ptrdiff_t nodes = static_cast<std::ptrdiff_t>(dof_node_.size());
    const Eigen::Index n = this->size();
    const VecX& free = this->free_;
    VecX diagonal = inertia_.mass();  // m_i, and the floor's friction stiffness
    std::vector<Triplet> floor;  // none without a Coulomb floor
    floor_friction_form_.add_hessian_triplets(floor);
    for (const Triplet& t : floor) diagonal[t.row()] += t.value();  // diagonal entries only
    std::vector<int>& start = assembly_start_;
    start.assign(nodes + 1, 0);
    for (std::ptrdiff_t k = 0; k < nodes; ++k) {
        int count = 0;
        for (int o = 0; o < kOffsets; ++o) count += pair_dof[k * kOffsets + o] >= 0;
        start[k + 1] = start[k] + count;
    }
    const Eigen::Index entries = static_cast<Eigen::Index>(start[nodes]) * dim * dim;
    out.resize(n, n);
    out.resizeNonZeros(entries);
    auto* outer = out.outerIndexPtr();
    auto* inner = out.innerIndexPtr();
    double* value = out.valuePtr();
    for (std::ptrdiff_t k = 0; k < nodes; ++k)
        for (int a = 0; a < dim; ++a) outer[dim * k + a] = dim * dim * start[k] + a * dim * (start[k + 1] - start[k]);
    outer[n] = static_cast<int>(entries);  // (nonZeros() of a compressed matrix reads outer[n])
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < nodes; ++k) {
        std::array<std::pair<int, int>, kOffsets> neighbours;  // (dof, offset), sorted by dof
        int count = 0;
        for (int o = 0; o < kOffsets; ++o)
            if (pair_dof[k * kOffsets + o] >= 0) neighbours[count++] = {pair_dof[k * kOffsets + o], o};
        std::sort(neighbours.begin(), neighbours.begin() + count);
        for (int a = 0; a < dim; ++a) {
            const Eigen::Index row = dim * k + a;
            int e = outer[row];
            for (int q = 0; q < count; ++q) {
                const int j = neighbours[q].first;
                const double* B = &pair_block[(static_cast<std::size_t>(k) * kOffsets + neighbours[q].second) * dim * dim];
                for (int b = 0; b < dim; ++b, ++e) {
                    const Eigen::Index col = dim * j + b;
                    inner[e] = static_cast<int>(col);
                    value[e] = free[row] > 0.0 && free[col] > 0.0 ? B[a * dim + b] : 0.0;
                    if (col == row) value[e] += diagonal[row];
                }
            }
        }
    }
}

template <int dim>
void IncrementalPotential<dim>::floor_friction_to_passes() {
    floor_friction_newton_ = false;
    floor_friction_form_.begin_step({}, this->free_);
    this->invalidate_pattern();  // the one solve's friction had its own nonsymmetric entries
    multigrid_built_ = multigrid_stale_ = false;
}

template <int dim>
std::size_t IncrementalPotential<dim>::floor_friction_contacts(const VecX* v) {
    if (floor_dofs_.empty() || floor_friction_form_.newton()) return floor_dofs_.size();
    // J_k = m_k (0 - v*_k,y) + dPsi/dv_k,y: the impulse the floor gives node k against the material's
    // inertia, gravity and stress. The first pass takes the start-of-step stress (v = 0 gives F = F^E,
    // where every energy's gradient is the elastic stress of F^E: the impulse explicit MPM's grid update
    // sees) and the slip of v*; the next ones those of the last solution v.
    VecX at = VecX::Zero(this->size());
    if (bdf2_) at = -offset_;  // F_p(v) about G_p(offset + v)
    VecX gradient = VecX::Zero(this->size());
    particle_energy_.add_gradient(v ? *v : at, gradient);
    const VecX& slip_from = v ? *v : inertia_.target();
    const VecX& mass = inertia_.mass();
    // Below eps_v the friction is a stiff drag (static friction): a node held by it creeps at most
    // eps_v / 2, a twentieth of a cell per second, whatever the step.
    const double eps_v = 0.1 * grid_->dx();  // m/s
    std::vector<typename FloorFrictionForm<dim>::Contact> contacts;
    for (std::size_t c = 0; c < floor_dofs_.size(); ++c) {
        const int k = floor_dofs_[c];
        const double impulse = -mass[dim * k + 1] * floor_normal_velocity_[c] + gradient[dim * k + 1];
        if (!(impulse > 0.0)) continue;
        double slip = 0.0;
        for (int a = 0; a < dim; ++a)
            if (a != 1) slip += slip_from[dim * k + a] * slip_from[dim * k + a];
        contacts.push_back({k, floor_friction_ * impulse * friction_f1_over_x(std::sqrt(slip), eps_v)});
    }
    const std::size_t count = contacts.size();
    floor_friction_form_.begin_step(std::move(contacts), this->free_);
    return count;
}

template <int dim>
void IncrementalPotential<dim>::use_bdf2(const VecX& u, const VecX& v_previous, const Vec<dim>& gravity, double omega) {
    if (!(omega > 0.0) || !std::isfinite(omega))
        throw std::invalid_argument("IncrementalPotential::use_bdf2: step ratio " + std::to_string(omega) +
                                    ", expected a finite number > 0");
    const double dt = step_dt_;
    const Bdf2Weights w = bdf2_weights(omega);
    const double extrapolate = omega / (1.0 + omega);
    VecX& v_star = inertia_.target();
    const VecX& free = this->free_;
    offset_.resize(v_star.size());
    for (Eigen::Index i = 0; i < v_star.size(); ++i) {
        const double g = gravity[i % dim];
        if (free[i] > 0.0) v_star[i] = w.current * (v_star[i] - dt * g) - w.previous * v_previous[i] + w.beta * dt * g;
        offset_[i] = free[i] * extrapolate * u[i];
    }
    dt_ = w.beta * dt;
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
    particle_energy_.energy().set_reference(F0, particles_->hardening, particles_->object);
}

template <int dim>
void IncrementalPotential<dim>::write_velocity(const VecX& v, Grid<dim>& grid) const {
    const std::ptrdiff_t dofs = static_cast<std::ptrdiff_t>(dof_node_.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < dofs; ++k) grid.node(dof_node_[k]).momentum = v.template segment<dim>(dim * k);
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

template class IncrementalPotential<2>;
template class IncrementalPotential<3>;

}  // namespace pnet
