#include "pnet/solver/implicit_options.hpp"

#include <algorithm>
#include <stdexcept>

namespace pnet {

namespace {

using O = ImplicitOptions;

std::vector<OptionField<O>> make_fields() {
    OptionField<O> regularizer = number_or_auto_option(
        "regularizer_weight", "--regularizer", 0.0, false, kNoBound, false, &O::regularizer_weight,
        "plasticitynet: w of the paper's eq. 11 (0: the ablation); auto: the material "
        "family's measured w");
    OptionField<O> lazy =
        number_or_auto_option("lazy_hessian", "--lazy-hessian", 0.0, false, 1.0, true, &O::lazy_hessian,
                              "keep the last Hessian while each Newton iteration cuts the residual by this factor "
                              "(0: never); auto: the integrator's measured value (plasticitynet 0.8, return_map 0.1, the others 0.5)");
    return {
        number_option("newton_tolerance", "--newton-tol", 0.0, true, kNoBound, false, &O::newton_tolerance,
                      "Newton's tolerance on the mass-weighted velocity residual", "m/s"),
        number_option("newton_acceleration_tolerance", nullptr, 0.0, false, kNoBound, false,
                      &O::newton_acceleration_tolerance, "a step of dt stops at min(newton_tolerance, this x dt)",
                      "m/s^2; 0: newton_tolerance alone"),
        integer_option("max_newton_iterations", nullptr, 1, 1000000, &O::max_newton_iterations,
                       "Newton's iteration cap"),
        number_option("cg_tolerance", "--cg-tol", 0.0, true, 1.0, true, &O::cg_tolerance,
                      "the largest relative residual of a Newton step's linear solve (inexact Newton)"),
        integer_option("max_cg_iterations", nullptr, 1, 1000000, &O::max_cg_iterations,
                       "the linear solve's iteration cap"),
        choice_option("outer_iteration", "--outer-iteration", {"auto", "newton", "fixed_point"}, &O::outer_iteration,
                      "plasticitynet: the reference F0 follows every Newton iterate (newton) or a whole solve (the "
                      "paper's fixed_point); auto: the one measured faster"),
        choice_option("time_integrator", "--time-integrator", {"backward_euler", "bdf2"}, &O::time_integrator,
                      "the time discretization of the implicit step"),
        choice_option("hessian", "--hessian", {"auto", "network", "tangent"}, &O::hessian,
                      "Newton's Hessian: auto, the integrator's own (plasticitynet: the network's; return_map: the "
                      "consistent tangent)"),
        choice_option(
            "hessian_precision", "--hessian-precision", {"single", "double"}, &O::hessian_precision,
            "plasticitynet: the arithmetic of the network's passes at Newton's iterate (its Hessian) and from "
            "it (the line search's values, as changes from the iterate)"),
        number_option("network_reuse", "--network-reuse", 0.0, false, kNoBound, false, &O::network_reuse,
                      "plasticitynet: a particle's network Hessian is kept while its reference F moves less than "
                      "this (largest entry), and a line search's point this close is valued by the expansion"),
        number_option("fixed_point_tolerance", "--fixed-point-tol", 0.0, false, kNoBound, false,
                      &O::fixed_point_tolerance, "plasticitynet's fixed point: max_p |F_p(v) - F0_p|"),
        integer_option("max_fixed_point_iterations", "--fixed-point-iterations", 1, 100000,
                       &O::max_fixed_point_iterations, "plasticitynet's fixed point: the most solves per step"),
        integer_option("fixed_point_anderson", "--fixed-point-anderson", 0, 100, &O::fixed_point_anderson,
                       "Anderson acceleration of the fixed point over this many iterates (0: the plain iteration)"),
        boolean_option("fixed_point_keep_hessian", "--fixed-point-keep-hessian", &O::fixed_point_keep_hessian,
                       "later solves of the fixed point start from the Hessian the last one prepared"),
        number_option("fixed_point_inexact", "--fixed-point-inexact", 0.0, false, 1.0, true, &O::fixed_point_inexact,
                      "inexact inner solves while F0 still moves: the forcing factor (0: exact solves)"),
        regularizer,
        number_option("tangent_damping", "--tangent-damping", 0.0, false, kNoBound, false, &O::tangent_damping,
                      "the damping w mu of sand's and snow's tangent Hessian"),
        number_option("analytic_regularizer", "--analytic-regularizer", 0.0, false, kNoBound, false,
                      &O::analytic_regularizer,
                      "FEM analytic: + W mu/2 |F - F0|^2 under plasticitynet's outer iteration (a diagnostic)"),
        choice_option("preconditioner", "--preconditioner", {"jacobi", "block_jacobi", "ichol", "multigrid"},
                      &O::preconditioner, "the linear solve's preconditioner (ichol, multigrid: MPM)"),
        choice_option("multigrid_rebuild", "--multigrid-rebuild", {"step", "hessian"}, &O::multigrid_rebuild,
                      "preconditioner multigrid: built once per step, or at every Hessian pass"),
        lazy,
        boolean_option("fail_on_unconverged", "--fail-on-unconverged", &O::fail_on_unconverged,
                       "a step whose solve ends unconverged is an error", {}),
        boolean_option("learned_return_map", "--return-map", &O::learned_return_map,
                       "plasticitynet: a model's learned return mapping, or the material's exact one",
                       {"learned", "exact"}),
    };
}

}  // namespace

const std::vector<OptionField<ImplicitOptions>>& implicit_option_fields() {
    static const std::vector<OptionField<ImplicitOptions>> fields = make_fields();
    return fields;
}

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
