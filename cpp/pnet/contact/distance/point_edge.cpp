#include "pnet/contact/distance/point_edge.hpp"

namespace pnet {

namespace {

/// Scatters a 4 x 4 point-point block (points i, j of three) into a 6 x 6 matrix.
Mat6 embed(const Mat4& H, int i, int j) {
    Mat6 out = Mat6::Zero();
    const int slot[2] = {i, j};
    for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 2; ++c) out.block<2, 2>(2 * slot[r], 2 * slot[c]) = H.block<2, 2>(2 * r, 2 * c);
    return out;
}

Vec6 embed(const Vec4& g, int i, int j) {
    Vec6 out = Vec6::Zero();
    out.segment<2>(2 * i) = g.head<2>();
    out.segment<2>(2 * j) = g.tail<2>();
    return out;
}

// Interior case: s = c^2 / L2 with c = cross(e, r), e = b - a, r = p - a, L2 = e.e.
// In the stacked coordinates q = (p, a, b): e = J_e q, r = J_r q, c = e^T R r with
// R = [[0, 1], [-1, 0]], so dc = J_e^T R r + J_r^T R^T e, d2c = J_e^T R J_r + J_r^T R^T J_e,
// dL2 = 2 J_e^T e, d2L2 = 2 J_e^T J_e.
struct Interior {
    Eigen::Matrix<double, 2, 6> Je, Jr;
    Eigen::Matrix2d R;
    Vec<2> e, r;
    double c, L2;
    Vec6 dc, dL2;

    Interior(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b) {
        Je.setZero();
        Jr.setZero();
        Je.block<2, 2>(0, 2) = -Eigen::Matrix2d::Identity();
        Je.block<2, 2>(0, 4) = Eigen::Matrix2d::Identity();
        Jr.block<2, 2>(0, 0) = Eigen::Matrix2d::Identity();
        Jr.block<2, 2>(0, 2) = -Eigen::Matrix2d::Identity();
        R << 0.0, 1.0, -1.0, 0.0;
        e = b - a;
        r = p - a;
        c = e.dot(R * r);
        L2 = e.squaredNorm();
        dc = Je.transpose() * (R * r) + Jr.transpose() * (R.transpose() * e);
        dL2 = 2.0 * Je.transpose() * e;
    }
};

}  // namespace

PointEdgeCase point_edge_case(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b) {
    const Vec<2> e = b - a;
    const double t = (p - a).dot(e) / e.squaredNorm();
    if (t <= 0.0) return PointEdgeCase::EndpointA;
    if (t >= 1.0) return PointEdgeCase::EndpointB;
    return PointEdgeCase::Interior;
}

double point_point_distance_sq(const Vec<2>& p, const Vec<2>& a) { return (p - a).squaredNorm(); }

Vec4 point_point_distance_sq_gradient(const Vec<2>& p, const Vec<2>& a) {
    Vec4 g;
    g.head<2>() = 2.0 * (p - a);
    g.tail<2>() = -2.0 * (p - a);
    return g;
}

Mat4 point_point_distance_sq_hessian() {
    Mat4 H = Mat4::Zero();
    H.block<2, 2>(0, 0) = H.block<2, 2>(2, 2) = 2.0 * Eigen::Matrix2d::Identity();
    H.block<2, 2>(0, 2) = H.block<2, 2>(2, 0) = -2.0 * Eigen::Matrix2d::Identity();
    return H;
}

double point_edge_distance_sq(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, PointEdgeCase c) {
    switch (c) {
        case PointEdgeCase::EndpointA: return point_point_distance_sq(p, a);
        case PointEdgeCase::EndpointB: return point_point_distance_sq(p, b);
        case PointEdgeCase::Interior: {
            const Vec<2> e = b - a, r = p - a;
            const double cross = e[0] * r[1] - e[1] * r[0];
            return cross * cross / e.squaredNorm();
        }
    }
    return 0.0;
}

Vec6 point_edge_distance_sq_gradient(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, PointEdgeCase c) {
    switch (c) {
        case PointEdgeCase::EndpointA: return embed(point_point_distance_sq_gradient(p, a), 0, 1);
        case PointEdgeCase::EndpointB: return embed(point_point_distance_sq_gradient(p, b), 0, 2);
        case PointEdgeCase::Interior: {
            const Interior I(p, a, b);
            return 2.0 * I.c / I.L2 * I.dc - I.c * I.c / (I.L2 * I.L2) * I.dL2;
        }
    }
    return Vec6::Zero();
}

Mat6 point_edge_distance_sq_hessian(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, PointEdgeCase c) {
    switch (c) {
        case PointEdgeCase::EndpointA: return embed(point_point_distance_sq_hessian(), 0, 1);
        case PointEdgeCase::EndpointB: return embed(point_point_distance_sq_hessian(), 0, 2);
        case PointEdgeCase::Interior: {
            const Interior I(p, a, b);
            const Mat6 d2c = I.Je.transpose() * I.R * I.Jr + I.Jr.transpose() * I.R.transpose() * I.Je;
            const Mat6 d2L2 = 2.0 * I.Je.transpose() * I.Je;
            const double L2 = I.L2, L4 = L2 * L2, c = I.c;
            return 2.0 / L2 * (I.dc * I.dc.transpose() + c * d2c) -
                   2.0 * c / L4 * (I.dc * I.dL2.transpose() + I.dL2 * I.dc.transpose()) - c * c / L4 * d2L2 +
                   2.0 * c * c / (L4 * L2) * (I.dL2 * I.dL2.transpose());
        }
    }
    return Mat6::Zero();
}

}  // namespace pnet
