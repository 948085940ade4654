#include "pnet/coupling/particle_mesh_forms.hpp"

#include <stdexcept>

#include "pnet/contact/friction.hpp"

namespace pnet {

template <int dim>
void ParticleMeshForm<dim>::split(const VecX& v) const {
    vg_ = v.head(mpm_.size());
    vf_ = v.tail(fem_.size());
}

template <int dim>
void ParticleMeshForm<dim>::positions(const VecX& v) const {
    split(v);
    mpm_.particle_positions(vg_, X_);
    fem_.positions(vf_, x_);
}

template <int dim>
void ParticleMeshForm<dim>::scatter_gradient(VecX& g) const {
    const double dt = mpm_.dt();
    const Eigen::Index ng = mpm_.size();
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const int p = pairs_[k].particle;
        const int* dof = mpm_.stencil_dofs(p);
        const double* w = mpm_.stencil_weights(p);
        const Gradient& gk = gradients_[k];
        for (int s = 0; s < kStencil; ++s) g.template segment<dim>(dim * dof[s]) += (dt * w[s]) * gk.template head<dim>();
        const auto& facet = contact_.facets()[pairs_[k].facet];
        for (int j = 0; j < dim; ++j)
            g.template segment<dim>(ng + dim * facet[j]) += dt * gk.template segment<dim>(dim * (j + 1));
    }
}

template <int dim>
int ParticleMeshForm<dim>::pair_nodes(const Pair& pair, Eigen::Index* index, double* weight, int* slot) const {
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    const int* dof = mpm_.stencil_dofs(pair.particle);
    const double* w = mpm_.stencil_weights(pair.particle);
    int count = 0;
    for (int s = 0; s < kStencil; ++s)
        if (w[s] != 0.0) {
            index[count] = dim * dof[s];
            weight[count] = w[s];
            slot[count++] = 0;
        }
    const auto& facet = contact_.facets()[pair.facet];
    for (int e = 0; e < dim; ++e) {
        index[count] = mpm_.size() + dim * facet[e];
        weight[count] = 1.0;
        slot[count++] = 1 + e;
    }
    return count;
}

template <int dim>
void ParticleMeshForm<dim>::add_hessian_multiply(const VecX& d, VecX& out) const {
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        // u = J d (the pair's positions' motion per dt), y = H u, out += J^T y scale.
        Gradient u = Gradient::Zero();
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (free_[index[i] + a] > 0.0) u[dim * slot[i] + a] += weight[i] * d[index[i] + a];
        const Gradient y = scale * (H * u);
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (free_[index[i] + a] > 0.0) out[index[i] + a] += weight[i] * y[dim * slot[i] + a];
    });
}

template <int dim>
void ParticleMeshForm<dim>::add_hessian_triplets(std::vector<Triplet>& triplets) const {
    for_each_pair_hessian([&](const Hessian& H, double hessian_scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i)
            for (int j = 0; j < count; ++j) {
                const double scale = hessian_scale * weight[i] * weight[j];
                for (int a = 0; a < dim; ++a)
                    for (int b = 0; b < dim; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (free_[row] > 0.0 && free_[col] > 0.0)
                            triplets.emplace_back(row, col, scale * H(dim * slot[i] + a, dim * slot[j] + b));
                    }
            }
    });
}

template <int dim>
void ParticleMeshForm<dim>::add_hessian_diagonal(VecX& diagonal) const {
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (free_[index[i] + a] > 0.0)
                    diagonal[index[i] + a] += scale * weight[i] * weight[i] * H(dim * slot[i] + a, dim * slot[i] + a);
    });
}

template <int dim>
void ParticleMeshForm<dim>::add_hessian_block_diagonal(VecX& blocks) const {
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                for (int b = 0; b < dim; ++b)
                    if (free_[index[i] + a] > 0.0 && free_[index[i] + b] > 0.0)
                        blocks[dim * index[i] + a * dim + b] +=
                            scale * weight[i] * weight[i] * H(dim * slot[i] + a, dim * slot[i] + b);
    });
}

template <int dim>
void ParticleBarrierForm<dim>::begin_step() {
    this->pairs_.clear();
    this->hessian_pairs_.clear();
    this->gradients_.clear();
    this->hessians_.clear();
    ccd_ = CcdCount{};
}

template <int dim>
double ParticleBarrierForm<dim>::value(const VecX& v) {
    this->positions(v);
    return this->contact_.value(this->X_, this->x_);
}

template <int dim>
double ParticleBarrierForm<dim>::add_gradient(const VecX& v, VecX& g) {
    this->positions(v);
    const double e = this->contact_.gradient(this->X_, this->x_, this->pairs_, this->gradients_);
    this->scatter_gradient(g);
    return e;
}

template <int dim>
void ParticleBarrierForm<dim>::prepare_hessian(const VecX& v) {
    this->positions(v);
    this->contact_.hessians(this->X_, this->x_, project_psd_, this->hessian_pairs_, this->hessians_);
    this->hessian_scale_ = this->mpm_.dt() * this->mpm_.dt();
}

