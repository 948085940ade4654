// The deposit shape of docs/metrics.md: spread about the centre of mass and the
// 90th mass percentile of the height, on particle sets with known answers.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "pnet/metrics/deposit_shape.hpp"

namespace pnet {
namespace {

TEST(DepositShape, SpreadAndHeightOfKnownSets) {
    // 2D: particles at x = 0.4 and 0.6 (centre 0.5, rms distance 0.1), heights 0.01 .. 0.10.
    std::vector<double> position, mass;
    for (int k = 1; k <= 10; ++k) {
        position.insert(position.end(), {k % 2 ? 0.4 : 0.6, 0.01 * k});
        mass.push_back(2.0);
    }
    DepositShape s = deposit_shape(2, position, mass);
    EXPECT_NEAR(s.spread, 0.1, 1e-15);
    EXPECT_DOUBLE_EQ(s.height, 0.09) << "90% of the mass lies at or below the 9th of 10 equal particles";
    // The centre is the centre of mass, not 0.5: shifting every x keeps the spread.
    for (std::size_t p = 0; p < mass.size(); ++p) position[2 * p] += 0.2;
    EXPECT_NEAR(deposit_shape(2, position, mass).spread, 0.1, 1e-15);
    // A film of light particles far out barely moves the spread; one heavy particle does.
    position.insert(position.end(), {0.95, 0.0});
    mass.push_back(0.01);
    EXPECT_LT(deposit_shape(2, position, mass).spread, 0.101);
    mass.back() = 20.0;
    EXPECT_GT(deposit_shape(2, position, mass).spread, 0.14);
}

TEST(DepositShape, ThreeDimensionsMeasureTheHorizontalPlane) {
    // Four particles on a circle of radius 0.2 in the x-z plane at different heights.
    const std::vector<double> position = {0.7, 0.1, 0.5, 0.3, 0.2, 0.5, 0.5, 0.3, 0.7, 0.5, 0.4, 0.3};
    const std::vector<double> mass(4, 1.0);
    const DepositShape s = deposit_shape(3, position, mass);
    EXPECT_NEAR(s.spread, 0.2, 1e-15) << "y (up) does not count";
    EXPECT_DOUBLE_EQ(s.height, 0.4);
}

TEST(DepositShape, RejectsBadInput) {
    EXPECT_THROW(deposit_shape(4, {0.0}, {1.0}), std::invalid_argument);
    EXPECT_THROW(deposit_shape(2, {0.0, 0.0, 1.0}, {1.0}), std::invalid_argument);
    EXPECT_THROW(deposit_shape(2, {0.0, 0.0}, {0.0}), std::invalid_argument);
}

}  // namespace
}  // namespace pnet
