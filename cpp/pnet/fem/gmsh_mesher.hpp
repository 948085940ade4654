#pragma once
// Meshes from gmsh (Debian libgmsh-dev; DESIGN.md §4.2): procedural 2D shapes
// meshed with linear triangles of a target size, and user mesh files (.msh,
// any version gmsh reads) with triangles (2D) or tetrahedra (3D).
//
// gmsh is a process-wide library with global state: every call here holds one
// lock, opens a gmsh session and closes it, runs gmsh with one thread and a
// fixed algorithm (Frontal-Delaunay in 2D), so the same input gives the same
// mesh on every run.
#include <string>

#include "pnet/fem/mesh.hpp"

namespace pnet {

/// A procedural 2D shape, m.
struct Shape2d {
    enum class Kind { Box, Frame, Disk } kind = Kind::Box;
    Vec<2> min = Vec<2>::Zero(), max = Vec<2>::Zero();  // box, frame: the outer rectangle
    double thickness = 0.0;                              // frame: wall thickness (the hole is inset by it)
    Vec<2> center = Vec<2>::Zero();                      // disk
    double radius = 0.0;                                 // disk
    double element_size = 0.0;                           // target edge length
};

/// Meshes `shape` with gmsh; the result is finalized (Mesh::finalize). Throws
/// MeshError naming `context` for a shape that makes no sense (empty box, a
/// frame with no hole, a size <= 0 or above the shape) or that gmsh cannot mesh.
Mesh<2> mesh_shape(const Shape2d& shape, const std::string& context);

/// Reads a mesh file with gmsh: its triangles (dim 2; z must be 0) or
/// tetrahedra (dim 3); other elements (points, lines, boundary triangles) are
/// ignored and unused nodes dropped. Throws MeshError "<path>: ..." for a file
/// gmsh cannot read, one without elements of that kind, or a bad mesh
/// (Mesh::finalize).
template <int dim>
Mesh<dim> read_mesh_file(const std::string& path);

}  // namespace pnet
