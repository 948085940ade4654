// Included first in every translation unit of ours when the compiler is GCC 12 (CMakeLists.txt).
//
// GCC 12 reports false positives of three kinds inside its own intrinsics headers once inlined into
// Eigen's vectorized code:
//   -Wmaybe-uninitialized and -Wuninitialized: the AVX-512 intrinsics (avx512fintrin.h, and
//     avxintrin.h under them) build "undefined" vectors as `__m256d __Y = __Y;` (GCC bug 105593, fixed
//     in GCC 13): ~2,850 warnings in a fresh build on a machine with AVX-512 and -march=native, and 6
//     of the definite kind (Eigen's 4x4 self-adjoint eigensolver, _mm512_max_pd);
//   -Warray-bounds: an unaligned 4-double load (avxintrin.h) that Eigen's comma initializer issues
//     only on the branch where the source has 4 doubles, seen by the warning on a Vec<2>'s as well.
// None of them is about our code. These warnings are decided by the pragma state at the intrinsic's
// own line, so including the intrinsics once here, with the two warnings off, silences exactly those
// and leaves both on for everything else.
#pragma once
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Warray-bounds"
#include <immintrin.h>
#pragma GCC diagnostic pop
