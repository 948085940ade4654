#include "pnet/solver/newton.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <omp.h>

#include <Eigen/CholmodSupport>

#include "pnet/solver/pcg.hpp"

namespace pnet {

namespace {

/// The residual of NewtonOptions at a point with gradient g; `diagonal` is
/// diag(H) of the Hessian prepared last.
double residual_of(const VecX& g, const NewtonOptions& options, const VecX& diagonal) {
    const VecX& mass = options.residual_mass;
    if (mass.size() != 0) {
        double energy = 0.0, total_mass = 0.0;
        for (Eigen::Index i = 0; i < g.size(); ++i)
            if (mass[i] > 0.0) {
                energy += g[i] * g[i] / diagonal[i];
                total_mass += mass[i];
            }
        return total_mass > 0.0 ? std::sqrt(energy / total_mass) : 0.0;
    }
    const VecX& scale = options.residual_scale;
    if (scale.size() == 0) return g.lpNorm<Eigen::Infinity>();
    return g.cwiseProduct(scale).lpNorm<Eigen::Infinity>();
}

/// The BLAS CHOLMOD calls (OpenBLAS, built on OpenMP) splits its sums by the OpenMP thread
/// count, so results would change with it in the last bit (measured on the 3D tiny frame:
/// 2.5e-16 m after one frame): factorizations and solves run with one thread.
class OneBlasThread {
public:
    OneBlasThread() : saved_(omp_get_max_threads()) { omp_set_num_threads(1); }
    ~OneBlasThread() { omp_set_num_threads(saved_); }
    OneBlasThread(const OneBlasThread&) = delete;
    OneBlasThread& operator=(const OneBlasThread&) = delete;

private:
    int saved_;
};

/// CHOLMOD's Cholesky of the objective's assembled Hessian, keeping the symbolic
/// analysis while the sparsity pattern stays the same. CHOLMOD picks supernodal
/// (BLAS on dense blocks) or simplicial LDL^T by the factor's flops per nonzero:
/// the supernodal one took 2x the time on the 2D metal frame (2220 unknowns:
/// 4.8 against 2.3 s for 10 frames), where the blocks are too small for BLAS.
class DirectSolver {
public:
    DirectSolver() {
        // LL^T whether supernodal or simplicial: CHOLMOD's simplicial LDL^T (its default, final_asis)
        // factorizes an indefinite matrix without a complaint, and the Newton direction would climb.
        cholesky_.cholmod().final_asis = 0;
        cholesky_.cholmod().final_ll = 1;
    }
    /// Factorizes H; false if H is not positive definite.
    bool factorize(const SparseMatrix& H, NewtonStats& stats) {
        const OneBlasThread one;
        if (!same_pattern(H)) {
            cholesky_.analyzePattern(H);
            outer_.assign(H.outerIndexPtr(), H.outerIndexPtr() + H.outerSize() + 1);
            inner_.assign(H.innerIndexPtr(), H.innerIndexPtr() + H.nonZeros());
            ++stats.analyses;
        }
        cholesky_.factorize(H);
        ++stats.factorizations;
        return cholesky_.info() == Eigen::Success;
    }
    void solve(const VecX& b, VecX& x) {
        const OneBlasThread one;
        x = cholesky_.solve(b);
    }

private:
    bool same_pattern(const SparseMatrix& H) const {
        return !outer_.empty() && static_cast<Eigen::Index>(outer_.size()) == H.outerSize() + 1 &&
               static_cast<Eigen::Index>(inner_.size()) == H.nonZeros() &&
               std::equal(outer_.begin(), outer_.end(), H.outerIndexPtr()) &&
               std::equal(inner_.begin(), inner_.end(), H.innerIndexPtr());
    }
    Eigen::CholmodDecomposition<SparseMatrix, Eigen::Upper> cholesky_;  // CHOLMOD transposes a lower one first
    std::vector<SparseMatrix::StorageIndex> outer_, inner_;
};

// Rebased solves' Levenberg-Marquardt damping (Objective::set_damping), in units of the shear modulus:
// the first weight, and the largest (the paper's regularizer w = 1, whose iteration always contracts).
constexpr double kFirstDamping = 1e-2;
constexpr double kMaxDamping = 1.0;
// GMRES's restart (NewtonOptions::nonsymmetric_solver): the MPM solves take 2-20 products per Newton iteration.
constexpr int kGmresRestart = 30;

std::string where(const std::string& context, int iteration, double residual) {
    char text[160];
    std::snprintf(text, sizeof text,
                  "%sNewton iteration %d (residual %.3e): ", context.empty() ? "" : (context + ": ").c_str(), iteration,
                  residual);
    return text;
}

/// The symmetric parts of consecutive b x b row-major blocks, in place: the block-Jacobi
/// preconditioner of a Hessian with a skew part (its diagonal blocks' symmetric parts are those of
/// the PSD part S plus inertia).
void symmetrize_blocks(VecX& blocks, int b) {
    for (Eigen::Index k = 0; k + b * b <= blocks.size(); k += b * b)
        for (int i = 0; i < b; ++i)
            for (int j = i + 1; j < b; ++j) {
                const double mean = 0.5 * (blocks[k + i * b + j] + blocks[k + j * b + i]);
                blocks[k + i * b + j] = blocks[k + j * b + i] = mean;
            }
}

}  // namespace

double newton_residual(const Objective& objective, const VecX& g, const NewtonOptions& options) {
    VecX diagonal(g.size());
    objective.hessian_diagonal(diagonal);
    return residual_of(g, options, diagonal);
}

struct NewtonWorkspace::Impl {
    DirectSolver direct;
    GmresWorkspace gmres;  // its Krylov basis, n x 31
};
NewtonWorkspace::NewtonWorkspace() : impl_(std::make_unique<Impl>()) {}
NewtonWorkspace::~NewtonWorkspace() = default;
NewtonWorkspace::NewtonWorkspace(NewtonWorkspace&&) noexcept = default;
NewtonWorkspace& NewtonWorkspace::operator=(NewtonWorkspace&&) noexcept = default;

NewtonStats minimize(Objective& objective, VecX& x, const NewtonOptions& options, const std::string& context,
                     NewtonWorkspace* workspace) {
    const Eigen::Index n = objective.size();
    if (x.size() != n) throw std::invalid_argument("minimize: x has the wrong size");
    if (options.residual_scale.size() != 0 && options.residual_scale.size() != n)
        throw std::invalid_argument("minimize: residual_scale has the wrong size");
    if (options.residual_mass.size() != 0 && options.residual_mass.size() != n)
        throw std::invalid_argument("minimize: residual_mass has the wrong size");
    NewtonStats stats;
    // Work vectors: sized once per solve; PCG keeps its own between calls.
    VecX g(n), g_trial(n), d(n), diagonal(n), x_trial(n), blocks;
    PcgWorkspace pcg;
    BicgstabWorkspace bicgstab;
    const bool use_gmres = options.nonsymmetric_solver == NewtonOptions::NonsymmetricSolver::Gmres;
    Preconditioner preconditioner;
    std::unique_ptr<NewtonWorkspace> local;
    if (!workspace) workspace = (local = std::make_unique<NewtonWorkspace>()).get();
    DirectSolver& direct = workspace->impl().direct;
    GmresWorkspace& gmres = workspace->impl().gmres;
    VecX gmres_weight;
    const int block = options.block_preconditioner ? objective.hessian_block_size() : 1;
    const bool lazy = options.lazy_hessian > 0.0;
    const bool symmetric = objective.hessian_symmetric();
    int ichol_hessians = -1;  // the Hessian count at the incomplete Cholesky factorization
    // Every iterate's Hessian is prepared before its direction is computed:
    // at the start by value_gradient_hessian (or kept, keep_prepared_hessian),
    // later by the full step's evaluation or by prepare_hessian when a lazy one
    // may not be kept.
    double energy;
    bool contracted = false;  // the last iterate was reached by a full step that cut the residual enough
    if (options.rebase && objective.rebase(x)) ++stats.rebases;
    // Rebased solves: the proximal damping of the Levenberg-Marquardt rule below (0: none).
    const bool work_search = options.rebase && options.work_line_search;
    const bool damped = options.rebase && !work_search && objective.set_damping(0.0);
    double work_energy = 0.0;  // work_search: the potential's change from the start, J
    double damping = 0.0;
    if (options.keep_prepared_hessian) {
        energy = objective.value_gradient(x, g);
        contracted = true;  // the kept Hessian is treated as a lazy one
    } else {
        energy = objective.value_gradient_hessian(x, g);
        ++stats.hessians;
    }
    objective.hessian_diagonal(diagonal);
    double residual = residual_of(g, options, diagonal);
    stats.initial_energy = stats.energy = energy;
    stats.initial_residual = stats.residual = residual;
    if (!std::isfinite(energy) || !g.allFinite())
        throw NewtonError(where(context, 0, residual) + "the energy or its gradient is not finite at the start");
    const double g0 = std::max(g.norm(), 1e-300);
    const double target = std::max(options.tolerance, options.relative_tolerance * residual);

    // Rebased solves: the fresh Hessian an iterate is owed (below) is prepared only once the iterate
    // did not already meet the tolerance (tested with the last Hessian's diagonal, as a lazily kept
    // one is): a converged solve's last iterate costs no Hessian pass.
    bool hessian_owed = false;
    for (int it = 0; it < options.max_iterations; ++it) {
        if (residual <= target && (it >= options.min_iterations || !(residual > 0.0))) {
            stats.converged = true;
            break;
        }
        if (hessian_owed) {
            objective.prepare_hessian(x);
            ++stats.hessians;
            hessian_owed = false;
            objective.hessian_diagonal(diagonal);
            residual = residual_of(g, options, diagonal);
        }
        // A Hessian with a skew part (Objective::hessian_symmetric) has no Cholesky factorization and
        // no CG: BiCGSTAB with the same preconditioners.
        const SparseMatrix* H = options.linear_solver == NewtonOptions::LinearSolver::Cholesky && symmetric
                                    ? objective.hessian_matrix()
                                    : nullptr;
        if (H && direct.factorize(*H, stats)) {
            direct.solve(-g, d);
        } else {
            const SparseMatrix* assembled = options.incomplete_cholesky ? objective.hessian_matrix() : nullptr;
            if (objective.has_preconditioner()) {
                preconditioner.set_objective(objective);
            } else if (assembled) {
                if (stats.hessians != ichol_hessians) {  // a new Hessian since the last factorization
                    preconditioner.set_incomplete_cholesky(*assembled);
                    ichol_hessians = stats.hessians;
                }
            } else if (block > 1) {
                objective.hessian_block_diagonal(blocks);
                if (!symmetric) symmetrize_blocks(blocks, block);  // M must stay symmetric positive definite
                preconditioner.set_block_jacobi(blocks, block);
            } else {
                preconditioner.set_jacobi(diagonal);
            }
            const double forcing = std::min(options.cg_tolerance, std::sqrt(g.norm() / g0));
            // GMRES judges its residual in Newton's own norm, g . diag(H)^-1 g (residual_of).
            if (!symmetric && use_gmres)
                gmres_weight = diagonal.unaryExpr([](double h) { return h > 0.0 ? 1.0 / h : 1.0; });
            const PcgResult cg =
                symmetric ? solve_pcg(objective, -g, preconditioner, d, forcing, options.max_cg_iterations, pcg)
                : use_gmres
                    ? solve_gmres(objective, -g, preconditioner, d, forcing, options.max_cg_iterations, gmres,
                                  kGmresRestart, &gmres_weight)
                    : solve_bicgstab(objective, -g, preconditioner, d, forcing, options.max_cg_iterations, bicgstab);
            stats.cg_iterations += cg.iterations;
            if (!symmetric && !(g.dot(d) < 0.0)) {
                // The exact solution descends (Objective::hessian_symmetric); an inexact one may not:
                // the preconditioned gradient step instead (M is symmetric positive definite).
                preconditioner.apply(-g, d);
                ++stats.nonsymmetric_fallbacks;
            }
        }
        const double slope = g.dot(d);
        if (!(slope < 0.0))
            throw NewtonError(where(context, it, residual) + "the search direction is not a descent direction (g.d = " +
                              std::to_string(slope) + "); the Hessian is not positive definite");

        // A step filter (contact: CCD) may shorten the step; the line search then
        // starts from the largest allowed fraction.
        const double alpha_max = std::min(1.0, objective.max_step(x, d));
        if (!(alpha_max > 0.0))
            throw NewtonError(where(context, it, residual) +
                              "the step filter allows no motion along the Newton "
                              "direction (max_step = " +
                              std::to_string(alpha_max) + ")");
        if (alpha_max < 1.0) d *= alpha_max;
        const double slope_full = g.dot(d);  // the slope of the (possibly shortened) step
        if (work_search) {
            // Trial points about their own reference: g_trial = R(x + alpha d), and the change of
            // the step's potential is the work of R along the segment, by the trapezoid rule
            // (exact for a quadratic): Armijo on it, halving alpha. A trial costs a gradient pass;
            // the accepted iterate's Hessian is prepared at the next iteration's start, if the
            // iterate is not converged and the last step did not contract enough to keep it (lazy).
            double alpha = 1.0, trial = energy, work = 0.0;
            bool accepted = false;
            for (int halvings = 0; halvings <= options.max_line_search && !accepted; ++halvings) {
                if (halvings > 0) alpha *= 0.5;
                x_trial = x + alpha * d;
                if (objective.rebase(x_trial)) ++stats.rebases;
                trial = objective.value_gradient(x_trial, g_trial);
                ++stats.line_search_steps;
                if (!std::isfinite(trial) || !g_trial.allFinite()) continue;
                work = 0.5 * alpha * (slope_full + g_trial.dot(d));
                accepted = work <= options.armijo * alpha * slope_full;
            }
            if (!accepted) {
                // Back to the last iterate's own reference, unconverged.
                if (objective.rebase(x)) ++stats.rebases;
                energy = objective.value_gradient(x, g);
                stats.line_search_failed = true;
                if (options.throw_on_line_search_failure)
                    throw NewtonError(where(context, it, residual) + "line search failed after " +
                                      std::to_string(options.max_line_search) + " halvings (the work of the true "
                                      "residual along the Newton direction did not decrease)");
                break;
            }
            work_energy += work;
            x.swap(x_trial);
            g.swap(g_trial);
            energy = trial;
            const double residual_before = residual;
            residual = residual_of(g, options, diagonal);
            hessian_owed = !(lazy && alpha == 1.0 && residual <= options.lazy_hessian * residual_before);
            stats.iterations = it + 1;
            stats.energy = work_energy;
            stats.residual = residual;
            continue;
        }
        // The full step first, with its gradient; with its Hessian too unless the
        // last iteration contracted (then this one likely does, and keeps the Hessian).
        // Rebased: the trial's value alone (Armijo); its gradient and Hessian about this reference
        // would be replaced at the next one, where the accepted iterate gets its own.
        x_trial = x + d;
        const bool trial_hessian = !options.rebase && !(lazy && contracted);
        bool trial_gradient = !options.rebase;
        const double e_full = options.rebase  ? objective.value(x_trial)
                              : trial_hessian ? objective.value_gradient_hessian(x_trial, g_trial)
                                              : objective.value_gradient(x_trial, g_trial);
        stats.hessians += trial_hessian;
        ++stats.line_search_steps;
        const bool full_finite = std::isfinite(e_full) && (!trial_gradient || g_trial.allFinite());
        // Near the solution the decrease g.d falls below the round-off of E: the
        // energy cannot rank the step any more, the gradient still can.
        const bool roundoff = -slope_full <= 16.0 * std::numeric_limits<double>::epsilon() * std::abs(energy);
        // Whether the full step lowers |g| (about this reference), its gradient evaluated when first asked.
        auto gradient_lowered = [&] {
            if (!trial_gradient && std::isfinite(e_full)) {
                objective.value_gradient(x_trial, g_trial);
                trial_gradient = true;
            }
            return trial_gradient && std::isfinite(e_full) && g_trial.allFinite() && g_trial.norm() < g.norm();
        };
        const bool lowers_gradient =
            (roundoff || !(full_finite && e_full <= energy + options.armijo * slope_full)) && gradient_lowered();
        if (roundoff && !lowers_gradient) {
            stats.roundoff_floor = true;  // nothing left to gain in double precision
            break;
        }
        const double residual_before = residual;
        bool full_step = alpha_max >= 1.0;
        bool backtracked = false;  // the line search shortened the step (not CCD)
        bool hessian_at_x = trial_hessian;  // whether the Hessian prepared last is at the new iterate
        if (roundoff || (full_finite && e_full <= energy + options.armijo * slope_full)) {
            x.swap(x_trial);
            g.swap(g_trial);
            energy = e_full;
        } else {
            double alpha = 0.5, trial = e_full;
            bool decreased = false, any_finite = std::isfinite(e_full);
            for (int halvings = 1; halvings <= options.max_line_search; ++halvings) {
                x_trial = x + alpha * d;
                trial = objective.value(x_trial);
                any_finite = any_finite || std::isfinite(trial);
                ++stats.line_search_steps;
                if (std::isfinite(trial) && trial <= energy + options.armijo * alpha * slope_full) {
                    decreased = true;
                    break;
                }
                alpha *= 0.5;
            }
            if (decreased && options.rebase) {
                // Rebased: the iterate gets its gradient and Hessian about its own reference below.
                backtracked = true;
                x.swap(x_trial);
                energy = trial;
                full_step = false;
            } else if (decreased) {
                backtracked = true;
                // A backtracked iterate always gets its own Hessian.
                x.swap(x_trial);
                energy = objective.value_gradient_hessian(x, g);
                ++stats.hessians;
                hessian_at_x = true;
                full_step = false;
                if (!std::isfinite(energy) || !g.allFinite())
                    throw NewtonError(where(context, it, residual) + "the gradient is not finite after the step");
            } else if (lowers_gradient &&
                       std::abs(e_full - energy) <= 1e-10 * std::max(std::abs(energy), std::abs(e_full))) {
                // The energy cannot rank the step (a change at its round-off):
                // the gradient decides.
                x.noalias() = x + d;
                g.swap(g_trial);
                energy = e_full;
            } else if (!any_finite) {
                throw NewtonError(where(context, it, residual) +
                                  "the energy is not finite anywhere along the Newton "
                                  "direction (down to a step of 2^-" +
                                  std::to_string(options.max_line_search) + ")");
            } else {
                stats.line_search_failed = true;
                if (options.throw_on_line_search_failure)
                    throw NewtonError(where(context, it, residual) + "line search failed after " +
                                      std::to_string(options.max_line_search) + " halvings (E = " +
                                      std::to_string(energy) + ", last trial " + std::to_string(trial) + ")");
                break;  // x and g are those of the last accepted iterate
            }
        }
        if (options.rebase) {
            // The exact gradient at the new reference; the Hessian prepared last (at the previous
            // iterate) stays unless the lazy rule below asks for a fresh one, at this reference.
            if (objective.rebase(x)) ++stats.rebases;
            energy = objective.value_gradient(x, g);
            if (!std::isfinite(energy) || !g.allFinite())
                throw NewtonError(where(context, it, residual) + "the energy or its gradient is not finite after "
                                  "moving the reference to the iterate");
        }
        objective.hessian_diagonal(diagonal);  // of the Hessian prepared last
        residual = residual_of(g, options, diagonal);
        if (damped) {
            // The merit is re-defined at every rebase, so nothing stops Newton from cycling where
            // the consistent tangent jumps (an element crossing the yield surface and back), and
            // along a mode of near-zero true stiffness (perfectly plastic flow) the full step can
            // leave the region where the network matches the stress, so that the line search
            // backtracks. When the true residual grew or the step was backtracked, damp the next
            // steps with a proximal weight about the new reference (a trust region: value,
            // gradient and Hessian alike; zero at F = F0, so R is unchanged), fourfold while it
            // goes on; relax it fourfold after a step that lowered R.
            if (residual > residual_before || backtracked) {
                damping = damping > 0.0 ? std::min(4.0 * damping, kMaxDamping) : kFirstDamping;
                objective.set_damping(damping);
                energy = objective.value_gradient_hessian(x, g);
                ++stats.hessians;
                ++stats.dampings;
                hessian_at_x = true;
                full_step = false;  // the fresh Hessian is kept below
                objective.hessian_diagonal(diagonal);
                residual = residual_of(g, options, diagonal);
            } else if (damping > 0.0) {
                damping = damping * 0.25 < kFirstDamping ? 0.0 : 0.25 * damping;
                objective.set_damping(damping);  // from the next Hessian on
            }
        }
        contracted = full_step && residual <= options.lazy_hessian * residual_before;
        if (!hessian_at_x && !contracted && options.rebase) {
            hessian_owed = true;  // prepared at the next iteration's start, if it has one
        } else if (!hessian_at_x && !contracted) {
            // The lazy Hessian may be kept only after a contracting full step.
            objective.prepare_hessian(x);
            ++stats.hessians;
            objective.hessian_diagonal(diagonal);
            residual = residual_of(g, options, diagonal);
        }
        stats.iterations = it + 1;
        stats.energy = energy;
        stats.residual = residual;
    }
    if (residual <= target) stats.converged = true;
    if (damped) objective.set_damping(0.0);
    return stats;
}

}  // namespace pnet
