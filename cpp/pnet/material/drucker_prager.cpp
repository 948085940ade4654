#include "pnet/material/drucker_prager.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pnet {

double DruckerPragerParams::alpha() const {
    const double s = std::sin(friction_angle_deg * M_PI / 180.0);
    return std::sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s);
}

void DruckerPragerParams::validate() const {
    if (!std::isfinite(friction_angle_deg) || friction_angle_deg <= 0.0 || friction_angle_deg >= 90.0) {
        std::ostringstream msg;
        msg << "drucker_prager parameter friction_angle_deg = " << friction_angle_deg
            << " must be in (0, 90) degrees";
        throw std::invalid_argument(msg.str());
    }
}

template <int dim>
DruckerPrager<dim>::DruckerPrager(const DruckerPragerParams& params, const Elasticity<dim>& elasticity)
    : params_(params), mu_(elasticity.mu()), lambda_(elasticity.lambda()) {
    params_.validate();
    if (elasticity.model() != ElasticityModel::StvkHencky)
        throw std::invalid_argument("plasticity 'drucker_prager' requires elasticity 'stvk_hencky', got '" +
                                    to_string(elasticity.model()) + "'");
    alpha_ = params_.alpha();
}

template <int dim>
Vec<dim> DruckerPrager<dim>::project_strain(const Vec<dim>& eps, ReturnBranch* branch) const {
    ReturnBranch taken = ReturnBranch::Elastic;
    Vec<dim> eps_Z = eps;
    const double tr_eps = eps.sum();
    if (tr_eps > 0.0) {
        taken = ReturnBranch::Apex;
        eps_Z.setZero();
    } else {
        const Vec<dim> eps_hat = eps - tr_eps / dim * Vec<dim>::Ones();
        const double eps_hat_norm = eps_hat.norm();
        const double dgamma = eps_hat_norm + alpha_ * (dim * lambda_ + 2.0 * mu_) * tr_eps / (2.0 * mu_);
        if (dgamma > 0.0) {  // implies eps_hat_norm > 0 because tr_eps <= 0 here
            taken = ReturnBranch::Cone;
            eps_Z = eps - dgamma / eps_hat_norm * eps_hat;
        }
    }
    if (branch) *branch = taken;
    return eps_Z;
}

template <int dim>
Vec<dim> DruckerPrager<dim>::project_strain(const Vec<dim>& eps, Mat<dim>& jacobian, double& deviatoric_scale,
                                            double& margin, ReturnBranch* branch) const {
    ReturnBranch taken;
    const Vec<dim> eps_Z = project_strain(eps, &taken);
    if (branch) *branch = taken;
    const double tr_eps = eps.sum();
    if (taken == ReturnBranch::Apex) {  // a change of one principal strain by x moves tr by x
        jacobian.setZero();
        deviatoric_scale = 0.0;
        margin = tr_eps;
        return eps_Z;
    }
    const Vec<dim> eps_hat = eps - tr_eps / dim * Vec<dim>::Ones();
    const double L = eps_hat.norm();
    const double c = alpha_ * (dim * lambda_ + 2.0 * mu_) / (2.0 * mu_);
    // x in one principal strain moves tr by x and ||dev eps|| by at most x, so dgamma by at most (1 + c) x.
    margin = std::min(-tr_eps, std::abs(L + c * tr_eps) / (1.0 + c));
    if (taken == ReturnBranch::Elastic) {
        jacobian.setIdentity();
        deviatoric_scale = 1.0;
        return eps_Z;
    }
    const Vec<dim> n = eps_hat / L;
    const double k = -c * tr_eps / L;
    const Mat<dim> mean = Mat<dim>::Constant(1.0 / dim);
    jacobian = mean - c * n * Vec<dim>::Ones().transpose() + k * (Mat<dim>::Identity() - mean - n * n.transpose());
    deviatoric_scale = k;
    return eps_Z;
}

template <int dim>
double DruckerPrager<dim>::deviatoric_scale(const Vec<dim>& eps) const {
    ReturnBranch branch;
    const Vec<dim> eps_Z = project_strain(eps, &branch);
    if (branch != ReturnBranch::Cone) return branch == ReturnBranch::Apex ? 0.0 : 1.0;
    const auto dev = [](const Vec<dim>& e) { return Vec<dim>(e - e.sum() / dim * Vec<dim>::Ones()); };
    return dev(eps_Z).norm() / dev(eps).norm();  // > 0 on the cone
}

template <int dim>
ReturnResult<dim> DruckerPrager<dim>::project(const Vec<dim>& Sigma, double hardening) const {
    ReturnBranch branch;
    const Vec<dim> eps_Z = project_strain(Sigma.array().log().matrix(), &branch);
    switch (branch) {
        case ReturnBranch::Apex: return {Vec<dim>::Ones(), hardening, branch, true, Vec<dim>::Zero()};
        case ReturnBranch::Elastic: return {Sigma, hardening, branch, true, eps_Z};
        default: return {eps_Z.array().exp().matrix(), hardening, branch, true, eps_Z};
    }
}

template <int dim>
double DruckerPrager<dim>::yield_function(const Vec<dim>& tau) const {
    const double tr = tau.sum();
    return (tau - tr / dim * Vec<dim>::Ones()).norm() + alpha_ * tr;
}

template <int dim>
double DruckerPrager<dim>::yield_scale(const Vec<dim>& tau) const {
    const double tr = tau.sum();
    return (tau - tr / dim * Vec<dim>::Ones()).norm() + alpha_ * std::abs(tr);
}

template class DruckerPrager<2>;
template class DruckerPrager<3>;

}  // namespace pnet
