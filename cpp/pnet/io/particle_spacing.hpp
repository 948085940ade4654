#pragma once
// The typical spacing of a cloud of particles, for sizing their splats and spheres in a picture.
#include <vector>

namespace pnet {

/// Typical particle spacing: the median distance to the nearest other particle over a sample of
/// up to 4096 particles, found with a hash grid of cell 2 h0, h0 = (bounding volume / n)^(1/d) the
/// spacing of a lattice filling the particles' bounding box. Particles of a body are nearly that
/// dense (a full N x M lattice of spacing h has h0 = h sqrt((N-1)(M-1) / (N M)), a little less
/// than h), so their nearest neighbour lies within 2 h0, in the 3^d surrounding cells; isolated
/// particles whose neighbour is farther are left out of the median. 0 if n < 2.
/// position: n x dim, a row per particle.
double particle_spacing(const std::vector<double>& position, int dim);

}  // namespace pnet
