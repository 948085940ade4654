// Dual1 (math/dual2.hpp): its elementary functions and mixed operations carry the exact derivative, and a
// formula over Eigen's fixed-size vectors of it (squaredNorm, prod, the reductions) gets the formula's gradient.
#include <gtest/gtest.h>

#include <cmath>

#include "pnet/math/dual2.hpp"

namespace pnet {
namespace {

using D = Dual1<2>;

TEST(Dual1, ElementaryFunctionsAndMixedOperationsCarryTheirDerivatives) {
    const double x = 0.7, y = 1.3;
    const D a = D::variable(0, x), b = D::variable(1, y);
    // f = sqrt(a) log(b) + sinh(a b) - pow(b, 1.5) / (2 - a) + 3 / b - (a - 1) / 4
    const D f = sqrt(a) * log(b) + sinh(a * b) - pow(b, 1.5) / (2.0 - a) + 3.0 / b - (a - 1.0) / 4.0;
    const double value = std::sqrt(x) * std::log(y) + std::sinh(x * y) - std::pow(y, 1.5) / (2.0 - x) + 3.0 / y -
                         (x - 1.0) / 4.0;
    const double df_dx = 0.5 / std::sqrt(x) * std::log(y) + std::cosh(x * y) * y - std::pow(y, 1.5) / std::pow(2.0 - x, 2) -
                         0.25;
    const double df_dy = std::sqrt(x) / y + std::cosh(x * y) * x - 1.5 * std::sqrt(y) / (2.0 - x) - 3.0 / (y * y);
    EXPECT_DOUBLE_EQ(f.value, value);
    EXPECT_NEAR(f.gradient[0], df_dx, 1e-14);
    EXPECT_NEAR(f.gradient[1], df_dy, 1e-14);
    D g = a;
    g += b;
    g *= a;
    g -= 1.0;
    g /= b;  // ((a + b) a - 1) / b
    EXPECT_NEAR(g.gradient[0], (2 * x + y) / y, 1e-14);
    EXPECT_NEAR(g.gradient[1], (x * y - (x + y) * x + 1.0) / (y * y), 1e-14);
    EXPECT_TRUE(a < b && a <= 0.7 && 1.3 >= b && !(a > b));
}

TEST(Dual1, EigenVectorsOfItGiveTheFormulasGradient) {
    Eigen::Matrix<D, 2, 1> v;
    v << D::variable(0, 3.0), D::variable(1, 4.0);
    const D norm = sqrt(v.squaredNorm()), product = v.prod();
    EXPECT_DOUBLE_EQ(norm.value, 5.0);
    EXPECT_NEAR(norm.gradient[0], 0.6, 1e-15);
    EXPECT_NEAR(norm.gradient[1], 0.8, 1e-15);
    EXPECT_DOUBLE_EQ(product.gradient[0], 4.0);
    EXPECT_DOUBLE_EQ(product.gradient[1], 3.0);
    const Eigen::Matrix<D, 2, 1> w = v / 2.0 + D(1.0) * Eigen::Matrix<D, 2, 1>::Ones();
    EXPECT_DOUBLE_EQ(w[1].value, 3.0);
    EXPECT_DOUBLE_EQ(w[1].gradient[1], 0.5);
}

}  // namespace
}  // namespace pnet
