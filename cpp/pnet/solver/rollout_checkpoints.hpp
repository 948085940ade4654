#pragma once
// Where a differentiated rollout keeps its checkpoints (the MPM, FEM and coupled adjoints; docs/adjoint.md).
#include <algorithm>
#include <cmath>

namespace pnet {

/// The steps between checkpoints: checkpoint_every, or for 0 ceil(sqrt(steps)), so that the checkpoints and the
/// segment the backward pass recomputes hold about 2 sqrt(steps) states.
inline int checkpoint_spacing(int steps, int checkpoint_every) {
    return checkpoint_every > 0 ? checkpoint_every : std::max(1, static_cast<int>(std::ceil(std::sqrt(steps))));
}

}  // namespace pnet
