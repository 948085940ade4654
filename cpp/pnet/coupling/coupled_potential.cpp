#include "pnet/coupling/coupled_potential.hpp"

#include <algorithm>

#include <Eigen/SparseCholesky>

#include "pnet/contact/friction.hpp"
#include "pnet/solver/newton.hpp"  // NewtonError

namespace pnet {

namespace {
template <int dim>
constexpr int kPairNodes = IncrementalPotential<dim>::kStencil + dim;  // stencil + facet nodes
}  // namespace

template <int dim>
struct CoupledPotential<dim>::FemFactor {
    Eigen::SimplicialLLT<SparseMatrix, Eigen::Lower> llt;
    std::vector<SparseMatrix::StorageIndex> outer, inner;  // the pattern analysed
};

template <int dim>
CoupledPotential<dim>::CoupledPotential(IncrementalPotential<dim>& mpm, FemPotential<dim>& fem, const Contact& contact)
    : mpm_(mpm), fem_(fem), contact_(contact), fem_factor_(std::make_unique<FemFactor>()) {}

template <int dim>
CoupledPotential<dim>::~CoupledPotential() = default;

template <int dim>
void CoupledPotential<dim>::begin_step() {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    v_star_.resize(ng + nf);
    v_star_ << mpm_.v_star(), fem_.v_star();
    residual_mass_.resize(ng + nf);
    residual_mass_ << mpm_.residual_mass(), fem_.residual_mass();
    ccd_queries_ = ccd_limited_ = 0;
    barrier_ = PairTerms{};
    friction_ = PairTerms{};
    friction_pairs_.clear();
    factorized_this_step_ = false;
}

template <int dim>
void CoupledPotential<dim>::set_friction(std::vector<ParticleFrictionPair<dim>> pairs, double mu, double eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0)) throw std::invalid_argument("CoupledPotential: mu must be >= 0 and eps_v > 0");
    mu_ = mu;
    eps_v_ = eps_v;
    friction_pairs_ = mu > 0.0 ? std::move(pairs) : std::vector<ParticleFrictionPair<dim>>{};
    friction_ = PairTerms{};
    for (const auto& f : friction_pairs_) friction_.pairs.push_back({f.particle, f.facet});
}

template <int dim>
void CoupledPotential<dim>::split(const VecX& v) const {
    vg_ = v.head(mpm_.size());
    vf_ = v.tail(fem_.size());
}

template <int dim>
void CoupledPotential<dim>::positions(const VecX& v, std::vector<Vec<dim>>& X, std::vector<Vec<dim>>& x) const {
    split(v);
    mpm_.particle_positions(vg_, X);
    fem_.positions(vf_, x);
}

template <int dim>
void CoupledPotential<dim>::deformation(const VecX& v, std::vector<Mat<dim>>& F) const {
    split(v);
    mpm_.deformation(vg_, F);
}

template <int dim>
Eigen::Matrix<double, dim - 1, 1> CoupledPotential<dim>::slip(std::size_t k) const {
    const ParticleFrictionPair<dim>& f = friction_pairs_[k];
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    const int* dof = mpm_.stencil_dofs(f.particle);
    const double* w = mpm_.stencil_weights(f.particle);
    Vec<dim> relative = Vec<dim>::Zero();
    for (int s = 0; s < kStencil; ++s) relative += w[s] * vg_.template segment<dim>(dim * dof[s]);
    const auto& facet = contact_.facets()[f.facet];
    for (int j = 0; j < dim; ++j) relative -= f.weight[j] * vf_.template segment<dim>(dim * facet[j]);
    return f.tangent.transpose() * relative;
}

template <int dim>
double CoupledPotential<dim>::friction_value(const VecX& v) const {
    if (friction_pairs_.empty()) return 0.0;
    split(v);
    double sum = 0.0;
    for (std::size_t k = 0; k < friction_pairs_.size(); ++k)
        sum += mu_ * friction_pairs_[k].normal_force * friction_f0(slip(k).norm(), eps_v_);
    return mpm_.dt() * sum;
}

template <int dim>
double CoupledPotential<dim>::value(const VecX& v) {
    split(v);
    const double e = mpm_.value(vg_) + fem_.value(vf_);
    positions(v, X_, x_);
    return e + contact_.value(X_, x_) + friction_value(v);  // friction_value: 0 without friction
}

