#pragma once
// FEM test systems shared by tests/cpp/fem/.
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/gmsh_mesher.hpp"

namespace pnet::test {

/// A metal bar (preset metal: StVK-Hencky + von Mises, E 1e7 Pa) 2 x 10 cm, clamped at the bottom,
/// no gravity; rest quantities not yet made (make_rest()).
inline FemSystem<2> clamped_bar() {
    Shape2d box;
    box.kind = Shape2d::Kind::Box;
    box.min = Vec<2>(0.0, 0.0);
    box.max = Vec<2>(0.02, 0.1);
    box.element_size = 0.005;
    FemSystem<2> system;
    system.mesh = mesh_shape(box, "bar");
    system.materials = {Material<2>(material_preset("metal"))};
    system.element_object.assign(system.mesh.elements.size(), 0);
    system.fixed_node.assign(system.mesh.nodes(), 0);
    system.prescribed_velocity.assign(system.mesh.nodes(), Vec<2>::Zero());
    for (std::size_t i = 0; i < system.mesh.nodes(); ++i)
        if (system.mesh.x[i][1] < 1e-9) system.fixed_node[i] = 1;
    return system;
}

/// The clamped bar with its top pushed down at `speed` m/s.
inline FemSystem<2> crushed_bar(double speed) {
    FemSystem<2> system = clamped_bar();
    for (std::size_t i = 0; i < system.mesh.nodes(); ++i)
        if (system.mesh.x[i][1] > 0.1 - 1e-9) {
            system.fixed_node[i] = 1;
            system.prescribed_velocity[i] = Vec<2>(0.0, -speed);
        }
    system.make_rest();
    return system;
}

}  // namespace pnet::test
