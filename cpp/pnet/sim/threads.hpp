#pragma once
// The simulator's thread count. Every parallel loop is OpenMP; LibTorch (model
// loading, the autograd reference) keeps an intra-op count of its own and, on
// its first operation in a thread, sets OpenMP's count to it. Its default can
// be below the cores the process may use (1 of 2 on a 2-core machine), so a
// run that loads a model would silently fall to one core. use_threads() sets
// both counts to the same value before any model is loaded.
namespace pnet {

/// The cores this process may run on: OMP_NUM_THREADS where it is set to a
/// positive integer, else the CPUs of the process's affinity mask.
int available_cores();

/// Sets OpenMP's and LibTorch's thread counts to `threads`, or to
/// available_cores() for threads <= 0. Returns the count set. Results do not
/// depend on it (every sum runs in a fixed order).
int use_threads(int threads = 0);

/// The thread count parallel loops run with now (OpenMP's).
int thread_count();

}  // namespace pnet
