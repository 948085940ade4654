#pragma once
// FEM test systems shared by tests/cpp/fem/ and tests/cpp/contact/: gmsh shapes, elastic
// materials, one-object systems under gravity and the lagged implicit integrator.
#include <memory>
#include <string>
#include <type_traits>
#include <utility>

#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/gmsh_mesher.hpp"

namespace pnet::test {

/// The procedural shape of a dimension: Shape2d or Shape3d.
template <int dim>
using ShapeOf = std::conditional_t<dim == 2, Shape2d, Shape3d>;

/// An axis-aligned box from `min` to `max` (m), meshed with elements of about `element_size`.
template <int dim>
ShapeOf<dim> box_shape(const Vec<dim>& min, const Vec<dim>& max, double element_size) {
    ShapeOf<dim> box;
    box.kind = ShapeOf<dim>::Kind::Box;
    box.min = min;
    box.max = max;
    box.element_size = element_size;
    return box;
}

/// A rectangular frame from `min` to `max` (m) with walls `thickness` thick.
inline Shape2d frame_shape(const Vec<2>& min, const Vec<2>& max, double thickness, double element_size) {
    Shape2d frame;
    frame.kind = Shape2d::Kind::Frame;
    frame.min = min;
    frame.max = max;
    frame.thickness = thickness;
    frame.element_size = element_size;
    return frame;
}

/// An elastic material: `model` with Young's modulus E (Pa), Poisson's ratio 0.3, `density` kg/m^3.
inline MaterialDescription elastic_material(ElasticityModel model, double E, double density = 1000.0) {
    MaterialDescription m;
    m.density = density;
    m.elasticity = model;
    m.elastic.E = E;
    m.elastic.nu = 0.3;
    return m;
}

/// `mesh` as one object of `material` under gravity (9.8 m/s^2 down y); rest not yet made.
template <int dim>
FemSystem<dim> falling_object(Mesh<dim> mesh, const MaterialDescription& material) {
    FemSystem<dim> system;
    system.mesh = std::move(mesh);
    system.materials = {Material<dim>(material)};
    system.element_object.assign(system.mesh.elements.size(), 0);
    system.gravity = Vec<dim>::Zero();
    system.gravity[1] = -9.8;
    return system;
}

/// A stiff (neo-Hookean, E 1e7 Pa) square or cube block, `size` m wide, turned by R onto a slope
/// with the normal `normal` through the origin and lifted dhat / 2 off it; rest made.
template <int dim>
FemSystem<dim> block_on_slope(const Mat<dim>& R, const Vec<dim>& normal, double size, double element_size,
                              double dhat) {
    Mesh<dim> mesh = mesh_shape(box_shape<dim>(Vec<dim>::Zero(), Vec<dim>::Constant(size), element_size), "block");
    for (Vec<dim>& p : mesh.x) p = R * p + 0.5 * dhat * normal;
    mesh.finalize("block on a slope");
    FemSystem<dim> system =
        falling_object<dim>(std::move(mesh), elastic_material(ElasticityModel::NeoHookeanMetal, 1e7));
    system.make_rest();
    return system;
}

/// The lagged implicit integrator (elastic energy) of `system` with `contact`, Newton to
/// `newton_tolerance` m/s in at most 200 iterations.
template <int dim>
FemImplicitIntegrator<dim> lagged_integrator(const FemSystem<dim>& system, const ContactPotential<dim>* contact,
                                             double newton_tolerance) {
    ImplicitOptions options;
    options.newton_tolerance = newton_tolerance;
    options.max_newton_iterations = 200;
    return FemImplicitIntegrator<dim>(system, FemMethod::Lagged, options,
                                      std::make_unique<ElasticParticleEnergy<dim>>(system.materials), contact);
}

/// A metal bar (preset metal: StVK-Hencky + von Mises, E 1e7 Pa) 2 x 10 cm, clamped at the bottom,
/// no gravity; rest quantities not yet made (make_rest()).
inline FemSystem<2> clamped_bar() {
    FemSystem<2> system;
    system.mesh = mesh_shape(box_shape<2>(Vec<2>(0.0, 0.0), Vec<2>(0.02, 0.1), 0.005), "bar");
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
