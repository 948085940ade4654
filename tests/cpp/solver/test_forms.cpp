// The form layer (docs/architecture.md, "Forms"): a Problem sums its forms' values, gradients
// (masked on fixed components) and Hessians, matrix-free and assembled alike; the assembled
// pattern is refilled through slots and rebuilt when invalidated; forms whose pattern changes
// are added apart; a problem inside another (ProblemForm) is the same problem on its slice. Then
// every form of the MPM, FEM-in-coupling and particle-mesh problems passes the one consistency
// check (support/form_checks.hpp) in 2D and 3D, with friction.
#include <gtest/gtest.h>

#include "pnet/solver/problem.hpp"
#include "support/coupled_runs.hpp"
#include "support/form_checks.hpp"

namespace pnet {
namespace {

/// E(x) = 1/2 (x - c)^T A (x - c), A given by its (symmetric) triplets.
class QuadraticForm final : public Form {
public:
    QuadraticForm(std::vector<Triplet> entries, VecX c, bool changing)
        : entries_(std::move(entries)), c_(std::move(c)), changing_(changing) {}
    void set_entries(std::vector<Triplet> entries) { entries_ = std::move(entries); }

    double value(const VecX& x) override { return 0.5 * (x - c_).dot(matrix() * (x - c_)); }
    double add_gradient(const VecX& x, VecX& g) override {
        g += matrix() * (x - c_);
        return value(x);
    }
    void prepare_hessian(const VecX&) override {}
    void add_hessian_multiply(const VecX& d, VecX& out) const override { out += matrix() * d; }
    void add_hessian_diagonal(VecX& diagonal) const override { diagonal += matrix().diagonal(); }
    void add_hessian_block_diagonal(VecX& blocks) const override {
        const SparseMatrix A = matrix();
        for (Eigen::Index k = 0; k < A.rows() / 2; ++k)
            for (int a = 0; a < 2; ++a)
                for (int b = 0; b < 2; ++b) blocks[4 * k + 2 * a + b] += A.coeff(2 * k + a, 2 * k + b);
    }
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override {
        triplets.insert(triplets.end(), entries_.begin(), entries_.end());
    }
    bool changing_pattern() const override { return changing_; }

private:
    SparseMatrix matrix() const {
        SparseMatrix A(c_.size(), c_.size());
        A.setFromTriplets(entries_.begin(), entries_.end());
        return A;
    }
    std::vector<Triplet> entries_;
    VecX c_;
    bool changing_;
};

class TestProblem final : public Problem<2> {
public:
    TestProblem(std::vector<Form*> forms, VecX free) {
        this->free_ = std::move(free);
        this->set_forms(std::move(forms));
    }
    void changed_pattern() { this->invalidate_pattern(); }
    void deformation(const VecX&, std::vector<Mat<2>>&) const override {}
    void set_reference(const std::vector<Mat<2>>&) override {}
};

/// A symmetric positive pattern on n unknowns: a diagonal and the pairs (i, i + step).
std::vector<Triplet> banded(int n, int step, double scale) {
    std::vector<Triplet> t;
    for (int i = 0; i < n; ++i) t.emplace_back(i, i, scale * (4.0 + i));
    for (int i = 0; i + step < n; ++i) {
        t.emplace_back(i, i + step, -scale);
        t.emplace_back(i + step, i, -scale);
    }
    return t;
}

SparseMatrix dense_sum(int n, const std::vector<std::vector<Triplet>>& parts) {
    std::vector<Triplet> all;
    for (const auto& p : parts) all.insert(all.end(), p.begin(), p.end());
    SparseMatrix A(n, n);
    A.setFromTriplets(all.begin(), all.end());
    return A;
}

TEST(Problem, SumsItsFormsMaskedAndAssembledAlike) {
    const int n = 8;
    const VecX c = VecX::LinSpaced(n, -1.0, 1.0);
    QuadraticForm fixed_a(banded(n, 2, 1.0), c, false), fixed_b(banded(n, 3, 0.5), -c, false);
    QuadraticForm contact(banded(n, 1, 2.0), 0.5 * c, true);
    VecX free = VecX::Ones(n);
    free[3] = 0.0;
    TestProblem problem({&fixed_a, &fixed_b, &contact}, free);
    const VecX x = VecX::LinSpaced(n, 0.3, -0.7), d = VecX::LinSpaced(n, 1.0, 2.0);

    VecX g;
    const double e = problem.value_gradient(x, g);
    EXPECT_DOUBLE_EQ(e, fixed_a.value(x) + fixed_b.value(x) + contact.value(x));
    EXPECT_DOUBLE_EQ(problem.value(x), e);
    VecX expected = VecX::Zero(n);
    fixed_a.add_gradient(x, expected);
    fixed_b.add_gradient(x, expected);
    contact.add_gradient(x, expected);
    expected[3] = 0.0;
    EXPECT_LT((g - expected).cwiseAbs().maxCoeff(), 1e-14);

    const SparseMatrix A = dense_sum(n, {banded(n, 2, 1.0), banded(n, 3, 0.5), banded(n, 1, 2.0)});
    problem.prepare_hessian(x);
    ASSERT_EQ(problem.hessian_matrix(), nullptr) << "matrix-free unless asked";
    VecX Hd, diagonal, blocks;
    problem.hessian_multiply(d, Hd);
    EXPECT_LT((Hd - A * d).cwiseAbs().maxCoeff(), 1e-13);
    problem.hessian_diagonal(diagonal);
    EXPECT_LT((diagonal - VecX(A.diagonal())).cwiseAbs().maxCoeff(), 1e-14);
    problem.hessian_block_diagonal(blocks);
    EXPECT_DOUBLE_EQ(blocks[4 * 1 + 1], A.coeff(2, 3));

    problem.set_assemble(true);
    problem.prepare_hessian(x);
    ASSERT_NE(problem.hessian_matrix(), nullptr);
    EXPECT_LT((Eigen::MatrixXd(*problem.hessian_matrix()) - Eigen::MatrixXd(A)).cwiseAbs().maxCoeff(), 1e-14);
    VecX Hd_assembled;
    problem.hessian_multiply(d, Hd_assembled);
    EXPECT_LT((Hd_assembled - Hd).cwiseAbs().maxCoeff(), 1e-13);

    // A changing-pattern form's new pairs are picked up at the next pass without invalidation;
    // a fixed-pattern form's new pattern after invalidate_pattern().
    contact.set_entries(banded(n, 4, 2.0));
    fixed_a.set_entries(banded(n, 5, 1.0));
    problem.changed_pattern();
    problem.prepare_hessian(x);
    const SparseMatrix B = dense_sum(n, {banded(n, 5, 1.0), banded(n, 3, 0.5), banded(n, 4, 2.0)});
    EXPECT_LT((Eigen::MatrixXd(*problem.hessian_matrix()) - Eigen::MatrixXd(B)).cwiseAbs().maxCoeff(), 1e-14);
    // Values change, pattern kept: refilled in place.
    fixed_b.set_entries(banded(n, 3, 0.25));
    problem.prepare_hessian(x);
    const SparseMatrix C = dense_sum(n, {banded(n, 5, 1.0), banded(n, 3, 0.25), banded(n, 4, 2.0)});
    EXPECT_LT((Eigen::MatrixXd(*problem.hessian_matrix()) - Eigen::MatrixXd(C)).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(ProblemForm, IsTheProblemOnItsSliceOfALargerOne) {
    const int n = 6, offset = 4;
    const VecX c = VecX::LinSpaced(n, -1.0, 1.0);
    QuadraticForm inner_form(banded(n, 1, 1.0), c, false);
    VecX inner_free = VecX::Ones(n);
    inner_free[0] = 0.0;
    TestProblem inner({&inner_form}, inner_free);
    ProblemForm<2> slice(inner);
    slice.set_offset(offset);
    const int N = n + offset;
    QuadraticForm outer_form(banded(N, 2, 0.5), VecX::Zero(N), true);
    VecX outer_free = VecX::Ones(N);
    outer_free.segment(offset, n) = inner_free;
    TestProblem outer({&slice, &outer_form}, outer_free);
    const VecX x = VecX::LinSpaced(N, 0.2, 1.1), d = VecX::LinSpaced(N, -1.0, 1.0);

    VecX g, g_inner;
    const double e = outer.value_gradient(x, g);
    const double e_inner = inner.value_gradient(x.segment(offset, n), g_inner);
    EXPECT_DOUBLE_EQ(e, e_inner + outer_form.value(x));
    VecX expected = VecX::Zero(N);
    outer_form.add_gradient(x, expected);
    expected.segment(offset, n) += g_inner;
    expected.array() *= outer_free.array();
    EXPECT_LT((g - expected).cwiseAbs().maxCoeff(), 1e-14);
    EXPECT_EQ(g[offset], 0.0) << "the inner problem's fixed component";

    outer.prepare_hessian(x);
    std::vector<Triplet> shifted;
    for (const Triplet& t : banded(n, 1, 1.0)) shifted.emplace_back(t.row() + offset, t.col() + offset, t.value());
    const SparseMatrix A = dense_sum(N, {shifted, banded(N, 2, 0.5)});
    VecX Hd;
    outer.hessian_multiply(d, Hd);
    EXPECT_LT((Hd - A * d).cwiseAbs().maxCoeff(), 1e-13);
    test::expect_consistent_form(slice, x, 2, "the slice");
    EXPECT_EQ(slice.max_step(x, d), 1.0);
}

/// The tiny coupled scene with its mesh's centre at height y (m), at rest, with friction mu.
template <int dim>
void check_coupled_forms(double y, double mu) {
    const char* file = dim == 2 ? PNET_SCENES_DIR "/tiny/sand_fem_coupling_2d.json"
                                : PNET_SCENES_DIR "/tiny/sand_fem_coupling_3d.json";
    nlohmann::json j = scene_to_json(load_scene(file));
    j["meshes"][0]["center"][1] = y;
    j["meshes"][0]["velocity"] = std::vector<double>(dim, 0.0);
    j["contact"]["friction"] = mu;
    test::CoupledFixture<dim> f(scene_from_json(j, "coupled.json", ""), mu, 0.2);
    ASSERT_GT(f.coupled.friction_pairs(), 0u) << "the mesh should be within dhat of the bed";
    const VecX v = f.coupled.v_star();
    // The forms of each problem at its own unknowns, and the coupled problem's at all of them.
    std::size_t entries = 0;
    const VecX vg = v.head(f.coupled.grid_size()), vf = v.tail(f.fem_potential.size());
    for (Form* form : f.mpm_potential.forms()) entries += test::expect_consistent_form(*form, vg, dim, "MPM form");
    for (Form* form : f.fem_potential.forms()) entries += test::expect_consistent_form(*form, vf, dim, "FEM form");
    for (Form* form : f.coupled.forms()) entries += test::expect_consistent_form(*form, v, dim, "coupled form");
    EXPECT_GT(entries, 0u);
}

// The heights of the friction tests (test_coupling_3d_friction.cpp): the mesh just within dhat.
TEST(Forms, EveryFormOfTheCoupledProblemIsConsistentIn2d) { check_coupled_forms<2>(0.09765625 + 0.05 + 0.003, 0.5); }
TEST(Forms, EveryFormOfTheCoupledProblemIsConsistentIn3d) { check_coupled_forms<3>(0.296875 + 0.1 + 0.015, 0.5); }

}  // namespace
}  // namespace pnet
