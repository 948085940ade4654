#pragma once
// BDF2's variable-step weights (ImplicitOptions::time_integrator "bdf2"), shared by the MPM and FEM steps.
// With omega = dt / dt_prev, the step solves y^{n+1} = y^ + beta dt f(y^{n+1}) about
//   y^ = current y^n - previous y^{n-1},
// current = (1 + omega)^2 / (1 + 2 omega), previous = omega^2 / (1 + 2 omega), beta = (1 + omega) / (1 + 2 omega):
// (4 y^n - y^{n-1}) / 3 and 2/3 at constant steps (omega = 1).

namespace pnet {

struct Bdf2Weights {
    double current, previous, beta;
};

inline Bdf2Weights bdf2_weights(double omega) {
    const double d = 1.0 + 2.0 * omega;
    return {(1.0 + omega) * (1.0 + omega) / d, omega * omega / d, (1.0 + omega) / d};
}

}  // namespace pnet
