#pragma once
// Forward-mode automatic differentiation in n variables, for closed-form
// formulas written once and templated on the scalar (the contact distances,
// contact/distance/point_triangle_edge_edge.cpp; the Cam-Clay projection,
// material/cam_clay.cpp): Dual1 carries a value and its gradient, Dual2 also
// its Hessian. Arithmetic follows the chain rule of each operation, e.g. for a product
//   (ab)' = a' b + a b',   (ab)'' = a'' b + a b'' + a' b'^T + b' a'^T,
// and for a quotient q = a / b (from (qb)'' = a''):
//   q' = (a' - q b') / b,  q'' = (a'' - q b'' - q' b'^T - b' q'^T) / b,
// so the derivatives are exact (to round-off), not finite differences. Fixed-size
// Eigen storage only: no heap allocation.
#include <cmath>

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

// Dual1 with plain numbers, compound assignment, comparisons (of the values: a formula's branches) and the
// elementary functions, so that a formula templated on its scalar runs on Dual1 inside Eigen's fixed-size
// vectors (NumTraits below): the Cam-Clay projection's derivatives (material/return_map_derivative.cpp).

template <int n>
Dual1<n> operator+(const Dual1<n>& a, double s) {
    Dual1<n> r = a;
    r.value += s;
    return r;
}

template <int n>
Dual1<n> operator+(double s, const Dual1<n>& a) {
    return a + s;
}

template <int n>
Dual1<n> operator-(const Dual1<n>& a, double s) {
    Dual1<n> r = a;
    r.value -= s;
    return r;
}

template <int n>
Dual1<n> operator-(double s, const Dual1<n>& a) {
    Dual1<n> r = -a;
    r.value += s;
    return r;
}

template <int n>
Dual1<n> operator/(const Dual1<n>& a, double s) {
    Dual1<n> r;
    r.value = a.value / s;
    r.gradient = a.gradient / s;
    return r;
}

template <int n>
Dual1<n> operator/(double s, const Dual1<n>& b) {
    return Dual1<n>(s) / b;
}

template <int n>
Dual1<n>& operator+=(Dual1<n>& a, const Dual1<n>& b) {
    return a = a + b;
}

template <int n>
Dual1<n>& operator-=(Dual1<n>& a, const Dual1<n>& b) {
    return a = a - b;
}

template <int n>
Dual1<n>& operator*=(Dual1<n>& a, const Dual1<n>& b) {
    return a = a * b;
}

template <int n>
Dual1<n>& operator/=(Dual1<n>& a, const Dual1<n>& b) {
    return a = a / b;
}

template <int n>
Dual1<n>& operator+=(Dual1<n>& a, double s) {
    return a = a + s;
}

template <int n>
Dual1<n>& operator-=(Dual1<n>& a, double s) {
    return a = a - s;
}

template <int n>
Dual1<n>& operator*=(Dual1<n>& a, double s) {
    return a = a * s;
}

template <int n>
Dual1<n>& operator/=(Dual1<n>& a, double s) {
    return a = a / s;
}

#define PNET_DUAL1_COMPARISON(op)                                             \
    template <int n>                                                          \
    bool operator op(const Dual1<n>& a, const Dual1<n>& b) {                  \
        return a.value op b.value;                                            \
    }                                                                         \
    template <int n>                                                          \
    bool operator op(const Dual1<n>& a, double b) {                           \
        return a.value op b;                                                  \
    }                                                                         \
    template <int n>                                                          \
    bool operator op(double a, const Dual1<n>& b) {                           \
        return a op b.value;                                                  \
    }
PNET_DUAL1_COMPARISON(<)
PNET_DUAL1_COMPARISON(<=)
PNET_DUAL1_COMPARISON(>)
PNET_DUAL1_COMPARISON(>=)
#undef PNET_DUAL1_COMPARISON

/// f(a) with f' given: the chain rule's one step.
template <int n>
Dual1<n> chain(const Dual1<n>& a, double f, double df) {
    Dual1<n> r;
    r.value = f;
    r.gradient = df * a.gradient;
    return r;
}

template <int n>
Dual1<n> sqrt(const Dual1<n>& a) {
    const double r = std::sqrt(a.value);
    return chain(a, r, 0.5 / r);
}

template <int n>
Dual1<n> log(const Dual1<n>& a) {
    return chain(a, std::log(a.value), 1.0 / a.value);
}

template <int n>
Dual1<n> sinh(const Dual1<n>& a) {
    return chain(a, std::sinh(a.value), std::cosh(a.value));
}

template <int n>
Dual1<n> pow(const Dual1<n>& a, double e) {
    const double r = std::pow(a.value, e);
    return chain(a, r, e * r / a.value);
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

namespace Eigen {

/// Dual1 as the scalar of Eigen's fixed-size matrices (its value's traits; squaredNorm and the reductions
/// run on it).
template <int n>
struct NumTraits<pnet::Dual1<n>> : GenericNumTraits<double> {
    using Real = pnet::Dual1<n>;
    using NonInteger = pnet::Dual1<n>;
    using Nested = pnet::Dual1<n>;
    using Literal = double;
    enum {
        IsComplex = 0,
        IsInteger = 0,
        IsSigned = 1,
        RequireInitialization = 1,
        ReadCost = n + 1,
        AddCost = n + 1,
        MulCost = 2 * n + 1,
    };
};

template <int n, typename BinaryOp>
struct ScalarBinaryOpTraits<pnet::Dual1<n>, double, BinaryOp> {
    using ReturnType = pnet::Dual1<n>;
};

template <int n, typename BinaryOp>
struct ScalarBinaryOpTraits<double, pnet::Dual1<n>, BinaryOp> {
    using ReturnType = pnet::Dual1<n>;
};

}  // namespace Eigen
