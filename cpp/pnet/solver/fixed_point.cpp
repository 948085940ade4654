#include "pnet/solver/fixed_point.hpp"

#include <Eigen/QR>
#include <algorithm>
#include <cstring>
#include <limits>

namespace pnet {

namespace {

/// F0 <- the Anderson combination, from F0 (the last reference) and F = G(F0) (its image).
template <int dim>
void anderson_update(ReferenceSolveWork<dim>& work, int depth, int iteration) {
    constexpr int kEntries = dim * dim;
    const Eigen::Index n = static_cast<Eigen::Index>(work.F.size()) * kEntries;
    const Eigen::Map<const VecX> g(work.F.data()->data(), n);
    const Eigen::Map<const VecX> f0(work.F0.data()->data(), n);
    const VecX r = g - f0;
    if (iteration == 0) {
        work.dR.resize(n, 0);
        work.dG.resize(n, 0);
    } else {
        // Append the newest differences, dropping the oldest beyond the depth.
        const Eigen::Index kept = std::min<Eigen::Index>(work.dR.cols(), depth - 1);
        Eigen::MatrixXd dR(n, kept + 1), dG(n, kept + 1);
        dR.leftCols(kept) = work.dR.rightCols(kept);
        dG.leftCols(kept) = work.dG.rightCols(kept);
        dR.col(kept) = r - work.last_r;
        dG.col(kept) = g - work.last_g;
        work.dR.swap(dR);
        work.dG.swap(dG);
    }
    work.last_r = r;
    work.last_g = g;
    VecX next = g;
    if (work.dR.cols() > 0) {
        const VecX gamma = work.dR.colPivHouseholderQr().solve(r);
        if (gamma.allFinite()) next -= work.dG * gamma;
    }
    Eigen::Map<VecX>(work.F0.data()->data(), n) = next;
}

/// The referenced objective seen by Newton with the reference following the iterate
/// (NewtonOptions::rebase): every call is forwarded; rebase(v) sets F0 = F(v) and records how far
/// F0 moved.
template <int dim>
class FollowingReference final : public Objective {
public:
    FollowingReference(ReferencedObjective<dim>& objective, ReferenceSolveWork<dim>& work,
                       const std::function<void()>& after_reference)
        : objective_(objective), work_(work), after_reference_(after_reference) {}

    Eigen::Index size() const override { return objective_.size(); }
    double value(const VecX& x) override { return objective_.value(x); }
    double value_gradient(const VecX& x, VecX& g) override { return objective_.value_gradient(x, g); }
    void prepare_hessian(const VecX& x) override { objective_.prepare_hessian(x); }
    double value_gradient_hessian(const VecX& x, VecX& g) override { return objective_.value_gradient_hessian(x, g); }
    void hessian_multiply(const VecX& d, VecX& out) const override { objective_.hessian_multiply(d, out); }
    void hessian_diagonal(VecX& diagonal) const override { objective_.hessian_diagonal(diagonal); }
    int hessian_block_size() const override { return objective_.hessian_block_size(); }
    void hessian_block_diagonal(VecX& blocks) const override { objective_.hessian_block_diagonal(blocks); }
    bool has_preconditioner() const override { return objective_.has_preconditioner(); }
    void apply_preconditioner(const VecX& r, VecX& z) const override { objective_.apply_preconditioner(r, z); }
    const SparseMatrix* hessian_matrix() const override { return objective_.hessian_matrix(); }
    bool hessian_symmetric() const override { return objective_.hessian_symmetric(); }
    double max_step(const VecX& x, const VecX& d) override { return objective_.max_step(x, d); }
    bool set_damping(double lambda) override { return objective_.set_damping(lambda); }

