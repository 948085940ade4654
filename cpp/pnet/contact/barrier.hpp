#pragma once
// The IPC log barrier on a squared distance s (Li et al. 2020; docs/methods.md):
//   b(s) = -(s - s_hat)^2 ln(s / s_hat)  for 0 < s < s_hat,  0 for s >= s_hat,
// s_hat = dhat^2. It is C2 at s_hat and grows without bound as s -> 0, so an
// energy that contains it keeps every iterate intersection-free as long as
// the line search never crosses s = 0 (CCD, ccd/).
#include <cmath>
#include <limits>

namespace pnet {

struct Barrier {
    double s_hat = 0.0;  // dhat^2, m^2

    double value(double s) const {
        if (s >= s_hat) return 0.0;
        if (!(s > 0.0)) return std::numeric_limits<double>::infinity();
        const double r = s - s_hat;
        return -r * r * std::log(s / s_hat);
    }
    /// db/ds.
    double first(double s) const {
        if (s >= s_hat) return 0.0;
        const double r = s - s_hat;
        return -2.0 * r * std::log(s / s_hat) - r * r / s;
    }
    /// d2b/ds2.
    double second(double s) const {
        if (s >= s_hat) return 0.0;
        const double r = s - s_hat;
        return -2.0 * std::log(s / s_hat) - 4.0 * r / s + r * r / (s * s);
    }
};

}  // namespace pnet
