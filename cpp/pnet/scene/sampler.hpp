#pragma once
// Initial MPM particles of a scene (docs/methods.md, docs/scenes.md): the same lattice sampling
// for every integrator, so that runs differ only by their time integration.
#include "pnet/mpm/particles.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet {

/// Particles on the lattice x_k = domain_min + (k + 1/2) h, h = dx / particles_per_cell
/// (particles_per_cell^dim per grid cell, none on a cell face), keeping the
/// points inside each object; shapes are closed (a point on the surface is in).
/// A point inside several objects belongs to the first one.
///
/// Order: objects in scene order; within an object, lattice order with x the
/// fastest index, then y, then z. Each particle gets rest_volume = h^dim,
/// mass = density h^dim, v = the object's velocity, C = 0, F_elastic = I,
/// hardening = SceneObject::initial_hardening() and object = its index.
///
/// Throws std::invalid_argument if scene.dim != dim, SceneError naming the
/// object if one gets no particle (smaller than the lattice spacing, or covered
/// by earlier objects).
template <int dim>
Particles<dim> sample_particles(const Scene& scene);

extern template Particles<2> sample_particles<2>(const Scene&);
extern template Particles<3> sample_particles<3>(const Scene&);

}  // namespace pnet
