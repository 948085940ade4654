#pragma once
// Meshes from gmsh (Debian libgmsh-dev; docs/methods.md): procedural 2D and 3D
// shapes meshed with linear triangles / tetrahedra of a target size, user mesh
// files (.msh, any version gmsh reads) with triangles (2D) or tetrahedra (3D),
// and closed surfaces (.obj, .stl) tetrahedralized.
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

/// A procedural 3D shape, m.
struct Shape3d {
    enum class Kind { Box, Frame, Sphere } kind = Kind::Box;
    Vec<3> min = Vec<3>::Zero(), max = Vec<3>::Zero();  // box, frame: the outer box
    double thickness = 0.0;  // frame: wall thickness; the hole (inset by it in x and y) runs along z
    Vec<3> center = Vec<3>::Zero();                      // sphere
    double radius = 0.0;                                 // sphere
    double element_size = 0.0;                           // target edge length
};

/// Meshes `shape` with linear tetrahedra (gmsh's Delaunay, one thread: deterministic); the
/// result is finalized. Throws MeshError naming `context` for a shape that makes no sense.
Mesh<3> mesh_shape(const Shape3d& shape, const std::string& context);

/// Tetrahedralizes the volume a closed triangle surface bounds (.obj read here, .stl and .ply
/// by gmsh), remeshing the surface to element_size (split at creases sharper than 40 degrees).
/// Throws MeshError "<path>: ..." for a missing file, one without faces, a bad index, or a
/// surface gmsh cannot close into a volume.
Mesh<3> tetrahedralize_surface_file(const std::string& path, double element_size);

/// Reads a mesh file with gmsh: its triangles (dim 2; z must be 0) or
/// tetrahedra (dim 3); other elements (points, lines, boundary triangles) are
/// ignored and unused nodes dropped. Throws MeshError "<path>: ..." for a file
/// gmsh cannot read, one without elements of that kind, or a bad mesh
/// (Mesh::finalize).
template <int dim>
Mesh<dim> read_mesh_file(const std::string& path);

}  // namespace pnet
