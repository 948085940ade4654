#pragma once
// Wall-clock seconds for the step statistics' timings (StepStats, the contact's broad phase and
// CCD): one steady clock for the whole library.
#include <chrono>

namespace pnet {

using Clock = std::chrono::steady_clock;

/// Seconds from start to now.
inline double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace pnet
