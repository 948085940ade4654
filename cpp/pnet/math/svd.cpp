#include "pnet/math/svd.hpp"

// GCC 12 reports a false -Wmaybe-uninitialized inside Eigen's fixed-size
// JacobiSVD (instantiated below); silence it for this file only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <Eigen/SVD>
#include <cmath>

namespace pnet {

namespace {

Mat<2> rotation2(double angle) {
    const double c = std::cos(angle), s = std::sin(angle);
    Mat<2> R;
    R << c, -s, s, c;
    return R;
}

}  // namespace

// Closed-form 2x2 SVD: write F = [E + Fm, G - H; G + H, E - Fm] as a sum of a
// scaled rotation (E, H) and a scaled reflection (Fm, G). Then
// Sigma = (Q + R, Q - R) with Q = |(E, H)|, R = |(Fm, G)|, and the rotation
// angles follow from the two atan2's. Q - R < 0 exactly when det F < 0, so
// the polar convention comes out without any sign fix.
template <>
PolarSVD<2> polar_svd<2>(const Mat<2>& F) {
    const double E = 0.5 * (F(0, 0) + F(1, 1));
    const double Fm = 0.5 * (F(0, 0) - F(1, 1));
    const double G = 0.5 * (F(1, 0) + F(0, 1));
    const double H = 0.5 * (F(1, 0) - F(0, 1));
    const double Q = std::hypot(E, H);
    const double R = std::hypot(Fm, G);
    const double a1 = std::atan2(G, Fm);
    const double a2 = std::atan2(H, E);
    PolarSVD<2> out;
    out.Sigma << Q + R, Q - R;
    out.U = rotation2(0.5 * (a2 + a1));
    out.V = rotation2(0.5 * (a1 - a2));  // V^T = rot((a2 - a1)/2)
    return out;
}

template <>
PolarSVD<3> polar_svd<3>(const Mat<3>& F) {
    Eigen::JacobiSVD<Mat<3>> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
    PolarSVD<3> out;
    out.U = svd.matrixU();
    out.V = svd.matrixV();
    out.Sigma = svd.singularValues();
    // Turn the orthogonal factors into rotations; each reflection removed
    // flips the sign of the smallest singular value.
    if (out.U.determinant() < 0) {
        out.U.col(2) *= -1.0;
        out.Sigma[2] *= -1.0;
    }
    if (out.V.determinant() < 0) {
        out.V.col(2) *= -1.0;
        out.Sigma[2] *= -1.0;
    }
    return out;
}

}  // namespace pnet

#pragma GCC diagnostic pop
