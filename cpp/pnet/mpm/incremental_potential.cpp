#include "pnet/mpm/incremental_potential.hpp"

#include "pnet/mpm/transfer.hpp"

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
        // The Coulomb floor holds a node's normal velocity only where it presses into the floor.
        if (bc.coulomb_floor() && bc.in_floor(coord[1]) && node.momentum[1] > 0.0) fixed[1] = false;
        for (int a = 0; a < dim; ++a) {
            const Eigen::Index i = dim * k + a;
            mass[i] = massless ? 1.0 : node.mass;
            v_star[i] = massless ? 0.0 : node.momentum[a];
            free[i] = (fixed[a] || massless) ? 0.0 : 1.0;
            residual_scale_[i] = free[i] / mass[i];
            residual_mass_[i] = free[i] * mass[i];
        }
    }
    // The Coulomb floor's contacts: the nodes whose normal velocity is held (in dof order).
    floor_friction_ = bc.coulomb_floor() ? bc.floor_friction : -1.0;
    floor_dofs_.clear();
    if (bc.coulomb_floor())
        for (std::ptrdiff_t k = 0; k < dofs; ++k) {
            int coord[dim];
            grid.coordinates(dof_node_[k], coord);
            if (bc.in_floor(coord[1]) && free[dim * k + 1] == 0.0 && grid.node(dof_node_[k]).mass > 0.0)
                floor_dofs_.push_back(static_cast<int>(k));
        }
    particle_energy_.begin_step(particles.size());
    this->invalidate_pattern();  // a new grid
}

template <int dim>
int IncrementalPotential<dim>::apply_floor_friction(VecX& v) {
    if (floor_dofs_.empty()) return 0;
    // The floor's normal impulse on a held component is what keeps it at its value: m (v - v*) plus the
    // particles' dPsi/dv there (the unmasked gradient; the inertia term is 0, held at v*). v* already
    // carries the floor's reaction to the inertia and gravity (Grid::apply_boundary); this is the rest,
    // the stress the material above presses the node with.
    floor_gradient_.setZero(v.size());
    particle_energy_.add_gradient(v, floor_gradient_);
    const VecX& mass = inertia_.mass();
    int sliding = 0;
    for (int k : floor_dofs_) {
        const Eigen::Index normal = dim * k + 1;
        const double impulse = floor_gradient_[normal];
        if (!(impulse > 0.0)) continue;
        Vec<dim> vk = v.template segment<dim>(dim * k);
        const double held = vk[1];
        coulomb_projection<dim>(vk, impulse / mass[normal], floor_friction_);
        vk[1] = held;
        v.template segment<dim>(dim * k) = vk;
        sliding += vk.squaredNorm() > held * held ? 1 : 0;
    }
    return sliding;
}

template <int dim>
void IncrementalPotential<dim>::use_bdf2(const VecX& u, const VecX& v_previous, const Vec<dim>& gravity) {
    const double beta = 2.0 / 3.0, dt = step_dt_;
    VecX& v_star = inertia_.target();
    const VecX& free = this->free_;
    offset_.resize(v_star.size());
    for (Eigen::Index i = 0; i < v_star.size(); ++i) {
        const double g = gravity[i % dim];
        if (free[i] > 0.0) v_star[i] = (4.0 * (v_star[i] - dt * g) - v_previous[i]) / 3.0 + beta * dt * g;
        offset_[i] = free[i] * 0.5 * u[i];
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
