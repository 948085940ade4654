#pragma once
// Forward-mode automatic differentiation in n variables, for closed-form
// formulas written once and templated on the scalar (the contact distances,
// contact/distance/point_triangle_edge_edge.cpp): Dual1 carries a value and its gradient, Dual2 also its
// Hessian. Arithmetic follows the chain rule of each operation, e.g. for a product
//   (ab)' = a' b + a b',   (ab)'' = a'' b + a b'' + a' b'^T + b' a'^T,
// and for a quotient q = a / b (from (qb)'' = a''):
//   q' = (a' - q b') / b,  q'' = (a'' - q b'' - q' b'^T - b' q'^T) / b,
// so the derivatives are exact (to round-off), not finite differences. Fixed-size
// Eigen storage only: no heap allocation.
#include <Eigen/Core>

namespace pnet {

template <int n>
struct Dual1 {
    using Gradient = Eigen::Matrix<double, n, 1>;

    double value = 0.0;
    Gradient gradient = Gradient::Zero();

    Dual1() = default;
    /// A constant (implicit, so that formulas may mix in plain numbers).
    Dual1(double v) : value(v), gradient(Gradient::Zero()) {}  // NOLINT(google-explicit-constructor)
    /// The i-th independent variable at value v.
    static Dual1 variable(int i, double v) {
        Dual1 d(v);
        d.gradient[i] = 1.0;
        return d;
    }
};

template <int n>
struct Dual2 {
    using Gradient = Eigen::Matrix<double, n, 1>;
    using Hessian = Eigen::Matrix<double, n, n>;

    double value = 0.0;
    Gradient gradient = Gradient::Zero();
    Hessian hessian = Hessian::Zero();

    Dual2() = default;
    /// A constant (implicit, so that formulas may mix in plain numbers).
    Dual2(double v) : value(v), gradient(Gradient::Zero()), hessian(Hessian::Zero()) {}  // NOLINT
    /// The i-th independent variable at value v.
    static Dual2 variable(int i, double v) {
        Dual2 d(v);
        d.gradient[i] = 1.0;
        return d;
    }
};

// ---------------------------------------------------------------------------
// Dual1

template <int n>
Dual1<n> operator-(const Dual1<n>& a) {
    Dual1<n> r;
    r.value = -a.value;
    r.gradient = -a.gradient;
    return r;
}

template <int n>
Dual1<n> operator+(const Dual1<n>& a, const Dual1<n>& b) {
    Dual1<n> r;
    r.value = a.value + b.value;
    r.gradient = a.gradient + b.gradient;
    return r;
}

template <int n>
Dual1<n> operator-(const Dual1<n>& a, const Dual1<n>& b) {
    Dual1<n> r;
    r.value = a.value - b.value;
    r.gradient = a.gradient - b.gradient;
    return r;
}

template <int n>
Dual1<n> operator*(const Dual1<n>& a, const Dual1<n>& b) {
    Dual1<n> r;
    r.value = a.value * b.value;
    r.gradient = b.value * a.gradient + a.value * b.gradient;
    return r;
}

template <int n>
Dual1<n> operator*(double s, const Dual1<n>& a) {
    Dual1<n> r;
    r.value = s * a.value;
    r.gradient = s * a.gradient;
    return r;
}

template <int n>
Dual1<n> operator*(const Dual1<n>& a, double s) {
    return s * a;
}

template <int n>
Dual1<n> operator/(const Dual1<n>& a, const Dual1<n>& b) {
    Dual1<n> r;
    r.value = a.value / b.value;
    r.gradient = (a.gradient - r.value * b.gradient) / b.value;
    return r;
}

// ---------------------------------------------------------------------------
// Dual2

template <int n>
Dual2<n> operator-(const Dual2<n>& a) {
    Dual2<n> r;
    r.value = -a.value;
    r.gradient = -a.gradient;
    r.hessian = -a.hessian;
    return r;
}

template <int n>
Dual2<n> operator+(const Dual2<n>& a, const Dual2<n>& b) {
    Dual2<n> r;
    r.value = a.value + b.value;
    r.gradient = a.gradient + b.gradient;
    r.hessian = a.hessian + b.hessian;
    return r;
}

template <int n>
Dual2<n> operator-(const Dual2<n>& a, const Dual2<n>& b) {
    Dual2<n> r;
    r.value = a.value - b.value;
    r.gradient = a.gradient - b.gradient;
    r.hessian = a.hessian - b.hessian;
    return r;
}

template <int n>
Dual2<n> operator*(const Dual2<n>& a, const Dual2<n>& b) {
    Dual2<n> r;
    r.value = a.value * b.value;
    r.gradient = b.value * a.gradient + a.value * b.gradient;
    const Eigen::Matrix<double, n, n> outer = a.gradient * b.gradient.transpose();
    r.hessian = b.value * a.hessian + a.value * b.hessian + outer + outer.transpose();
    return r;
}

template <int n>
Dual2<n> operator*(double s, const Dual2<n>& a) {
    Dual2<n> r;
    r.value = s * a.value;
    r.gradient = s * a.gradient;
    r.hessian = s * a.hessian;
    return r;
}

template <int n>
Dual2<n> operator*(const Dual2<n>& a, double s) {
    return s * a;
}

template <int n>
Dual2<n> operator/(const Dual2<n>& a, const Dual2<n>& b) {
    Dual2<n> r;
    const double inv = 1.0 / b.value;
    r.value = a.value * inv;
    r.gradient = (a.gradient - r.value * b.gradient) * inv;
    const Eigen::Matrix<double, n, n> outer = r.gradient * b.gradient.transpose();
    r.hessian = (a.hessian - r.value * b.hessian - outer - outer.transpose()) * inv;
    return r;
}

}  // namespace pnet