template <int dim>
void CoupledPotential<dim>::scatter_gradient(const PairTerms& terms, VecX& g) const {
    const double dt = mpm_.dt();
    const Eigen::Index ng = mpm_.size();
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    for (std::size_t k = 0; k < terms.pairs.size(); ++k) {
        const int p = terms.pairs[k].particle;
        const int* dof = mpm_.stencil_dofs(p);
        const double* w = mpm_.stencil_weights(p);
        const Gradient& gk = terms.gradients[k];
        for (int s = 0; s < kStencil; ++s) g.template segment<dim>(dim * dof[s]) += (dt * w[s]) * gk.template head<dim>();
        const auto& facet = contact_.facets()[terms.pairs[k].facet];
        for (int j = 0; j < dim; ++j)
            g.template segment<dim>(ng + dim * facet[j]) += dt * gk.template segment<dim>(dim * (j + 1));
    }
}

template <int dim>
double CoupledPotential<dim>::add_contact_gradient(const VecX& v, VecX& g) {
    positions(v, X_, x_);
    double e = contact_.gradient(X_, x_, barrier_.pairs, barrier_.gradients);
    scatter_gradient(barrier_, g);
    if (!friction_pairs_.empty()) {
        // dD/d(v_p, v_facet) in the stacked slots: f = mu lambda f1(|u|) T u / |u| on the particle,
        // -c_j f on the facet's nodes; scattered with dt, as the barrier's position gradients.
        friction_.gradients.resize(friction_pairs_.size());
        double d = 0.0;
        for (std::size_t k = 0; k < friction_pairs_.size(); ++k) {
            const ParticleFrictionPair<dim>& fp = friction_pairs_[k];
            const Eigen::Matrix<double, dim - 1, 1> u = slip(k);
            const double x = u.norm();
            d += mu_ * fp.normal_force * friction_f0(x, eps_v_);
            const Vec<dim> f = mu_ * fp.normal_force * friction_f1_over_x(x, eps_v_) * (fp.tangent * u);
            Gradient& gk = friction_.gradients[k];
            gk.template head<dim>() = f;
            for (int j = 0; j < dim; ++j) gk.template segment<dim>(dim * (j + 1)) = -fp.weight[j] * f;
        }
        scatter_gradient(friction_, g);
        e += mpm_.dt() * d;
    }
    // Fixed components (sticky floor, kinematic nodes) are held: no gradient.
    g.array() *= (residual_mass_.array() > 0.0).template cast<double>();
    return e;
}

template <int dim>
void CoupledPotential<dim>::friction_hessians() {
    friction_.hessians.resize(friction_pairs_.size());
    friction_.hessian_scale = mpm_.dt();
    for (std::size_t k = 0; k < friction_pairs_.size(); ++k) {
        const ParticleFrictionPair<dim>& fp = friction_pairs_[k];
        const Eigen::Matrix<double, dim - 1, 1> u = slip(k);
        const Mat<dim> H = mu_ * fp.normal_force * fp.tangent * friction_slip_hessian<dim - 1>(u, eps_v_) *
                           fp.tangent.transpose();
        // (a a^T) (x) H with a = (1, -c_1, ..., -c_dim): the relative velocity's weights per slot.
        double a[dim + 1];
        a[0] = 1.0;
        for (int j = 0; j < dim; ++j) a[j + 1] = -fp.weight[j];
        Hessian& Hk = friction_.hessians[k];
        for (int i = 0; i <= dim; ++i)
            for (int j = 0; j <= dim; ++j) Hk.template block<dim, dim>(dim * i, dim * j) = (a[i] * a[j]) * H;
    }
}

template <int dim>
double CoupledPotential<dim>::value_gradient(const VecX& v, VecX& gradient) {
    split(v);
    const double em = mpm_.value_gradient(vg_, gg_);
    const double ef = fem_.value_gradient(vf_, gf_);
    gradient.resize(size());
    gradient << gg_, gf_;
    return em + ef + add_contact_gradient(v, gradient);
}

