#pragma once
// The solver's settings of every implicit integrator (MPM, FEM, coupling): Newton's tolerances and
// caps, the outer iteration on F0, the time discretization, the Hessian, the network's passes and the
// linear solve's preconditioner (docs/solver.md). A scene gives them as keys of its "integrator"
// block; `pnet simulate` and Python can override them. Each key is declared once, in
// implicit_option_fields(); the methods' own options live with them (mpm/mpm_options,
// fem/fem_options, coupling/coupling_options), and sim/integrator_settings joins the tables.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/integrators.hpp"
#include "pnet/solver/newton.hpp"
#include "pnet/solver/option_field.hpp"

namespace pnet {

/// Solver settings of the implicit integrators. In a scene they are keys of the
/// "integrator" block (same names); the command line can override some.
struct ImplicitOptions {
    // m/s: the mass-weighted velocity residual sqrt(sum_i g_i^2 / H_ii / sum_i m_i) over the free
    // components (NewtonOptions::residual_mass; E - min E ~ M r^2 / 2) a step may leave, and
    // m/s^2: that residual per unit of step. A step of dt stops at min(newton_tolerance,
    // newton_acceleration_tolerance dt) (newton_tolerance_at()): the same 1e-3 m/s as a fixed velocity
    // from 1e-3 s up, and a force balanced to 1 m/s^2 below. A fixed velocity alone let the solve of a
    // short step stop before it began: at 1e-5 s the forces change a velocity by about g dt = 1e-4 m/s,
    // and most steps took no Newton step at all (docs/solver.md). 0: the fixed velocity alone.
    double newton_tolerance = 1e-3;
    double newton_acceleration_tolerance = 1.0;
    int max_newton_iterations = 50;
    int max_cg_iterations = 500;
    double cg_tolerance = 0.1;  // largest relative PCG residual (inexact Newton)
    // plasticitynet: how the reference F0 follows F(v) (solver/fixed_point.hpp, docs/solver.md):
    // "newton", F0 = F(v) at every Newton iterate, one solve converged on the true residual; or
    // "fixed_point", the paper's eq. 10, a full solve per F0 (the keys fixed_point_* below); "auto"
    // (the default), the one measured faster at the same accuracy (resolved_outer_iteration()).
    // return_map: always "newton".
    std::string outer_iteration = "auto";
    // The time discretization of the implicit step: "backward_euler" (first order) or "bdf2" (second
    // order, FEM: x^{n+1} = x^ + beta dt v^{n+1}, v^{n+1} = v^ + beta dt a^{n+1} with beta = 2/3,
    // x^ = (4 x^n - x^{n-1}) / 3, v^ = (4 v^n - v^{n-1}) / 3: the same incremental potential about x^ with
    // the step beta dt; the first step, without history, is backward Euler).
    std::string time_integrator = "backward_euler";
    double fixed_point_tolerance = 1e-3;  // max_p ||F_p(v) - F0_p||_F (plasticitynet)
    // Solves per step (plasticitynet): the fixed point on F0 is converged to
    // fixed_point_tolerance, with this cap. On sand_column_2d at dt 1e-3 one
    // solve (F0 = F(v*) only) left the deposit's spread 5.7% short of the
    // explicit ground truth (outside the noise floor: explicit at 2e-5 +2.2%,
    // at CFL +3.7%); converged it is +1.7%, at 3.6x the cost (about 3 solves
    // per step; notebooks/results/implicit_eval).
    int max_fixed_point_iterations = 8;
    // Anderson acceleration of the fixed point over this many iterates (0: the
    // plain iteration; solver/fixed_point.hpp).
    int fixed_point_anderson = 0;
    // The fixed point's solves after the first start from the Hessian the previous one prepared
    // (a modified Newton start, ReferenceSolveOptions::keep_hessian): a gradient pass instead of a
    // Hessian pass per solve. MPM and MPM-FEM coupling; FEM's direct solver ignores it. On
    // sand_column_2d (10 frames, 1 thread) 89 -> 61 ms per step at the same Newton and CG counts; with
    // the energy's reuse of set_reference's pass at F = F0, 51 ms (issue 19; fixed_point_anderson 3
    // cut the solves on sand_column_2d but added 29% on snowball_2d, fixed_point_inexact saved nothing:
    // the later solves already take one Newton step; notebooks/results/implicit_eval/solver_comparison.md).
    bool fixed_point_keep_hessian = true;
    // Inexact inner solves while F0 still moves: a later solve of the fixed point whose F0 moved by
    // more than fixed_point_tolerance stops once its residual has fallen by this factor (0: exact
    // solves; ReferenceSolveOptions::inexact_forcing). MPM and MPM-FEM coupling.
    double fixed_point_inexact = 0.0;
    // w of eq. 11 (plasticitynet; 0: the ablation); < 0 (the default, "auto" in a scene): the
    // material family's measured w (plasticitynet_defaults(), solver/integrators.hpp).
    double regularizer_weight = -1.0;
    // plasticitynet, hessian "auto" on non-associative flow (Drucker-Prager sand, Cam-Clay snow): the w
    // that damps their symmetrized tangent (which is not the residual's Jacobian), in units of the
    // shear modulus; it shapes Newton's steps only. With the paper's w = 1 Newton converged at ~0.7
    // per iteration and a solve stopped by its tolerance was biased toward v*: a tall granular column
    // ran out 4% short (docs/solver.md, "Which Hessian").
    double tangent_damping = kDefaultTangentDamping;
    // The Hessian of Newton's steps, "auto" (the default): the integrator's own, which is the only one
    // it takes. plasticitynet: "network", E [Hess N + w mu I] projected to PSD (the paper's);
    // return_map: "tangent", the return mapping's consistent tangent (+ w mu I for non-associative
    // flow, w = tangent_damping). Each refuses the other's (check_for()).
    std::string hessian = "auto";
    // plasticitynet: the arithmetic of the network's passes at Newton's iterate (its Hessian) and from it
    // (the line search's trial values, as float passes of the change N(F) - N(F0)): "single" (the
    // default: float, twice the particles per instruction; measured in docs/integrators.md) or
    // "double". The gradient Newton solves with is double either way
    // (NeuralElastoplasticEnergy::Options::hessian_precision).
    std::string hessian_precision = "single";
    // plasticitynet under the rebased Newton: a tolerance on F below which the network is not evaluated
    // again for a particle (its Hessian kept while its reference moves less, a line search's trial
    // point that close to the reference valued by the energy's second-order expansion; 0: never reused;
    // NeuralElastoplasticEnergy::Options::network_reuse). 1e-4: measured in docs/integrators.md.
    double network_reuse = 1e-4;
    // FEM `analytic` only, a diagnostic: > 0 adds w mu/2 ||F - F0||^2 about a reference to the
    // closed-form energy and solves with plasticitynet's predictor and outer iteration on F0, the
    // learned energy's solve without its learning error (AnalyticElastoplasticEnergy).
    double analytic_regularizer = 0.0;
    // PCG preconditioner: "jacobi", "block_jacobi" (the d x d block of each
    // node), "ichol" (incomplete Cholesky of the assembled grid Hessian; MPM only) or "multigrid" (Galerkin
    // multigrid on the grid, built once per step; MPM only; solver/multigrid.hpp). Jacobi is the default: block
    // Jacobi saved 2-3% of the CG iterations on sand_column_2d and snowball_2d (measured), not its cost; the
    // multigrid cuts the Krylov iterations 1.2-3.6x and costs 2-4x the step at today's sizes (docs/solver.md).
    std::string preconditioner = "jacobi";
    // preconditioner "multigrid": its hierarchy is built from the step's first Hessian and kept for the
    // step's solves ("step"), or rebuilt at every Hessian pass ("hessian": fewer Krylov iterations, a
    // build per Newton iteration; docs/solver.md, "Multigrid on the MPM grid").
    std::string multigrid_rebuild = "step";
    // The Krylov method for a Hessian with a skew part (Objective::hessian_symmetric() false: the
    // consistent tangent of non-associative flow, the Coulomb floor's friction in the one solve):
    // "gmres" (the default: restarted GMRES, one product per iteration and the least residual over the
    // Krylov space built so far, in Newton's norm) or "bicgstab" (two products per iteration). Measured
    // 2026-11-30 (docs/solver.md, "GMRES for the tangent's skew part"): GMRES takes 24-36% fewer Hessian
    // products per Newton iteration on every MPM scene measured, and as many Newton iterations on the sand
    // (5% and 27% more on the snowball and the stiff snowball). A symmetric Hessian is solved by PCG either way.
    std::string nonsymmetric_solver = "gmres";
    // Newton keeps the last Hessian while each iteration cuts the residual by
    // this factor (NewtonOptions::lazy_hessian; 0: a fresh one every
    // iteration); -1 ("auto", the default): the integrator's measured value
    // (IntegratorInfo::lazy_hessian: plasticitynet 0.8, return_map 0.1, the others 0.5). 0.5 halved
    // the energy time on sand_column_2d and cut it by 40% on snowball_2d at dt 1e-3,
    // with as many or fewer Newton iterations.
    double lazy_hessian = -1.0;
    // A step whose solve ends unconverged (iteration cap or failed line search)
    // is an error (SimulationError) instead of being counted and used.
    bool fail_on_unconverged = false;
    // plasticitynet: after each step, the return mapping of a model that ships
    // one (metal_nh_2d.pt: metal_nh_rm_2d.pt) instead of the material's exact
    // one; false: the material library's (for the comparison of the two).
    bool learned_return_map = true;

