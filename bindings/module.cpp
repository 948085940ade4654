// plasticitynet_sim: PlasticityNet's C++ simulator from Python (docs/architecture.md).
#include "common.hpp"

PYBIND11_MODULE(plasticitynet_sim, m) {
    m.doc() = R"doc(PlasticityNet simulator: MPM, FEM and coupled scenes with the integrators of
integrators() (plasticitynet, the learned energy; return_map, the classical solver; lagged;
explicit; analytic), trained energy models and the analytic materials, from Python and numpy.

    import plasticitynet_sim as pns
    sim = pns.Simulation("scenes/sand_column_2d.json", integrator="plasticitynet")
    sim.advance(5)                      # five frames of 0.02 s
    x = sim.positions                   # (n, 2) float64, m (a live read-only view)
    stats = sim.step_stats()            # per-step Newton / CG / timing arrays

Units are SI throughout (m, s, kg, Pa). Matrices are batches of shape (n, d, d)
with entry [p, i, j] = F_p(i, j); Hessians are (n, d*d, d*d) in the row-major
vec(F) basis, entry (i*d + j, k*d + l). Arrays passed in must be float64.
)doc";
    using namespace pnet::bindings;
    define_errors(m);
    define_scene(m);
    define_materials(m);
    define_models(m);
    define_simulation(m);
    define_metrics(m);
    define_adjoint(m);
}
