#pragma once
// The shape of an MPM deposit (docs/metrics.md): measures that a film one
// particle thick barely moves, unlike the outermost particle (whose position
// swings by a fifth between two valid explicit runs where these move by a few
// percent).
#include <vector>

namespace pnet {

struct DepositShape {
    /// Mass-weighted rms horizontal distance from the centre of mass, m:
    /// sqrt(sum m |x_h - x_c|^2 / sum m), x_h the horizontal coordinates (x in
    /// 2D; x and z in 3D, y being up).
    double spread = 0.0;
    /// The 90th mass percentile of the height y, m.
    double height = 0.0;
};

/// position: n dim coordinates (particle-major), mass: n values >= 0 with a
/// positive sum. Throws std::invalid_argument on inconsistent sizes, dim not 2
/// or 3, or no mass.
DepositShape deposit_shape(int dim, const std::vector<double>& position, const std::vector<double>& mass);

}  // namespace pnet
