#pragma once
// Particle frames as binary little-endian PLY point clouds, the format that
// ParaView, Blender (4.x importer), Houdini, MeshLab and Open3D all read as
// points with per-vertex attributes.
//
// Layout (one `vertex` per particle, every property a little-endian double):
//
//     ply
//     format binary_little_endian 1.0
//     comment plasticitynet particles
//     comment dim 2
//     comment run_id <id>       (optional: the pnet simulate run that wrote the frame)
//     element vertex <n>
//     property double x         position, m (z = 0 in 2D)
//     property double y
//     property double z
//     property double vx        velocity, m/s (vz = 0 in 2D)
//     property double vy
//     property double vz
//     property double mass      kg
//     property double hardening (Cam-Clay a, von Mises h; 0 for sand)
//     end_header
//
// Why double rather than float: frames double as restart data and as the
// reference in cross-implementation comparisons, where a round trip must be
// bit-exact; float would lose ~1e-7 relative on positions. The viewers above
// read double properties (converting to float for display), so nothing is
// gained by float but half the file size. 2D frames keep x, y, z so that the
// same file opens in 3D viewers as a flat point cloud; `comment dim` records
// the dimension so a reader can drop z again.
#include <cstddef>
#include <string>
#include <vector>

namespace pnet {

/// Particle fields as flat arrays: row i of position/velocity is particle i.
struct PlyParticles {
    int dim = 2;                    // 2 or 3
    std::vector<double> position;   // n * dim, m
    std::vector<double> velocity;   // n * dim, m/s
    std::vector<double> mass;       // n, kg
    std::vector<double> hardening;  // n
    std::string run_id;             // the run that wrote the frame ("comment run_id"); "" if none

    std::size_t size() const { return mass.size(); }
};

/// Writes p atomically (write_file_atomically) in the layout above. Throws
/// std::invalid_argument "<path>: ..." if dim is not 2 or 3 or the array sizes disagree, and
/// std::runtime_error "<path>: ..." if the file cannot be written.
void write_particles_ply(const std::string& path, const PlyParticles& p);

/// Reads a file in the layout above. dim = 0 takes the dimension from the `comment dim` line;
/// dim = 2 or 3 requires that line, if present, to agree, and in 2D requires z = vz = 0.
/// Throws std::runtime_error "<path>: <problem>" for a missing or non-PLY file, a header other
/// than the one above (format, element, property names and types), or vertex data shorter or
/// longer than the header announces.
PlyParticles read_particles_ply(const std::string& path, int dim = 0);

/// A FEM frame: the mesh's nodes and triangles (2D: the elements; 3D: the boundary
/// triangles of the tetrahedral mesh, each with the hardening of its tetrahedron; every
/// node is kept, so node i of the frame is node i of the simulation). Layout (binary
/// little-endian; Blender, ParaView and MeshLab open it as a surface):
///
///     ply / format binary_little_endian 1.0 / comment plasticitynet mesh / comment dim D
///     [comment run_id <id>]
///     element vertex <n>    property double x y z vx vy vz   (2D: z = vz = 0)
///     element face <m>      property list uchar int vertex_indices
///                           property double hardening          (the element's state)
///     end_header
struct PlyMesh {
    int dim = 2;
    std::vector<double> position;   // n * dim, m
    std::vector<double> velocity;   // n * dim, m/s
    std::vector<int> triangles;     // m * 3 node indices
    std::vector<double> hardening;  // m
    std::string run_id;             // as PlyParticles::run_id

    std::size_t nodes() const { return position.size() / dim; }
};

/// Writes m atomically. Throws std::invalid_argument "<path>: ..." for sizes that disagree or
/// an index out of range, std::runtime_error if the file cannot be written.
void write_mesh_ply(const std::string& path, const PlyMesh& m);

/// Reads a file in that layout; std::runtime_error "<path>: <problem>" for anything else
/// (another header, a truncated or overlong body, an index out of range).
PlyMesh read_mesh_ply(const std::string& path);

}  // namespace pnet
