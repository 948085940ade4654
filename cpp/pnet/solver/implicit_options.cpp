#include "pnet/solver/implicit_options.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <cstdlib>

namespace pnet {

namespace {

using Kind = OptionField::Kind;
using O = ImplicitOptions;

OptionField number(const char* key, const char* flag, double lo, bool lo_open, double hi, bool hi_open,
                   double O::*member, const char* help, const char* unit = nullptr) {
    OptionField f;
    f.key = key, f.flag = flag, f.kind = Kind::Number, f.help = help;
    f.lo = lo, f.lo_open = lo_open, f.hi = hi, f.hi_open = hi_open, f.unit = unit, f.number = member;
    return f;
}
OptionField integer(const char* key, const char* flag, int lo, int hi, int O::*member, const char* help) {
    OptionField f;
    f.key = key, f.flag = flag, f.kind = Kind::Integer, f.help = help;
    f.lo = lo, f.hi = hi, f.integer = member;
    return f;
}
OptionField boolean(const char* key, const char* flag, bool O::*member, const char* help,
                    std::vector<std::string> words = {"yes", "no"}) {
    OptionField f;
    f.key = key, f.flag = flag, f.kind = Kind::Boolean, f.help = help;
    f.boolean = member, f.choices = std::move(words);
    return f;
}
OptionField choice(const char* key, const char* flag, std::vector<std::string> values, std::string O::*member,
                   const char* help) {
    OptionField f;
    f.key = key, f.flag = flag, f.kind = Kind::Choice, f.help = help;
    f.choices = std::move(values), f.text = member;
    return f;
}

constexpr double kNone = 1e300;  // no upper bound

std::vector<OptionField> make_fields() {
    OptionField regularizer = number("regularizer_weight", "--regularizer", 0.0, false, kNone, false,
                                     &O::regularizer_weight,
                                     "plasticitynet: w of the paper's eq. 11 (0: the ablation); auto: the material "
                                     "family's measured w");
    regularizer.kind = Kind::NumberOrAuto;
    OptionField lazy = number("lazy_hessian", "--lazy-hessian", 0.0, false, 1.0, true, &O::lazy_hessian,
                              "keep the last Hessian while each Newton iteration cuts the residual by this factor "
                              "(0: never); auto: the integrator's measured value (plasticitynet 0.8, the others 0.5)");
    lazy.kind = Kind::NumberOrAuto;
    return {
        number("newton_tolerance", "--newton-tol", 0.0, true, kNone, false, &O::newton_tolerance,
               "Newton's tolerance on the mass-weighted velocity residual", "m/s"),
        number("newton_acceleration_tolerance", nullptr, 0.0, false, kNone, false, &O::newton_acceleration_tolerance,
               "a step of dt stops at min(newton_tolerance, this x dt)", "m/s^2; 0: newton_tolerance alone"),
        integer("max_newton_iterations", nullptr, 1, 1000000, &O::max_newton_iterations, "Newton's iteration cap"),
        number("cg_tolerance", "--cg-tol", 0.0, true, 1.0, true, &O::cg_tolerance,
               "the largest relative residual of a Newton step's linear solve (inexact Newton)"),
        integer("max_cg_iterations", nullptr, 1, 1000000, &O::max_cg_iterations, "the linear solve's iteration cap"),
        choice("outer_iteration", "--outer-iteration", {"auto", "newton", "fixed_point"}, &O::outer_iteration,
               "plasticitynet: the reference F0 follows every Newton iterate (newton) or a whole solve (the "
               "paper's fixed_point); auto: the one measured faster"),
        choice("time_integrator", "--time-integrator", {"backward_euler", "bdf2"}, &O::time_integrator,
               "the time discretization of the implicit step"),
        choice("hessian", "--hessian", {"auto", "network", "tangent"}, &O::hessian,
               "Newton's Hessian: auto, the integrator's own (plasticitynet: the network's; return_map: the "
               "consistent tangent)"),
        choice("hessian_precision", "--hessian-precision", {"single", "double"}, &O::hessian_precision,
               "plasticitynet: the arithmetic of the network's passes at Newton's iterate (its Hessian) and from "
               "it (the line search's values, as changes from the iterate)"),
        number("fixed_point_tolerance", "--fixed-point-tol", 0.0, false, kNone, false, &O::fixed_point_tolerance,
               "plasticitynet's fixed point: max_p |F_p(v) - F0_p|"),
        integer("max_fixed_point_iterations", "--fixed-point-iterations", 1, 100000, &O::max_fixed_point_iterations,
                "plasticitynet's fixed point: the most solves per step"),
        integer("fixed_point_anderson", "--fixed-point-anderson", 0, 100, &O::fixed_point_anderson,
                "Anderson acceleration of the fixed point over this many iterates (0: the plain iteration)"),
        boolean("fixed_point_keep_hessian", "--fixed-point-keep-hessian", &O::fixed_point_keep_hessian,
                "later solves of the fixed point start from the Hessian the last one prepared"),
        number("fixed_point_inexact", "--fixed-point-inexact", 0.0, false, 1.0, true, &O::fixed_point_inexact,
               "inexact inner solves while F0 still moves: the forcing factor (0: exact solves)"),
        regularizer,
        number("tangent_damping", "--tangent-damping", 0.0, false, kNone, false, &O::tangent_damping,
               "the damping w mu of sand's and snow's tangent Hessian"),
        number("analytic_regularizer", "--analytic-regularizer", 0.0, false, kNone, false, &O::analytic_regularizer,
               "FEM analytic: + W mu/2 |F - F0|^2 under plasticitynet's outer iteration (a diagnostic)"),
        choice("preconditioner", "--preconditioner", {"jacobi", "block_jacobi", "ichol", "multigrid"},
               &O::preconditioner, "the linear solve's preconditioner (ichol, multigrid: MPM)"),
        choice("multigrid_rebuild", "--multigrid-rebuild", {"step", "hessian"}, &O::multigrid_rebuild,
               "preconditioner multigrid: built once per step, or at every Hessian pass"),
        choice("linear_solver", nullptr, {"pcg", "cholesky"}, &O::linear_solver,
               "MPM's linear solve: matrix-free PCG or CHOLMOD on the assembled Hessian"),
        choice("coupled_solver", nullptr, {"block", "cholesky"}, &O::coupled_solver,
               "MPM-FEM coupling's linear solve: PCG with an exact FEM block, or CHOLMOD on the whole Hessian"),
        lazy,
        boolean("fail_on_unconverged", "--fail-on-unconverged", &O::fail_on_unconverged,
                "a step whose solve ends unconverged is an error", {}),
        integer("max_kinematic_stages", nullptr, 0, 1000000, &O::max_kinematic_stages,
                "FEM: the most extra solves per step that lead kinematic nodes to their targets"),
        choice("kinematic_start", "--kinematic-start", {"scaled", "last_velocity"}, &O::kinematic_start,
               "FEM with kinematic nodes: the start of a step that CCD holds back"),
        boolean("fem_predictor", nullptr, &O::fem_predictor,
                "FEM plasticitynet under newton: start from the elastic energy's solution"),
        boolean("learned_return_map", "--return-map", &O::learned_return_map,
                "plasticitynet: a model's learned return mapping, or the material's exact one", {"learned", "exact"}),
        number("advection_cfl", "--advection-cfl", 0.0, false, 1.0, false, &O::advection_cfl,
               "MPM: cap a step so that no particle moves more than this many cells (0: off)"),
        boolean("floor_friction_in_solve", "--floor-friction-in-solve", &O::floor_friction_in_solve,
                "a Coulomb floor's friction follows the Newton iterates in one solve (no: three passes)"),
    };
}

std::string range_text(const OptionField& f) {
    const bool bounded = f.hi < kNone;
    const auto show = [](double x) {
        nlohmann::json j = x;
        std::string t = j.dump();
        if (t.size() > 2 && t.compare(t.size() - 2, 2, ".0") == 0) t.resize(t.size() - 2);
        return t;
    };
    std::string text;
    if (f.kind == Kind::Integer)
        text = "an integer >= " + show(f.lo);
    else if (bounded)
        text = "a number in " + std::string(f.lo_open ? "(" : "[") + show(f.lo) + ", " + show(f.hi) +
               (f.hi_open ? ")" : "]");
    else if (f.lo_open && f.lo == 0.0)
        text = "a positive number";
    else
        text = std::string("a number ") + (f.lo_open ? "> " : ">= ") + show(f.lo);
    if (f.unit) text += std::string(" (") + f.unit + ")";
    return text;
}

std::string listed(const std::vector<std::string>& words, bool quoted) {
    std::string text;
    for (std::size_t k = 0; k < words.size(); ++k) {
        if (k > 0) text += k + 1 == words.size() ? " or " : ", ";
        text += quoted ? "\"" + words[k] + "\"" : words[k];
    }
    return text;
}

bool in_range(const OptionField& f, double x) {
    return std::isfinite(x) && (f.lo_open ? x > f.lo : x >= f.lo) && (f.hi_open ? x < f.hi : x <= f.hi);
}

}  // namespace

std::string OptionField::expected() const {
    switch (kind) {
        case Kind::Boolean: return "true or false";
        case Kind::Choice: return listed(choices, true);
        case Kind::NumberOrAuto: return range_text(*this) + " or \"auto\"";
        default: return range_text(*this);
    }
}

std::string OptionField::flag_expected() const {
    switch (kind) {
        case Kind::Boolean: return choices.empty() ? "no value" : listed(choices, false);
        case Kind::Choice: return listed(choices, false);
        case Kind::NumberOrAuto: return range_text(*this) + " or auto";
        default: return range_text(*this);
    }
}

bool OptionField::accepts(const nlohmann::json& value) const {
    switch (kind) {
        case Kind::Boolean: return value.is_boolean();
        case Kind::Choice:
            return value.is_string() &&
                   std::find(choices.begin(), choices.end(), value.get<std::string>()) != choices.end();
        case Kind::Integer: return value.is_number_integer() && in_range(*this, value.get<double>());
        case Kind::NumberOrAuto:
            if (value.is_string() && value == "auto") return true;
            [[fallthrough]];
        case Kind::Number: return value.is_number() && in_range(*this, value.get<double>());
    }
    return false;
}

nlohmann::json OptionField::get(const ImplicitOptions& o) const {
    switch (kind) {
        case Kind::Boolean: return o.*boolean;
        case Kind::Choice: return o.*text;
        case Kind::Integer: return o.*integer;
        case Kind::NumberOrAuto: return o.*number >= 0.0 ? nlohmann::json(o.*number) : nlohmann::json("auto");
        case Kind::Number: return o.*number;
    }
    return nullptr;
}

void OptionField::set(ImplicitOptions& o, const nlohmann::json& value) const {
    switch (kind) {
        case Kind::Boolean: o.*boolean = value.get<bool>(); break;
        case Kind::Choice: o.*text = value.get<std::string>(); break;
        case Kind::Integer: o.*integer = value.get<int>(); break;
        case Kind::NumberOrAuto: o.*number = value.is_string() ? -1.0 : value.get<double>(); break;
        case Kind::Number: o.*number = value.get<double>(); break;
    }
}

std::optional<nlohmann::json> OptionField::parse_flag(const std::string& word) const {
    nlohmann::json value;
    switch (kind) {
        case Kind::Boolean:
            if (choices.empty()) return nlohmann::json(true);  // a switch
            if (word == choices[0]) return nlohmann::json(true);
            if (word == choices[1]) return nlohmann::json(false);
            return std::nullopt;
        case Kind::Choice: value = word; break;
        case Kind::NumberOrAuto:
            if (word == "auto") return nlohmann::json("auto");
            [[fallthrough]];
        case Kind::Number:
        case Kind::Integer: {
            char* end = nullptr;
            const double x = std::strtod(word.c_str(), &end);
            if (word.empty() || end != word.c_str() + word.size()) return std::nullopt;
            if (kind == Kind::Integer) {
                if (x != std::floor(x) || std::abs(x) > 2e9) return std::nullopt;
                value = static_cast<long>(x);
            } else {
                value = x;
            }
            break;
        }
    }
    if (!accepts(value)) return std::nullopt;
    return value;
}

const std::vector<OptionField>& implicit_option_fields() {
    static const std::vector<OptionField> fields = make_fields();
    return fields;
}

const OptionField* find_option_field(const std::string& key_or_flag) {
    for (const OptionField& f : implicit_option_fields())
        if (key_or_flag == f.key || (f.flag && key_or_flag == f.flag)) return &f;
    return nullptr;
}

ImplicitOptions ImplicitOptions::from_json(const nlohmann::json& block, const std::string& context) {
    ImplicitOptions o;
    if (!block.is_object()) return o;
    for (const auto& [key, value] : block.items()) {
        if (key == "name" || key == "dt" || key == "cfl") continue;  // the scene's
        const OptionField* f = find_option_field(key);
        if (!f || key != f->key) {
            std::string known;
            for (const OptionField& field : implicit_option_fields()) known += (known.empty() ? "" : ", ") + std::string(field.key);
            throw std::invalid_argument(context + ": integrator." + key + ": unknown key (known: name, dt, cfl, " +
                                        known + ")");
        }
        if (!f->accepts(value))
            throw std::invalid_argument(context + ": integrator." + key + ": expected " + f->expected() + ", got " +
                                        value.dump());
        f->set(o, value);
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
    solve.floor_friction_in_solve = floor_friction_in_solve;
    return solve;
}

nlohmann::json ImplicitOptions::to_json() const {
    nlohmann::json j = nlohmann::json::object();
    for (const OptionField& f : implicit_option_fields()) j[f.key] = f.get(*this);
    return j;
}

}  // namespace pnet
