#pragma once
// Packs of lanes as GCC/Clang vector types, 32 bytes each: four doubles or
// eight floats, one AVX2 register with -march=native on x86-64 (two SSE2
// registers otherwise). The fused MLP kernel evaluates one particle per lane,
// so that every weight is loaded once and broadcast to all of them; in single
// precision a register holds twice the particles, and the same instructions do
// twice the work.
//
// exp() is our own: glibc's scalar exp costs about three times the rest of a
// SiLU, and does not vectorize.
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace pnet::simd {

constexpr int kBytes = 32;

template <class S>
struct Pack;

template <>
struct Pack<double> {
    typedef double V __attribute__((vector_size(kBytes)));
    typedef std::int64_t I __attribute__((vector_size(kBytes)));
    static constexpr int kLanes = kBytes / sizeof(double);
};

template <>
struct Pack<float> {
    typedef float V __attribute__((vector_size(kBytes)));
    typedef std::int32_t I __attribute__((vector_size(kBytes)));
    static constexpr int kLanes = kBytes / sizeof(float);
};

constexpr int kLanes = Pack<double>::kLanes;  // double lanes
using Vd = Pack<double>::V;
using Vf = Pack<float>::V;

/// The scalar type of a pack.
template <class V>
using Scalar = std::remove_cv_t<std::remove_reference_t<decltype(V{}[0])>>;

template <class V = Vd>
inline V splat(Scalar<V> x) {
    return V{} + x;
}

template <class V = Vd>
inline V load(const Scalar<V>* p) {
    V v;
    std::memcpy(&v, p, sizeof(V));
    return v;
}

template <class V>
inline void store(Scalar<V>* p, V v) {
    std::memcpy(p, &v, sizeof(V));
}

template <class To, class From>
inline To bit_cast(From v) {
    static_assert(sizeof(To) == sizeof(From));
    To t;
    std::memcpy(&t, &v, sizeof(To));
    return t;
}

/// e^x per lane, within 2 ulp on [-708, 709]; arguments outside are clamped
/// there (e^-708 ~ 3e-308, e^709 ~ 8e307), NaN stays NaN.
///
/// x = n ln2 + r with |r| <= ln2/2 (Cody-Waite: ln2_hi has trailing zero bits,
/// so n ln2_hi is exact), e^r by its Taylor polynomial of degree 12 (remainder
/// < 0.347^13/13! ~ 1.7e-16, under an ulp), then 2^n through the exponent bits.
inline Vd exp(Vd x) {
    using Vi = Pack<double>::I;
    constexpr double kLog2e = 1.4426950408889634074;
    constexpr double kLn2Hi = 6.93147180369123816490e-01;
    constexpr double kLn2Lo = 1.90821492927058770002e-10;
    constexpr double kRound = 6755399441055744.0;  // 1.5 * 2^52: adding it rounds to an integer
    const Vd lo = splat(-708.0), hi = splat(709.0);
    x = hi < x ? hi : x;  // vminpd/vmaxpd; a comparison with NaN is false: NaN passes through
    x = lo > x ? lo : x;

    const Vd t = x * kLog2e + kRound;
    const Vd n = t - kRound;
    const Vd r = (x - n * kLn2Hi) - n * kLn2Lo;

    // 1/k! for k = 12 .. 2, Horner from the top.
    Vd p = splat(1.0 / 479001600.0);
    p = p * r + 1.0 / 39916800.0;
    p = p * r + 1.0 / 3628800.0;
    p = p * r + 1.0 / 362880.0;
    p = p * r + 1.0 / 40320.0;
    p = p * r + 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;

    // The low bits of t hold n + bits(kRound); 2^n has exponent field n + 1023.
    const Vi k = bit_cast<Vi>(t) - bit_cast<Vi>(splat(kRound));
    const Vd scale = bit_cast<Vd>((k + 1023) << 52);
    return p * scale;
}

/// e^x per lane in single precision, within 2 ulp on [-87, 88] (clamped there:
/// e^-87 ~ 1.6e-38, e^88 ~ 1.7e38), NaN stays NaN: the same reduction with
/// float constants (ln2_hi = 0.693359375 has 9 significant bits) and a Taylor
/// polynomial of degree 7 (remainder < 0.347^8/8! ~ 5e-9, under an ulp).
inline Vf exp(Vf x) {
    using Vi = Pack<float>::I;
    constexpr float kLog2e = 1.44269504088896341f;
    constexpr float kLn2Hi = 0.693359375f;
    constexpr float kLn2Lo = -2.12194440e-4f;
    constexpr float kRound = 12582912.0f;  // 1.5 * 2^23
    const Vf lo = splat<Vf>(-87.0f), hi = splat<Vf>(88.0f);
    x = hi < x ? hi : x;
    x = lo > x ? lo : x;

    const Vf t = x * kLog2e + kRound;
    const Vf n = t - kRound;
    const Vf r = (x - n * kLn2Hi) - n * kLn2Lo;

    Vf p = splat<Vf>(1.0f / 5040.0f);
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;

    const Vi k = bit_cast<Vi>(t) - bit_cast<Vi>(splat<Vf>(kRound));
    const Vf scale = bit_cast<Vf>((k + 127) << 23);
    return p * scale;
}

/// SiLU z sigma(z) and its first two derivatives, per lane (sigma = logistic):
///   silu'  = s (1 + z (1 - s)),   silu'' = s (1 - s) (2 + z (1 - 2 s)).
template <class V>
struct Silu {
    V value, d1, d2;
};

template <class V>
inline V sigmoid(V z) {
    using S = Scalar<V>;
    return S(1) / (S(1) + exp(-z));
}

template <class V>
inline V silu(V z) {
    return z * sigmoid(z);
}

template <class V>
inline Silu<V> silu_with_derivatives(V z) {
    using S = Scalar<V>;
    const V s = sigmoid(z);
    const V one_minus_s = S(1) - s;
    return {z * s, s * (S(1) + z * one_minus_s), s * one_minus_s * (S(2) + z * (S(1) - S(2) * s))};
}

/// 1/k! for k = 0 .. n, at compile time.
template <class S, int n>
struct InverseFactorials {
    S c[n + 1];
    constexpr InverseFactorials() : c{} {
        c[0] = 1;
        for (int k = 1; k <= n; ++k) c[k] = c[k - 1] / S(k);
    }
};

/// e^t - 1 per lane, to the pack's relative precision also where e^t ~ 1: below |t| = 1/2
/// by its Taylor polynomial (expm1_polynomial: degree 8 in float, remainder < 0.5^8/9! ~ 1e-8
/// of t; degree 14 in double, < 0.5^14/15! ~ 5e-17), else e^t - 1, which cancels no digit
/// there. `e` = e^t.
template <class V>
inline V expm1_polynomial(V t) {
    using S = Scalar<V>;
    constexpr int degree = std::is_same_v<S, float> ? 8 : 14;
    static constexpr InverseFactorials<S, degree> f{};
    V p = splat<V>(f.c[degree]);
    for (int k = degree - 1; k >= 1; --k) p = p * t + f.c[k];
    return p * t;
}

template <class V>
inline V expm1_with(V t, V e) {
    using S = Scalar<V>;
    const V magnitude = t < S(0) ? -t : t;
    return magnitude < S(0.5) ? expm1_polynomial(t) : e - S(1);
}

/// silu(z0) and the change silu(z0 + dz) - silu(z0) of silu_change().
template <class V>
struct SiluChange {
    V value, change;
};

/// The change of a SiLU, silu(z0 + dz) - silu(z0), to the pack's precision relative to |dz| (no
/// cancellation between two values of silu: the line search's values as differences from the
/// reference, FusedMlp::difference). With e0 = e^-z0, s0 = sigmoid(z0) = 1 / (1 + e0),
/// t0 = 1 - s0 = e0 s0 (without cancellation) and q = e^-dz,
///   silu(z0 + dz) - silu(z0) = dz s1 + z0 (s1 - s0),
///   s1 = s0 / (s0 + t0 q),   s1 - s0 = -(q - 1) t0 s1,
/// and q - 1 = expm1(-dz); s1's denominator is a sum of two positive terms, finite for any z0 and
/// dz. Also returns silu(z0) (`value`), the next layer's reference input.
template <class V>
inline SiluChange<V> silu_change(V z0, V dz) {
    using S = Scalar<V>;
    const V e0 = exp(-z0);
    const V s0 = S(1) / (S(1) + e0);
    const V t0 = e0 * s0;
    // q - 1 by its polynomial alone where every lane's change is below 1/2 (a line search's trial
    // points near their reference): no second exp.
    bool small = true;
    for (int l = 0; l < Pack<S>::kLanes; ++l) small = small && dz[l] < S(0.5) && dz[l] > S(-0.5);
    V q, q_minus_1;
    if (small) {
        q_minus_1 = expm1_polynomial(-dz);
        q = S(1) + q_minus_1;
    } else {
        q = exp(-dz);
        q_minus_1 = expm1_with(-dz, q);
    }
    const V s1 = s0 / (s0 + t0 * q);
    return {z0 * s0, dz * s1 - z0 * (q_minus_1 * t0 * s1)};
}

}  // namespace pnet::simd