    /// Throws std::invalid_argument "<context>.<key>: ..." for a combination `method` does not take:
    /// plasticitynet with hessian "tangent" (the classical integrator's, return_map), return_map with
    /// hessian "network" or outer_iteration "fixed_point" (plasticitynet's).
    void check_for(Method method, const std::string& context) const;
    /// plasticitynet's outer iteration with "auto" resolved ("newton" or "fixed_point").
    std::string resolved_outer_iteration() const;
    /// plasticitynet's w for an object of `family`: regularizer_weight, or the family's when "auto".
    double resolved_regularizer_weight(PlasticityModel family) const {
        return regularizer_weight >= 0.0 ? regularizer_weight : plasticitynet_defaults(family).regularizer_weight;
    }

    /// Reads the keys of implicit_option_fields() from an integrator block (name, dt and cfl, which
    /// the block also holds, are the scene's). Throws std::invalid_argument
    /// "<context>: integrator.<key>: <problem>" for a wrong type or range, or a key that is none of
    /// these (naming the known ones).
    static ImplicitOptions from_json(const nlohmann::json& block, const std::string& context);
    /// The Newton loop's settings from these for a step of dt s (tolerance newton_tolerance_at(dt),
    /// iteration caps, CG tolerance, lazy Hessian); the caller adds its residual masses and linear
    /// solver.
    NewtonOptions newton_options(double dt, Method method) const;
    /// m/s: min(newton_tolerance, newton_acceleration_tolerance dt), or newton_tolerance where the
    /// acceleration tolerance is 0.
    double newton_tolerance_at(double dt) const;
    /// The step's solve settings from these: the fixed point on F0 when `fixed_point`, its cap,
    /// tolerance, acceleration, Hessian reuse and inexact inner solves.
    ReferenceSolveOptions reference_solve_options(bool fixed_point) const;
    nlohmann::json to_json() const;
    /// `hessian` as the learned energy's option.
    template <int dim>
    typename NeuralElastoplasticEnergy<dim>::Options::Hessian neural_hessian() const {
        using Hessian = typename NeuralElastoplasticEnergy<dim>::Options::Hessian;
        return hessian == "tangent" ? Hessian::Tangent : Hessian::Network;
    }
    /// `hessian_precision` as the fused kernel's.
    FusedMlp::Precision network_hessian_precision() const {
        return hessian_precision == "double" ? FusedMlp::Precision::Double : FusedMlp::Precision::Single;
    }
};

/// Every key of ImplicitOptions, in the order --help lists them (the other layers' options:
/// sim/integrator_settings.hpp).
inline const std::vector<OptionField<ImplicitOptions>>& implicit_option_fields() {
    using O = ImplicitOptions;
    static const std::vector<OptionField<O>> fields = []() -> std::vector<OptionField<O>> {
        OptionField<O> regularizer = number_or_auto_option(
            "regularizer_weight", "--regularizer", 0.0, false, kNoBound, false, &O::regularizer_weight,
            "plasticitynet: w of the paper's eq. 11 (0: the ablation); auto: the material "
            "family's measured w");
        OptionField<O> lazy = number_or_auto_option(
            "lazy_hessian", "--lazy-hessian", 0.0, false, 1.0, true, &O::lazy_hessian,
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
            choice_option("outer_iteration", "--outer-iteration", {"auto", "newton", "fixed_point"},
                          &O::outer_iteration,
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
            number_option("fixed_point_inexact", "--fixed-point-inexact", 0.0, false, 1.0, true,
                          &O::fixed_point_inexact,
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
            choice_option("nonsymmetric_solver", "--nonsymmetric-solver", {"gmres", "bicgstab"},
                          &O::nonsymmetric_solver,
                          "the Krylov method for a Hessian with a skew part (sand's and snow's tangent, the Coulomb "
                          "floor's friction): restarted GMRES or BiCGSTAB"),
            lazy,
            boolean_option("fail_on_unconverged", "--fail-on-unconverged", &O::fail_on_unconverged,
                           "a step whose solve ends unconverged is an error", {}),
            boolean_option("learned_return_map", "--return-map", &O::learned_return_map,
                           "plasticitynet: a model's learned return mapping, or the material's exact one",
                           {"learned", "exact"}),
        };
    }();
    return fields;
}

}  // namespace pnet
