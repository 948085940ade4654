#include "pnet/solver/implicit_options.hpp"

#include <algorithm>
#include <stdexcept>

namespace pnet {

ImplicitOptions ImplicitOptions::from_json(const nlohmann::json& block, const std::string& context) {
    ImplicitOptions o;
    read_options(implicit_option_fields(), o, block, context);
    return o;
}

void ImplicitOptions::check_for(Method method, const std::string& context) const {
    if (method == Method::PlasticityNet && hessian == "tangent")
        throw std::invalid_argument(context +
                                    ".hessian: \"tangent\" is the return mapping's consistent tangent, "
                                    "the classical integrator's: plasticitynet steps with the network's Hessian "
                                    "(\"auto\" or \"network\"); for the tangent use the integrator return_map");
    if (method == Method::ReturnMap && hessian == "network")
        throw std::invalid_argument(context +
                                    ".hessian: \"network\" is the learned energy's, which return_map "
                                    "does not read: use the integrator plasticitynet, or hessian \"auto\"");
    if (method == Method::ReturnMap && outer_iteration == "fixed_point")
        throw std::invalid_argument(context +
                                    ".outer_iteration: \"fixed_point\" iterates the learned energy's "
                                    "reference (paper eq. 10), plasticitynet's: return_map solves the true residual "
                                    "by Newton (\"auto\" or \"newton\")");
}

std::string ImplicitOptions::resolved_outer_iteration() const {
    // plasticitynet's choice, measured (docs/solver.md, "The integrators"): the same for every family.
    return outer_iteration == "auto" ? plasticitynet_defaults(PlasticityModel::None).outer_iteration : outer_iteration;
}

double ImplicitOptions::newton_tolerance_at(double dt) const {
    return newton_acceleration_tolerance > 0.0 ? std::min(newton_tolerance, newton_acceleration_tolerance * dt)
                                               : newton_tolerance;
}

NewtonOptions ImplicitOptions::newton_options(double dt, Method method) const {
    NewtonOptions newton;
    newton.tolerance = newton_tolerance_at(dt);
    newton.max_iterations = max_newton_iterations;
    newton.max_cg_iterations = max_cg_iterations;
    newton.cg_tolerance = cg_tolerance;
    newton.nonsymmetric_solver = nonsymmetric_solver == "bicgstab" ? NewtonOptions::NonsymmetricSolver::Bicgstab
                                                                   : NewtonOptions::NonsymmetricSolver::Gmres;
    newton.lazy_hessian = lazy_hessian >= 0.0 ? lazy_hessian : integrator_info(method).lazy_hessian;
    return newton;
}

ReferenceSolveOptions ImplicitOptions::reference_solve_options(bool fixed_point) const {
    ReferenceSolveOptions solve;
    solve.fixed_point = fixed_point;
    solve.outer = resolved_outer_iteration() == "fixed_point" ? OuterIteration::FixedPoint : OuterIteration::Newton;
    solve.max_solves = max_fixed_point_iterations;
    solve.tolerance = fixed_point_tolerance;
    solve.anderson_depth = fixed_point_anderson;
    solve.keep_hessian = fixed_point_keep_hessian;
    solve.inexact_forcing = fixed_point_inexact;
    solve.fail_on_unconverged = fail_on_unconverged;
    return solve;
}

nlohmann::json ImplicitOptions::to_json() const {
    return options_to_json(implicit_option_fields(), *this);
}

}  // namespace pnet