    bool rebase(const VecX& x) override {
        objective_.deformation(x, work_.F);
        if (updates_ > 0) {
            double change = 0.0;
            for (std::size_t p = 0; p < work_.F.size(); ++p)
                change = std::max(change, (work_.F[p] - work_.F0[p]).norm());
            last_change_ = change;
        }
        work_.F0.swap(work_.F);
        objective_.set_reference(work_.F0);
        if (after_reference_) after_reference_();
        ++updates_;
        return true;
    }
    int updates() const { return updates_; }
    /// max_p ||F(v) - F0|| of the last move (0 before the second).
    double last_change() const { return last_change_; }

private:
    ReferencedObjective<dim>& objective_;
    ReferenceSolveWork<dim>& work_;
    const std::function<void()>& after_reference_;
    int updates_ = 0;
    double last_change_ = 0.0;
};

std::string unconverged_message(const std::string& where, const NewtonStats& s, double tolerance) {
    return where + ": the Newton solve did not converge (" +
           (s.line_search_failed ? std::string("line search failed") : std::to_string(s.iterations) + " iterations") +
           ", residual " + std::to_string(s.residual) + " m/s > tolerance " + std::to_string(tolerance) + " m/s)";
}

/// plasticitynet with OuterIteration::Newton: one solve, the reference at every iterate.
template <int dim>
ReferenceSolveStats solve_following_reference(ReferencedObjective<dim>& objective, VecX& v,
                                              const NewtonOptions& newton, const ReferenceSolveOptions& options,
                                              const std::string& context, ReferenceSolveWork<dim>& work,
                                              const std::function<void()>& after_reference) {
    FollowingReference<dim> following(objective, work, after_reference);
    NewtonOptions solve_newton = newton;
    solve_newton.rebase = true;
    solve_newton.work_line_search = options.work_line_search;
    const NewtonStats s = minimize(following, v, solve_newton, context, &work.newton);
    ReferenceSolveStats stats;
    stats.solves = 1;
    stats.newton_iterations = s.iterations;
    stats.cg_iterations = s.cg_iterations;
    stats.line_search_steps = s.line_search_steps;
    stats.initial_residual = s.initial_residual;
    stats.residual = stats.true_residual = s.residual;  // at the last reference, F0 = F(v): R(v) itself
    stats.energy = s.energy;
    stats.reference_updates = following.updates();
    stats.change = following.last_change();
    const bool converged = s.converged || s.roundoff_floor;
    stats.converged = stats.fixed_point_converged = converged;
    stats.line_search_failed = s.line_search_failed;
    if (options.fail_on_unconverged && !converged)
        throw NewtonError(unconverged_message(context, s, newton.tolerance));
    return stats;
}

}  // namespace

template <int dim>
ReferenceSolveStats solve_with_reference(ReferencedObjective<dim>& objective, VecX& v, const NewtonOptions& newton,
                                         const ReferenceSolveOptions& options, const std::string& context,
                                         ReferenceSolveWork<dim>& work, const std::function<void()>& after_reference) {
    if (follows_iterate(options))
        return solve_following_reference(objective, v, newton, options, context, work, after_reference);
    ReferenceSolveStats stats;
    const bool fixed_point = options.fixed_point;
    const int solves = fixed_point ? options.max_solves : 1;
    if (fixed_point) objective.deformation(v, work.F0);  // F0^0 = F(v)
    double best_change = std::numeric_limits<double>::infinity(), previous_change = best_change;
    double last_change = best_change;  // the change of F0 that the next solve starts from
    bool have_best = false;
    for (int j = 0; j < solves; ++j) {
        if (fixed_point) objective.set_reference(work.F0);
        if (after_reference) after_reference();
        const std::string where = context + (fixed_point ? ", fixed-point iteration " + std::to_string(j + 1) : "");
        NewtonOptions solve_newton = newton;
        solve_newton.keep_prepared_hessian = newton.keep_prepared_hessian || (options.keep_hessian && j > 0);
        if (j > 0 && last_change > options.tolerance) solve_newton.relative_tolerance = options.inexact_forcing;
        const NewtonStats s = minimize(objective, v, solve_newton, where, &work.newton);
        if (j == 0) stats.initial_residual = s.initial_residual;
        stats.newton_iterations += s.iterations;
        stats.cg_iterations += s.cg_iterations;
        stats.line_search_steps += s.line_search_steps;
        stats.residual = s.residual;
        stats.energy = s.energy;
        const bool converged = s.converged || s.roundoff_floor;
        stats.converged = stats.converged && converged;
        stats.line_search_failed = stats.line_search_failed || s.line_search_failed;
        if (options.fail_on_unconverged && !converged)
            throw NewtonError(unconverged_message(where, s, newton.tolerance));
        ++stats.solves;
        if (!fixed_point) break;
        objective.deformation(v, work.F);
        double change = 0.0;
        for (std::size_t p = 0; p < work.F.size(); ++p) change = std::max(change, (work.F[p] - work.F0[p]).norm());
        // Keep the most self-consistent solution among those solved to the Newton tolerance (an inexact
        // solve's v is only a start for the next).
        const bool exact = s.residual <= newton.tolerance || solve_newton.relative_tolerance <= 0.0;
        if (exact && change < best_change) {
            best_change = change;
            work.best_v = v;
            have_best = true;
        }
        stats.change = have_best ? best_change : change;
        last_change = change;
        // Done when F0 is consistent and this solve met the Newton tolerance itself (not an inexact one).
        if (change <= options.tolerance && (exact || !converged)) break;
        if (options.anderson_depth <= 0) {
            if (change > previous_change) break;
            previous_change = change;
            work.F0.swap(work.F);  // F0^{j+1} = F(v^{j+1})
        } else {
            // Accelerated: not monotone, so stop only when far above the best (diverging).
            if (change > 10.0 * best_change) break;
            anderson_update(work, options.anderson_depth, j);
        }
    }
    if (fixed_point) {
        if (have_best) v.swap(work.best_v);  // else: every solve was inexact (the cap); the last one stands
        stats.fixed_point_converged = have_best && best_change <= options.tolerance;
        stats.reference_updates = stats.solves;
        // The true residual at the returned v: the gradient about F0 = F(v) (a diagnostic; the
        // reference is moved there, which the caller's next use does not depend on).
        objective.deformation(v, work.F0);
        objective.set_reference(work.F0);
        if (after_reference) after_reference();
        VecX g(objective.size());
        objective.value_gradient(v, g);
        stats.true_residual = newton_residual(objective, g, newton);
    }
    return stats;
}

template ReferenceSolveStats solve_with_reference<2>(ReferencedObjective<2>&, VecX&, const NewtonOptions&,
                                                     const ReferenceSolveOptions&, const std::string&,
                                                     ReferenceSolveWork<2>&, const std::function<void()>&);
template ReferenceSolveStats solve_with_reference<3>(ReferencedObjective<3>&, VecX&, const NewtonOptions&,
                                                     const ReferenceSolveOptions&, const std::string&,
                                                     ReferenceSolveWork<3>&, const std::function<void()>&);

}  // namespace pnet
