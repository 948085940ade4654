#include "pnet/solver/implicit_options.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <type_traits>

namespace pnet {

namespace {

template <typename T>
T read_option(const nlohmann::json& block, const char* key, T value, const std::string& context, T lowest,
              const char* expected) {
    const auto it = block.find(key);
    if (it == block.end()) return value;
    const bool ok = std::is_integral_v<T> ? it->is_number_integer() : it->is_number();
    if (ok) {
        const T v = it->get<T>();
        if (std::isfinite(static_cast<double>(v)) && v >= lowest) return v;
    }
    throw std::invalid_argument(context + ": integrator." + key + ": expected " + expected + ", got " + it->dump());
}

}  // namespace

ImplicitOptions ImplicitOptions::from_json(const nlohmann::json& block, const std::string& context) {
    ImplicitOptions o;
    if (!block.is_object()) return o;
    o.newton_tolerance =
        read_option(block, "newton_tolerance", o.newton_tolerance, context, 1e-300, "a positive number (m/s)");
    o.newton_acceleration_tolerance = read_option(block, "newton_acceleration_tolerance",
                                                  o.newton_acceleration_tolerance, context, 0.0,
                                                  "a number >= 0 (m/s^2; 0: newton_tolerance alone)");
    o.max_newton_iterations =
        read_option(block, "max_newton_iterations", o.max_newton_iterations, context, 1, "an integer >= 1");
    o.max_cg_iterations = read_option(block, "max_cg_iterations", o.max_cg_iterations, context, 1, "an integer >= 1");
    o.cg_tolerance = read_option(block, "cg_tolerance", o.cg_tolerance, context, 1e-300, "a positive number");
    if (o.cg_tolerance >= 1.0)
        throw std::invalid_argument(context + ": integrator.cg_tolerance: expected a number in (0, 1), got " +
                                    std::to_string(o.cg_tolerance));
    o.fixed_point_tolerance =
        read_option(block, "fixed_point_tolerance", o.fixed_point_tolerance, context, 0.0, "a number >= 0");
    o.max_fixed_point_iterations =
        read_option(block, "max_fixed_point_iterations", o.max_fixed_point_iterations, context, 1, "an integer >= 1");
    o.fixed_point_anderson =
        read_option(block, "fixed_point_anderson", o.fixed_point_anderson, context, 0, "an integer >= 0");
    o.fixed_point_inexact =
        read_option(block, "fixed_point_inexact", o.fixed_point_inexact, context, 0.0, "a number in [0, 1)");
    if (o.fixed_point_inexact >= 1.0)
        throw std::invalid_argument(context + ": integrator.fixed_point_inexact: expected a number in [0, 1), got " +
                                    nlohmann::json(o.fixed_point_inexact).dump());
    if (const auto it = block.find("regularizer_weight"); it != block.end() && !(it->is_string() && *it == "auto"))
        o.regularizer_weight =
            read_option(block, "regularizer_weight", 0.0, context, 0.0, "a number >= 0 or \"auto\"");
    o.tangent_damping = read_option(block, "tangent_damping", o.tangent_damping, context, 0.0, "a number >= 0");
    o.analytic_regularizer =
        read_option(block, "analytic_regularizer", o.analytic_regularizer, context, 0.0, "a number >= 0");
    o.lazy_hessian = read_option(block, "lazy_hessian", o.lazy_hessian, context, 0.0, "a number in [0, 1)");
    if (o.lazy_hessian >= 1.0)
        throw std::invalid_argument(context + ": integrator.lazy_hessian: expected a number in [0, 1), got " +
                                    nlohmann::json(o.lazy_hessian).dump());
    o.advection_cfl = read_option(block, "advection_cfl", o.advection_cfl, context, 0.0, "a number in [0, 1]");
    if (o.advection_cfl > 1.0)
        throw std::invalid_argument(context + ": integrator.advection_cfl: expected a number in [0, 1], got " +
                                    nlohmann::json(o.advection_cfl).dump());
    o.max_kinematic_stages =
        read_option(block, "max_kinematic_stages", o.max_kinematic_stages, context, 0, "an integer >= 0");
    if (const auto it = block.find("fail_on_unconverged"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.fail_on_unconverged: expected true or false, got " +
                                        it->dump());
        o.fail_on_unconverged = it->get<bool>();
    }
    if (const auto it = block.find("fixed_point_keep_hessian"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(
                context + ": integrator.fixed_point_keep_hessian: expected true or false, got " + it->dump());
        o.fixed_point_keep_hessian = it->get<bool>();
    }
    if (const auto it = block.find("floor_friction_in_solve"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.floor_friction_in_solve: expected true or false, got " +
                                        it->dump());
        o.floor_friction_in_solve = it->get<bool>();
    }
    if (const auto it = block.find("fem_predictor"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.fem_predictor: expected true or false, got " +
                                        it->dump());
        o.fem_predictor = it->get<bool>();
    }
    if (const auto it = block.find("learned_return_map"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.learned_return_map: expected true or false, got " +
                                        it->dump());
        o.learned_return_map = it->get<bool>();
    }
    if (const auto it = block.find("linear_solver"); it != block.end()) {
        if (!it->is_string() || (*it != "pcg" && *it != "cholesky"))
            throw std::invalid_argument(context + ": integrator.linear_solver: expected \"pcg\" or \"cholesky\", got " +
                                        it->dump());
        o.linear_solver = it->get<std::string>();
    }
    if (const auto it = block.find("coupled_solver"); it != block.end()) {
        if (!it->is_string() || (*it != "block" && *it != "cholesky"))
            throw std::invalid_argument(
                context + ": integrator.coupled_solver: expected \"block\" or \"cholesky\", got " + it->dump());
        o.coupled_solver = it->get<std::string>();
    }
    if (const auto it = block.find("kinematic_start"); it != block.end()) {
        if (!it->is_string() || (*it != "scaled" && *it != "last_velocity"))
            throw std::invalid_argument(context + ": integrator.kinematic_start: expected \"scaled\" or "
                                        "\"last_velocity\", got " + it->dump());
        o.kinematic_start = it->get<std::string>();
    }
    if (const auto it = block.find("hessian"); it != block.end()) {
        if (!it->is_string() || (*it != "auto" && *it != "network" && *it != "tangent"))
            throw std::invalid_argument(
                context + ": integrator.hessian: expected \"auto\", \"network\" or \"tangent\", got " + it->dump());
        o.hessian = it->get<std::string>();
    }
    if (const auto it = block.find("hessian_precision"); it != block.end()) {
        if (!it->is_string() || (*it != "single" && *it != "double"))
            throw std::invalid_argument(context + ": integrator.hessian_precision: expected \"single\" or "
                                        "\"double\", got " + it->dump());
        o.hessian_precision = it->get<std::string>();
    }
    if (const auto it = block.find("outer_iteration"); it != block.end()) {
        if (!it->is_string() || (*it != "auto" && *it != "newton" && *it != "fixed_point"))
            throw std::invalid_argument(context + ": integrator.outer_iteration: expected \"auto\", \"newton\" or "
                                        "\"fixed_point\", got " + it->dump());
        o.outer_iteration = it->get<std::string>();
    }
    if (const auto it = block.find("time_integrator"); it != block.end()) {
        if (!it->is_string() || (*it != "backward_euler" && *it != "bdf2"))
            throw std::invalid_argument(context + ": integrator.time_integrator: expected \"backward_euler\" or "
                                        "\"bdf2\", got " + it->dump());
        o.time_integrator = it->get<std::string>();
    }
    if (const auto it = block.find("preconditioner"); it != block.end()) {
        if (!it->is_string() || (*it != "jacobi" && *it != "block_jacobi" && *it != "ichol" && *it != "multigrid"))
            throw std::invalid_argument(
                context + ": integrator.preconditioner: expected \"jacobi\", \"block_jacobi\", \"ichol\" or \"multigrid\", got " +
                it->dump());
        o.preconditioner = it->get<std::string>();
    }
    return o;
}

void ImplicitOptions::check_for(Method method, const std::string& context) const {
    if (method == Method::PlasticityNet && hessian == "tangent")
        throw std::invalid_argument(context + ".hessian: \"tangent\" is the return mapping's consistent tangent, "
                                    "the classical integrator's: plasticitynet steps with the network's Hessian "
                                    "(\"auto\" or \"network\"); for the tangent use the integrator return_map");
    if (method == Method::ReturnMap && hessian == "network")
        throw std::invalid_argument(context + ".hessian: \"network\" is the learned energy's, which return_map "
                                    "does not read: use the integrator plasticitynet, or hessian \"auto\"");
    if (method == Method::ReturnMap && outer_iteration == "fixed_point")
        throw std::invalid_argument(context + ".outer_iteration: \"fixed_point\" iterates the learned energy's "
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

NewtonOptions ImplicitOptions::newton_options(double dt) const {
    NewtonOptions newton;
    newton.tolerance = newton_tolerance_at(dt);
    newton.max_iterations = max_newton_iterations;
    newton.max_cg_iterations = max_cg_iterations;
    newton.cg_tolerance = cg_tolerance;
    newton.lazy_hessian = lazy_hessian;
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
    solve.floor_friction_in_solve = floor_friction_in_solve;
    return solve;
}

nlohmann::json ImplicitOptions::to_json() const {
    return {{"newton_tolerance", newton_tolerance},
            {"newton_acceleration_tolerance", newton_acceleration_tolerance},
            {"max_newton_iterations", max_newton_iterations},
            {"max_cg_iterations", max_cg_iterations},
            {"cg_tolerance", cg_tolerance},
            {"outer_iteration", outer_iteration},
            {"time_integrator", time_integrator},
            {"fixed_point_tolerance", fixed_point_tolerance},
            {"max_fixed_point_iterations", max_fixed_point_iterations},
            {"fixed_point_anderson", fixed_point_anderson},
            {"fixed_point_keep_hessian", fixed_point_keep_hessian},
            {"fixed_point_inexact", fixed_point_inexact},
            {"regularizer_weight", regularizer_weight >= 0.0 ? nlohmann::json(regularizer_weight) : nlohmann::json("auto")},
            {"tangent_damping", tangent_damping},
            {"analytic_regularizer", analytic_regularizer},
            {"hessian", hessian},
            {"hessian_precision", hessian_precision},
            {"preconditioner", preconditioner},
            {"linear_solver", linear_solver},
            {"coupled_solver", coupled_solver},
            {"lazy_hessian", lazy_hessian},
            {"fail_on_unconverged", fail_on_unconverged},
            {"max_kinematic_stages", max_kinematic_stages},
            {"kinematic_start", kinematic_start},
            {"fem_predictor", fem_predictor},
            {"learned_return_map", learned_return_map},
            {"advection_cfl", advection_cfl},
            {"floor_friction_in_solve", floor_friction_in_solve}};
}

}  // namespace pnet
