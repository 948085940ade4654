#include "pnet/coupling/particle_mesh_forms.hpp"

#include <stdexcept>

#include "pnet/contact/friction.hpp"

namespace pnet {

template <int dim>
void CoupledVertices<dim>::join(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>& X,
                                std::vector<Vec<dim>>& out) {
    out.resize(x.size() + X.size());
    std::copy(x.begin(), x.end(), out.begin());
    std::copy(X.begin(), X.end(), out.begin() + static_cast<std::ptrdiff_t>(x.size()));
}

template <int dim>
void CoupledVertices<dim>::positions(const VecX& v, std::vector<Vec<dim>>& x) const {
    vg_ = v.head(mpm_.size());
    vf_ = v.tail(fem_.size());
    fem_.positions(vf_, x_);
    mpm_.particle_positions(vg_, X_);
    join(x_, X_, x);
}

template <int dim>
void CoupledVertices<dim>::motion(const VecX& d, std::vector<Vec<dim>>& dx) const {
    vg_ = d.head(mpm_.size());
    vf_ = d.tail(fem_.size());
    x_.resize(fem_.mesh().nodes());
    for (std::size_t a = 0; a < x_.size(); ++a) x_[a] = mpm_.dt() * vf_.template segment<dim>(dim * a);
    mpm_.particle_positions(vg_, X_, true);
    join(x_, X_, dx);
}

template <int dim>
int CoupledVertices<dim>::unknowns(int vertex, Eigen::Index* index, double* weight) const {
    const int nodes = static_cast<int>(fem_.mesh().nodes());
    if (vertex < nodes) {
        index[0] = mpm_.size() + dim * static_cast<Eigen::Index>(vertex);
        weight[0] = 1.0;
        return 1;
    }
    const std::size_t p = static_cast<std::size_t>(vertex - nodes);
    const int* dof = mpm_.stencil_dofs(p);
    const double* w = mpm_.stencil_weights(p);
    int count = 0;
    for (int s = 0; s < IncrementalPotential<dim>::kStencil; ++s)
        if (w[s] != 0.0) {
            index[count] = dim * static_cast<Eigen::Index>(dof[s]);
            weight[count++] = w[s];
        }
    return count;
}

template <int dim>
void ParticleFrictionForm<dim>::set_pairs(std::vector<FrictionPair<dim>> pairs, double mu, double eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0))
        throw std::invalid_argument("ParticleFrictionForm: mu must be >= 0 and eps_v > 0");
    mu_ = mu;
    eps_v_ = eps_v;
    pairs_ = mu > 0.0 ? std::move(pairs) : std::vector<FrictionPair<dim>>{};
    this->hessians_.clear();
}

template <int dim>
Eigen::Matrix<double, dim - 1, 1> ParticleFrictionForm<dim>::slip(std::size_t k, const VecX& v) const {
    const FrictionPair<dim>& f = pairs_[k];
    Vec<dim> relative = Vec<dim>::Zero();
    for (int j = 0; j < f.count; ++j) relative += f.weight[j] * this->vertices_.velocity(f.node[j], v);
    return f.tangent.transpose() * relative;
}

template <int dim>
double ParticleFrictionForm<dim>::value(const VecX& v) {
    double sum = 0.0;
    for (std::size_t k = 0; k < pairs_.size(); ++k)
        sum += mu_ * pairs_[k].normal_force * friction_f0(slip(k, v).norm(), eps_v_);
    return this->vertices_.dt() * sum;
}

template <int dim>
double ParticleFrictionForm<dim>::add_gradient(const VecX& v, VecX& g) {
    // dD/du_j = c_j f with f = mu lambda f1(|s|) T s / |s| (s the slip), reaching vertex j's
    // unknowns through its weights; scaled by dt.
    const double dt = this->vertices_.dt();
    Eigen::Index index[ContactVertices<dim>::kMaxUnknowns];
    double weight[ContactVertices<dim>::kMaxUnknowns];
    double d = 0.0;
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const FrictionPair<dim>& fp = pairs_[k];
        const Eigen::Matrix<double, dim - 1, 1> u = slip(k, v);
        const double x = u.norm();
        d += mu_ * fp.normal_force * friction_f0(x, eps_v_);
        const Vec<dim> f = mu_ * fp.normal_force * friction_f1_over_x(x, eps_v_) * (fp.tangent * u);
        for (int j = 0; j < fp.count; ++j) {
            const int n = this->vertices_.unknowns(fp.node[j], index, weight);
            for (int i = 0; i < n; ++i) g.template segment<dim>(index[i]) += (dt * weight[i] * fp.weight[j]) * f;
        }
    }
    return dt * d;
}

template <int dim>
void ParticleFrictionForm<dim>::prepare_hessian(const VecX& v) {
    this->hessians_.resize(pairs_.size());
    this->hessian_scale_ = this->vertices_.dt();
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const FrictionPair<dim>& fp = pairs_[k];
        const Mat<dim> H = mu_ * fp.normal_force * fp.tangent * friction_slip_hessian<dim - 1>(slip(k, v), eps_v_) *
                           fp.tangent.transpose();
        // (c c^T) (x) H with c the pair's weights: the relative velocity's per vertex.
        ContactPairTerms<dim>& t = this->hessians_[k];
        t.count = fp.count;
        t.hessian.setZero();
        for (int i = 0; i < fp.count; ++i) {
            t.node[i] = fp.node[i];
            for (int j = 0; j < fp.count; ++j)
                t.hessian.template block<dim, dim>(dim * i, dim * j) = (fp.weight[i] * fp.weight[j]) * H;
        }
    }
}

template class CoupledVertices<2>;
template class CoupledVertices<3>;
template class ParticleFrictionForm<2>;
template class ParticleFrictionForm<3>;

}  // namespace pnet