template <int dim>
double ParticleBarrierForm<dim>::max_step(const VecX& v, const VecX& d) {
    const Eigen::Index ng = this->mpm_.size();
    const VecX dg = d.head(ng), df = d.tail(this->fem_.size());
    this->positions(v);
    this->mpm_.particle_positions(dg, dX_, true);
    dx_.resize(this->x_.size());
    for (std::size_t a = 0; a < this->x_.size(); ++a) dx_[a] = this->mpm_.dt() * df.template segment<dim>(dim * a);
    return ccd_.record(this->contact_.max_step(this->X_, dX_, this->x_, dx_));
}

template <int dim>
void ParticleFrictionForm<dim>::set_pairs(std::vector<ParticleFrictionPair<dim>> pairs, double mu, double eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0)) throw std::invalid_argument("ParticleFrictionForm: mu must be >= 0 and eps_v > 0");
    mu_ = mu;
    eps_v_ = eps_v;
    friction_pairs_ = mu > 0.0 ? std::move(pairs) : std::vector<ParticleFrictionPair<dim>>{};
    this->pairs_.clear();
    for (const auto& f : friction_pairs_) this->pairs_.push_back({f.particle, f.facet});
    this->hessian_pairs_ = this->pairs_;
    this->gradients_.clear();
    this->hessians_.clear();
}

template <int dim>
Eigen::Matrix<double, dim - 1, 1> ParticleFrictionForm<dim>::slip(std::size_t k) const {
    const ParticleFrictionPair<dim>& f = friction_pairs_[k];
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    const int* dof = this->mpm_.stencil_dofs(f.particle);
    const double* w = this->mpm_.stencil_weights(f.particle);
    Vec<dim> relative = Vec<dim>::Zero();
    for (int s = 0; s < kStencil; ++s) relative += w[s] * this->vg_.template segment<dim>(dim * dof[s]);
    const auto& facet = this->contact_.facets()[f.facet];
    for (int j = 0; j < dim; ++j) relative -= f.weight[j] * this->vf_.template segment<dim>(dim * facet[j]);
    return f.tangent.transpose() * relative;
}

template <int dim>
double ParticleFrictionForm<dim>::value(const VecX& v) {
    if (friction_pairs_.empty()) return 0.0;
    this->split(v);
    double sum = 0.0;
    for (std::size_t k = 0; k < friction_pairs_.size(); ++k)
        sum += mu_ * friction_pairs_[k].normal_force * friction_f0(slip(k).norm(), eps_v_);
    return this->mpm_.dt() * sum;
}

template <int dim>
double ParticleFrictionForm<dim>::add_gradient(const VecX& v, VecX& g) {
    if (friction_pairs_.empty()) return 0.0;
    this->split(v);
    // dD/d(v_p, v_facet) in the stacked slots: f = mu lambda f1(|u|) T u / |u| on the particle,
    // -c_j f on the facet's nodes; scattered with dt, as the barrier's position gradients.
    this->gradients_.resize(friction_pairs_.size());
    double d = 0.0;
    for (std::size_t k = 0; k < friction_pairs_.size(); ++k) {
        const ParticleFrictionPair<dim>& fp = friction_pairs_[k];
        const Eigen::Matrix<double, dim - 1, 1> u = slip(k);
        const double x = u.norm();
        d += mu_ * fp.normal_force * friction_f0(x, eps_v_);
        const Vec<dim> f = mu_ * fp.normal_force * friction_f1_over_x(x, eps_v_) * (fp.tangent * u);
        typename ParticleMeshForm<dim>::Gradient& gk = this->gradients_[k];
        gk.template head<dim>() = f;
        for (int j = 0; j < dim; ++j) gk.template segment<dim>(dim * (j + 1)) = -fp.weight[j] * f;
    }
    this->scatter_gradient(g);
    return this->mpm_.dt() * d;
}

template <int dim>
void ParticleFrictionForm<dim>::prepare_hessian(const VecX& v) {
    if (friction_pairs_.empty()) return;
    this->split(v);
    this->hessians_.resize(friction_pairs_.size());
    this->hessian_scale_ = this->mpm_.dt();
    for (std::size_t k = 0; k < friction_pairs_.size(); ++k) {
        const ParticleFrictionPair<dim>& fp = friction_pairs_[k];
        const Eigen::Matrix<double, dim - 1, 1> u = slip(k);
        const Mat<dim> H = mu_ * fp.normal_force * fp.tangent * friction_slip_hessian<dim - 1>(u, eps_v_) *
                           fp.tangent.transpose();
        // (a a^T) (x) H with a = (1, -c_1, ..., -c_dim): the relative velocity's weights per slot.
        double a[dim + 1];
        a[0] = 1.0;
        for (int j = 0; j < dim; ++j) a[j + 1] = -fp.weight[j];
        typename ParticleMeshForm<dim>::Hessian& Hk = this->hessians_[k];
        for (int i = 0; i <= dim; ++i)
            for (int j = 0; j <= dim; ++j) Hk.template block<dim, dim>(dim * i, dim * j) = (a[i] * a[j]) * H;
    }
}

template class ParticleMeshForm<2>;
template class ParticleMeshForm<3>;
template class ParticleBarrierForm<2>;
template class ParticleBarrierForm<3>;
template class ParticleFrictionForm<2>;
template class ParticleFrictionForm<3>;

}  // namespace pnet
