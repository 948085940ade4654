#pragma once
#include <string>

namespace pnet {

/// Singular values are clamped to at least this before any constitutive
/// evaluation (docs/physics.md): eps = log(max(Sigma, kSigmaMin)). A material thus
/// sees the clamped polar form F_c = U diag(max(Sigma, kSigmaMin)) V^T, which
/// keeps log-strains finite for (near-)degenerate and inverted F.
inline constexpr double kSigmaMin = 1e-4;

}  // namespace pnet
