#pragma once
// One check for every form (cpp/pnet/solver/form.hpp): the views a problem takes of a form's
// Hessian agree, and its value and gradient are the same from each pass.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include <Eigen/SparseCore>

#include "pnet/solver/form.hpp"

namespace pnet::test {

/// At x (n unknowns, nodes of `block` components): value() is what add_gradient() and
/// add_gradient_hessian() return, and the two give the same gradient; the matrix-free product
/// (random d), the diagonal, the node blocks and the slot refill (add_hessian_values) agree with
/// the matrix the triplets assemble. Returns the number of Hessian entries (triplets).
inline std::size_t expect_consistent_form(Form& form, const Eigen::VectorXd& x, int block, const std::string& name,
                                          unsigned seed = 1) {
    SCOPED_TRACE(name);
    using VecX = Eigen::VectorXd;
    const Eigen::Index n = x.size();
    VecX g1 = VecX::Zero(n), g2 = VecX::Zero(n);
    const double e0 = form.value(x);
    const double e1 = form.add_gradient(x, g1);
    const double e2 = form.add_gradient_hessian(x, g2);
    const double e_scale = std::max({std::abs(e0), std::abs(e1), 1e-300});
    EXPECT_LE(std::abs(e0 - e1), 1e-12 * e_scale) << "value and add_gradient";
    EXPECT_LE(std::abs(e1 - e2), 1e-12 * e_scale) << "add_gradient and add_gradient_hessian";
    EXPECT_LE((g1 - g2).cwiseAbs().maxCoeff(), 1e-12 * std::max(g1.cwiseAbs().maxCoeff(), 1e-300));

    std::vector<Triplet> triplets;
    form.add_hessian_triplets(triplets);
    Eigen::SparseMatrix<double> H(n, n);
    H.setFromTriplets(triplets.begin(), triplets.end());
    const double h_scale = std::max(Eigen::MatrixXd(H).cwiseAbs().maxCoeff(), 1e-300);

    std::mt19937 engine(seed);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    VecX d(n);
    for (Eigen::Index i = 0; i < n; ++i) d[i] = uniform(engine);
    VecX Hd = VecX::Zero(n);
    form.add_hessian_multiply(d, Hd);
    EXPECT_LE((Hd - H * d).cwiseAbs().maxCoeff(), 1e-11 * h_scale * std::max(1.0, d.cwiseAbs().sum() / 10.0))
        << "the matrix-free product";

    VecX diagonal = VecX::Zero(n);
    form.add_hessian_diagonal(diagonal);
    EXPECT_LE((diagonal - VecX(H.diagonal())).cwiseAbs().maxCoeff(), 1e-12 * h_scale) << "the diagonal";

    VecX blocks = VecX::Zero(n * block);
    form.add_hessian_block_diagonal(blocks);
    double worst = 0.0;
    for (Eigen::Index k = 0; k < n / block; ++k)
        for (int a = 0; a < block; ++a)
            for (int b = 0; b < block; ++b)
                worst = std::max(worst, std::abs(blocks[k * block * block + a * block + b] -
                                                 H.coeff(block * k + a, block * k + b)));
    EXPECT_LE(worst, 1e-12 * h_scale) << "the node blocks";

    // The refill through slots: the triplets' positions in H's compressed pattern.
    H.makeCompressed();
    std::vector<int> slots(triplets.size());
    for (std::size_t k = 0; k < triplets.size(); ++k) {
        const auto* inner = H.innerIndexPtr();
        const auto* first = inner + H.outerIndexPtr()[triplets[k].col()];
        const auto* last = inner + H.outerIndexPtr()[triplets[k].col() + 1];
        slots[k] = static_cast<int>(std::lower_bound(first, last, triplets[k].row()) - inner);
    }
    std::vector<double> values(H.nonZeros(), 0.0);
    form.add_hessian_values(values.data(), slots.data());
    worst = 0.0;
    for (Eigen::Index k = 0; k < H.nonZeros(); ++k) worst = std::max(worst, std::abs(values[k] - H.valuePtr()[k]));
    EXPECT_LE(worst, 1e-12 * h_scale) << "the slot refill";
    return triplets.size();
}

}  // namespace pnet::test
