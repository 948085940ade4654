#include "pnet/math/svd.hpp"

#include <cmath>
#include <utility>

#include <Eigen/Geometry>

namespace pnet {

namespace {

/// The square root of the unit complex number (c, s) with a non-negative real
/// part, i.e. (cos t/2, sin t/2) for (c, s) = (cos t, sin t), t in (-pi, pi];
/// whichever half-angle component is larger is taken from the square root, so
/// both are accurate.
inline void half_angle(double c, double s, double& hc, double& hs) {
    if (c >= 0.0) {
        hc = std::sqrt(0.5 * (1.0 + c));
        hs = s / (2.0 * hc);
    } else {
        hs = std::copysign(std::sqrt(0.5 * (1.0 - c)), s);
        hc = s / (2.0 * hs);
    }
}

}  // namespace

// Closed-form 2x2 SVD: write F = [E + Fm, G - H; G + H, E - Fm] as a sum of a
// scaled rotation (E, H) = Q (cos a2, sin a2) and a scaled reflection
// (Fm, G) = R (cos a1, sin a1). Then Sigma = (Q + R, Q - R),
// U = rot((a1 + a2) / 2) and V = rot((a1 - a2) / 2). The angles are never
// formed: with unit complex numbers z1 = e^{i a1} and z2 = e^{i a2},
// u = sqrt(z1 z2) and v = u conj(z2) (any square root: both factors flip sign
// together, which leaves U Sigma V^T unchanged), so the SVD costs three square roots
// instead of hypot's, atan2's and sincos's. Q - R < 0 exactly when
// det F < 0, so the polar convention comes out without any sign fix.
template <>
PolarSVD<2> polar_svd<2>(const Mat<2>& F) {
    const double E = 0.5 * (F(0, 0) + F(1, 1));
    const double Fm = 0.5 * (F(0, 0) - F(1, 1));
    const double G = 0.5 * (F(1, 0) + F(0, 1));
    const double H = 0.5 * (F(1, 0) - F(0, 1));
    const double Q = std::sqrt(E * E + H * H);
    const double R = std::sqrt(Fm * Fm + G * G);
    double c1 = 1.0, s1 = 0.0, c2 = 1.0, s2 = 0.0;
    if (R > 0.0) {
        const double inv = 1.0 / R;
        c1 = Fm * inv;
        s1 = G * inv;
    }
    if (Q > 0.0) {
        const double inv = 1.0 / Q;
        c2 = E * inv;
        s2 = H * inv;
    }
    // z1 z2 = (cos(a1 + a2), sin(a1 + a2)) (unit to round-off, which
    // half_angle tolerates).
    const double c = c1 * c2 - s1 * s2, s = s1 * c2 + c1 * s2;
    double uc, us;
    half_angle(c, s, uc, us);
    const double vc = uc * c2 + us * s2, vs = us * c2 - uc * s2;
    PolarSVD<2> out;
    out.Sigma << Q + R, Q - R;
    out.U << uc, -us, us, uc;
    out.V << vc, -vs, vs, vc;
    return out;
}

// The closed form needs no start.
template <>
PolarSVD<2> polar_svd<2>(const Mat<2>& F, const Mat<2>& /*V_start*/) {
    return polar_svd<2>(F);
}

namespace {

/// One Jacobi rotation in the (p, q) plane that zeroes A(p, q) of the
/// symmetric A (A <- J^T A J, V <- V J; Numerical Recipes' stable form).
inline void jacobi_rotate(Mat<3>& A, Mat<3>& V, int p, int q) {
    const double apq = A(p, q);
    if (apq == 0.0) return;
    const double theta = (A(q, q) - A(p, p)) / (2.0 * apq);
    const double t = std::copysign(1.0, theta) / (std::abs(theta) + std::sqrt(1.0 + theta * theta));
    const double c = 1.0 / std::sqrt(1.0 + t * t), s = t * c;
    const int r = 3 - p - q;
    const double arp = A(r, p), arq = A(r, q);
    A(p, p) -= t * apq;
    A(q, q) += t * apq;
    A(p, q) = A(q, p) = 0.0;
    A(r, p) = A(p, r) = c * arp - s * arq;
    A(r, q) = A(q, r) = s * arp + c * arq;
    for (int k = 0; k < 3; ++k) {
        const double vkp = V(k, p), vkq = V(k, q);
        V(k, p) = c * vkp - s * vkq;
        V(k, q) = s * vkp + c * vkq;
    }
}

/// Givens rotation on rows (p, q) of B that zeroes B(q, p) with B(p, p) >= 0
/// after it; U accumulates the transpose so that U B stays constant.
inline void givens_qr_step(Mat<3>& B, Mat<3>& U, int p, int q) {
    const double a = B(p, p), b = B(q, p);
    const double r = std::sqrt(a * a + b * b);
    if (r == 0.0) return;
    const double c = a / r, s = b / r;
    for (int k = 0; k < 3; ++k) {
        const double bp = B(p, k), bq = B(q, k);
        B(p, k) = c * bp + s * bq;
        B(q, k) = -s * bp + c * bq;
        const double up = U(k, p), uq = U(k, q);
        U(k, p) = c * up + s * uq;
        U(k, q) = -s * up + c * uq;
    }
}

inline void swap_columns(Mat<3>& A, Mat<3>& V, int i, int j) {
    std::swap(A(i, i), A(j, j));
    V.col(i).swap(V.col(j));
    V.col(j) = -V.col(j);  // keep det V = +1
}

}  // namespace

// 3x3 polar SVD (the scheme of McAdams et al. 2011, in double precision with
// exact rotations): cyclic Jacobi sweeps diagonalize F^T F = V Lambda V^T
// (V a product of rotations), the eigenvalues are sorted with V's columns,
// and Givens QR of B = F V gives U (a rotation) and R = diag(Sigma) up to
// round-off: R(0,0), R(1,1) >= 0 and R(2,2) carries the sign of det F. Three
// to four sweeps reach round-off for any F; an MPM step's F is close to a
// rotation times a near-identity stretch, where two usually do. Started from a nearby F's V (the
// warm start below), they start near convergence.
namespace {

PolarSVD<3> polar_svd_from(const Mat<3>& F, Mat<3> V) {
    Mat<3> A = V.transpose() * (F.transpose() * F) * V;
    A = (0.5 * (A + A.transpose())).eval();  // exactly symmetric, as the rotations assume
    for (int sweep = 0; sweep < 8; ++sweep) {
        const double off = A(0, 1) * A(0, 1) + A(0, 2) * A(0, 2) + A(1, 2) * A(1, 2);
        const double diagonal = A(0, 0) * A(0, 0) + A(1, 1) * A(1, 1) + A(2, 2) * A(2, 2);
        if (!(off > 1e-34 * diagonal)) break;  // also ends on zero and non-finite input
        jacobi_rotate(A, V, 0, 1);
        jacobi_rotate(A, V, 0, 2);
        jacobi_rotate(A, V, 1, 2);
    }
    if (A(0, 0) < A(1, 1)) swap_columns(A, V, 0, 1);
    if (A(0, 0) < A(2, 2)) swap_columns(A, V, 0, 2);
    if (A(1, 1) < A(2, 2)) swap_columns(A, V, 1, 2);

    Mat<3> B = F * V;
    Mat<3> U = Mat<3>::Identity();
    givens_qr_step(B, U, 0, 1);
    givens_qr_step(B, U, 0, 2);
    givens_qr_step(B, U, 1, 2);
    PolarSVD<3> out;
    out.U = U;
    out.V = V;
    out.Sigma << B(0, 0), B(1, 1), B(2, 2);
    return out;
}

}  // namespace

template <>
PolarSVD<3> polar_svd<3>(const Mat<3>& F) {
    return polar_svd_from(F, Mat<3>::Identity());
}

template <>
PolarSVD<3> polar_svd<3>(const Mat<3>& F, const Mat<3>& V_start) {
    // Gram-Schmidt, keeping the handedness (the sorting's column swaps keep det V = +1).
    Mat<3> V = Mat<3>::Identity();
    const double n0 = V_start.col(0).norm();
    const Vec<3> e1 = V_start.col(1) - V_start.col(0).dot(V_start.col(1)) / (n0 * n0) * V_start.col(0);
    const double n1 = e1.norm();
    if (n0 > 1e-6 && n1 > 1e-6 && std::isfinite(n0) && std::isfinite(n1)) {  // else: a degenerate start
        V.col(0) = V_start.col(0) / n0;
        V.col(1) = e1 / n1;
        V.col(2) = V.col(0).cross(V.col(1));
    }
    return polar_svd_from(F, V);
}

}  // namespace pnet