template <int dim>
int CoupledPotential<dim>::pair_nodes(const Pair& pair, Eigen::Index* index, double* weight, int* slot) const {
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
template <typename F>
void CoupledPotential<dim>::for_each_pair_hessian(F&& f) const {
    Eigen::Index index[kPairNodes<dim>];
    double weight[kPairNodes<dim>];
    int slot[kPairNodes<dim>];
    for (const PairTerms* terms : {&barrier_, &friction_})
        for (std::size_t k = 0; k < terms->hessians.size(); ++k) {
            const int count = pair_nodes(terms->pairs[k], index, weight, slot);
            f(terms->hessians[k], terms->hessian_scale, count, index, weight, slot);
        }
}

template <int dim>
void CoupledPotential<dim>::prepare(const VecX& v) {
    positions(v, X_, x_);
    contact_.hessians(X_, x_, project_psd_, barrier_.pairs, barrier_.hessians);
    barrier_.hessian_scale = mpm_.dt() * mpm_.dt();
    if (!friction_pairs_.empty()) friction_hessians();
    if (solve_ == LinearSolve::Assembled)
        assemble();
    else
        prepare_blocks();
}

template <int dim>
void CoupledPotential<dim>::assemble() {
    const Eigen::Index ng = mpm_.size(), n = size();
    triplets_.clear();
    mpm_.add_hessian_triplets(triplets_, 0);
    const SparseMatrix& Hf = *fem_.hessian_matrix();
    for (Eigen::Index c = 0; c < Hf.outerSize(); ++c)
        for (SparseMatrix::InnerIterator it(Hf, c); it; ++it) triplets_.emplace_back(ng + it.row(), ng + c, it.value());
    for_each_pair_hessian([&](const Hessian& H, double hessian_scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i)
            for (int j = 0; j < count; ++j) {
                const double scale = hessian_scale * weight[i] * weight[j];
                for (int a = 0; a < dim; ++a)
                    for (int b = 0; b < dim; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (residual_mass_[row] > 0.0 && residual_mass_[col] > 0.0)
                            triplets_.emplace_back(row, col, scale * H(dim * slot[i] + a, dim * slot[j] + b));
                    }
            }
    });
    hessian_.resize(n, n);
    hessian_.setFromTriplets(triplets_.begin(), triplets_.end());  // duplicates summed in triplet order
    diagonal_ = hessian_.diagonal();
}

template <int dim>
void CoupledPotential<dim>::prepare_blocks() {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    // The grid's diagonal and the FEM block, each with the pairs' terms on its own unknowns.
    VecX grid_diagonal;
    mpm_.hessian_diagonal(grid_diagonal);
    const SparseMatrix& Hf = *fem_.hessian_matrix();
    triplets_.clear();  // the pairs' FEM terms, added to Hf below
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i) {
            if (index[i] < ng) {
                for (int a = 0; a < dim; ++a)
                    if (residual_mass_[index[i] + a] > 0.0)
                        grid_diagonal[index[i] + a] +=
                            scale * weight[i] * weight[i] * H(dim * slot[i] + a, dim * slot[i] + a);
                continue;
            }
            for (int j = 0; j < count; ++j) {
                if (index[j] < ng) continue;
                for (int a = 0; a < dim; ++a)
                    for (int b = 0; b < dim; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (residual_mass_[row] > 0.0 && residual_mass_[col] > 0.0)
                            triplets_.emplace_back(row - ng, col - ng, scale * H(dim * slot[i] + a, dim * slot[j] + b));
                    }
            }
        }
    });
    if (triplets_.empty()) {
        fem_block_ = Hf;
    } else {
        pair_block_.resize(nf, nf);
        pair_block_.setFromTriplets(triplets_.begin(), triplets_.end());
        fem_block_ = Hf + pair_block_;
    }
    FemFactor& f = *fem_factor_;
    // The FEM block only preconditions PCG: its factorization is kept through the step's Newton
    // iterations while the barrier's pairs are the same ones (the stiff body's Hessian hardly
    // changes; the pairs' terms do, and a new pair set gets a new factorization).
    const std::vector<Pair>& pairs = barrier_.pairs;
    const bool same_pairs =
        factorized_this_step_ && pairs.size() == factor_pairs_.size() &&
        std::equal(pairs.begin(), pairs.end(), factor_pairs_.begin(),
                   [](const auto& a, const auto& b) { return a.particle == b.particle && a.facet == b.facet; });
    inverse_grid_diagonal_ = grid_diagonal.unaryExpr([](double h) { return h > 0.0 ? 1.0 / h : 1.0; });
    diagonal_.resize(ng + nf);
    diagonal_ << grid_diagonal, fem_block_.diagonal();
    if (same_pairs) return;
    factorized_this_step_ = true;
    factor_pairs_ = pairs;
    const bool same = static_cast<Eigen::Index>(f.outer.size()) == nf + 1 &&
                      static_cast<Eigen::Index>(f.inner.size()) == fem_block_.nonZeros() &&
                      std::equal(f.outer.begin(), f.outer.end(), fem_block_.outerIndexPtr()) &&
                      std::equal(f.inner.begin(), f.inner.end(), fem_block_.innerIndexPtr());
    if (!same) {
        f.llt.analyzePattern(fem_block_);
        f.outer.assign(fem_block_.outerIndexPtr(), fem_block_.outerIndexPtr() + nf + 1);
        f.inner.assign(fem_block_.innerIndexPtr(), fem_block_.innerIndexPtr() + fem_block_.nonZeros());
    }
    f.llt.factorize(fem_block_);
    if (f.llt.info() != Eigen::Success)
        throw NewtonError("the FEM block of the coupled Hessian is not positive definite");
}

