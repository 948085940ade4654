#pragma once
// Four double lanes as a GCC/Clang vector type: one AVX2 register with
// -march=native on x86-64, two SSE2 registers otherwise. The fused MLP kernel
// evaluates four particles at once, one per lane, so that every weight is
// loaded once and broadcast to the four of them.
//
// exp() is our own: glibc's scalar exp costs about three times the rest of a
// SiLU, and does not vectorize.
#include <cstdint>
#include <cstring>

namespace pnet::simd {

constexpr int kLanes = 4;

typedef double Vd __attribute__((vector_size(kLanes * sizeof(double))));
typedef std::int64_t Vi __attribute__((vector_size(kLanes * sizeof(std::int64_t))));

inline Vd splat(double x) { return Vd{x, x, x, x}; }

inline Vd load(const double* p) {
    Vd v;
    std::memcpy(&v, p, sizeof(Vd));
    return v;
}

inline void store(double* p, Vd v) { std::memcpy(p, &v, sizeof(Vd)); }

inline Vd bits_to_double(Vi v) {
    Vd d;
    std::memcpy(&d, &v, sizeof(Vd));
    return d;
}

inline Vi double_to_bits(Vd v) {
    Vi i;
    std::memcpy(&i, &v, sizeof(Vi));
    return i;
}

/// e^x per lane, within 2 ulp on [-708, 709]; arguments outside are clamped
/// there (e^-708 ~ 3e-308, e^709 ~ 8e307), NaN stays NaN.
///
/// x = n ln2 + r with |r| <= ln2/2 (Cody-Waite: ln2_hi has trailing zero bits,
/// so n ln2_hi is exact), e^r by its Taylor polynomial of degree 12 (remainder
/// < 0.347^13/13! ~ 1.7e-16, under an ulp), then 2^n through the exponent bits.
inline Vd exp(Vd x) {
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
    const Vi k = double_to_bits(t) - double_to_bits(splat(kRound));
    const Vd scale = bits_to_double((k + 1023) << 52);
    return p * scale;
}

/// SiLU z sigma(z) and its first two derivatives, per lane (sigma = logistic):
///   silu'  = s (1 + z (1 - s)),   silu'' = s (1 - s) (2 + z (1 - 2 s)).
struct Silu {
    Vd value, d1, d2;
};

inline Vd sigmoid(Vd z) { return 1.0 / (1.0 + exp(-z)); }

inline Vd silu(Vd z) { return z * sigmoid(z); }

inline Silu silu_with_derivatives(Vd z) {
    const Vd s = sigmoid(z);
    const Vd one_minus_s = 1.0 - s;
    return {z * s, s * (1.0 + z * one_minus_s), s * one_minus_s * (2.0 + z * (1.0 - 2.0 * s))};
}

}  // namespace pnet::simd