template <int dim>
void CoupledPotential<dim>::hessian_multiply(const VecX& d, VecX& out) const {
    if (solve_ == LinearSolve::Assembled) {
        out.noalias() = hessian_ * d;
        return;
    }
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    out.resize(ng + nf);
    work_in_ = d.head(ng);
    mpm_.hessian_multiply(work_in_, work_out_);
    out.head(ng) = work_out_;
    out.tail(nf).noalias() = *fem_.hessian_matrix() * d.tail(nf);
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        // u = J d (the pair's positions' motion per dt), y = H u, out += J^T y scale.
        Gradient u = Gradient::Zero();
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (residual_mass_[index[i] + a] > 0.0) u[dim * slot[i] + a] += weight[i] * d[index[i] + a];
        const Gradient y = scale * (H * u);
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (residual_mass_[index[i] + a] > 0.0) out[index[i] + a] += weight[i] * y[dim * slot[i] + a];
    });
}

template <int dim>
void CoupledPotential<dim>::apply_preconditioner(const VecX& r, VecX& z) const {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    z.resize(ng + nf);
    z.head(ng) = inverse_grid_diagonal_.cwiseProduct(r.head(ng));
    z.tail(nf) = fem_factor_->llt.solve(r.tail(nf));
}

template <int dim>
void CoupledPotential<dim>::prepare_hessian(const VecX& v) {
    split(v);
    mpm_.prepare_hessian(vg_);
    fem_.prepare_hessian(vf_);
    prepare(v);
}

template <int dim>
double CoupledPotential<dim>::value_gradient_hessian(const VecX& v, VecX& gradient) {
    split(v);
    const double em = mpm_.value_gradient_hessian(vg_, gg_);
    const double ef = fem_.value_gradient_hessian(vf_, gf_);
    gradient.resize(size());
    gradient << gg_, gf_;
    const double b = add_contact_gradient(v, gradient);
    prepare(v);
    return em + ef + b;
}

template <int dim>
double CoupledPotential<dim>::max_step(const VecX& v, const VecX& d) {
    split(d);
    const VecX dg = vg_, df = vf_;
    double t = std::min(1.0, fem_.max_step(v.tail(fem_.size()), df));
    positions(v, X_, x_);
    mpm_.particle_positions(dg, dX_, true);
    dx_.resize(x_.size());
    for (std::size_t a = 0; a < x_.size(); ++a) dx_[a] = mpm_.dt() * df.template segment<dim>(dim * a);
    t = std::min(t, contact_.max_step(X_, dX_, x_, dx_));
    ++ccd_queries_;
    ccd_limited_ += t < 1.0;
    return t;
}

template class CoupledPotential<2>;
template class CoupledPotential<3>;

}  // namespace pnet
