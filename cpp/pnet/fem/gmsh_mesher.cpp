#include "pnet/fem/gmsh_mesher.hpp"

#include <gmsh.h>
#include <omp.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <mutex>
#include <unordered_map>

namespace pnet {

namespace {

std::mutex gmsh_mutex;

/// One gmsh session: initialized quiet and deterministic, finalized on exit.
/// gmsh's General.NumThreads sets OpenMP's thread count for the whole process;
/// the caller's is restored when the session ends.
class GmshSession {
public:
    GmshSession() : threads_(omp_get_max_threads()) {
        gmsh::initialize(0, nullptr, /*readConfigFiles=*/false);
        gmsh::option::setNumber("General.Terminal", 0);
        gmsh::option::setNumber("General.Verbosity", 1);
        gmsh::option::setNumber("General.NumThreads", 1);
        gmsh::option::setNumber("Mesh.Algorithm", 6);  // Frontal-Delaunay
        gmsh::option::setNumber("Mesh.RandomSeed", 1);
    }
    ~GmshSession() {
        gmsh::finalize();
        omp_set_num_threads(threads_);
    }
    GmshSession(const GmshSession&) = delete;
    GmshSession& operator=(const GmshSession&) = delete;

private:
    int threads_;
};

/// The elements of gmsh type `type` in the current model, with compact node numbers.
/// What gmsh holds of a mesh: the elements of one type (tags and node tags) and every node.
struct GmshMeshData {
    std::vector<std::size_t> element_tags, node_tags, all_tags;
    std::vector<double> coord;  // 3 per node
};

GmshMeshData query_gmsh_mesh(int type) {
    GmshMeshData d;
    gmsh::model::mesh::getElementsByType(type, d.element_tags, d.node_tags);
    std::vector<double> parametric;
    gmsh::model::mesh::getNodes(d.all_tags, d.coord, parametric, -1, -1, false, false);
    return d;
}

template <int dim>
Mesh<dim> build_mesh(const GmshMeshData& d, const std::string& context) {
    const std::vector<std::size_t>& element_tags = d.element_tags;
    const std::vector<std::size_t>& node_tags = d.node_tags;
    const std::vector<std::size_t>& all_tags = d.all_tags;
    const std::vector<double>& coord = d.coord;
    if (element_tags.empty())
        throw MeshError(context + ": no " + (dim == 2 ? "triangles" : "tetrahedra") + " in the mesh");
    if (node_tags.size() != element_tags.size() * (dim + 1) || coord.size() != 3 * all_tags.size())
        throw MeshError(context + ": inconsistent element or node arrays from gmsh");
    std::unordered_map<std::size_t, std::size_t> position;  // gmsh node tag -> index into coord / 3
    for (std::size_t i = 0; i < all_tags.size(); ++i) position[all_tags[i]] = i;
    Mesh<dim> mesh;
    std::unordered_map<std::size_t, int> index;  // gmsh node tag -> mesh node, in order of first use
    const std::size_t per = dim + 1;
    mesh.elements.resize(element_tags.size());
    for (std::size_t e = 0; e < element_tags.size(); ++e)
        for (std::size_t a = 0; a < per; ++a) {
            const std::size_t tag = node_tags[e * per + a];
            auto [it, inserted] = index.try_emplace(tag, static_cast<int>(mesh.x.size()));
            if (inserted) {
                const auto p = position.find(tag);
                if (p == position.end())
                    throw MeshError(context + ": element " + std::to_string(element_tags[e]) + " refers to node " +
                                    std::to_string(tag) + ", which the file does not define");
                const double* c = &coord[3 * p->second];
                if (dim == 2 && std::abs(c[2]) > 1e-12 * (1.0 + std::abs(c[0]) + std::abs(c[1])))
                    throw MeshError(context + ": node " + std::to_string(tag) + " has z = " + std::to_string(c[2]) +
                                    "; a 2D mesh lies in the plane z = 0");
                Vec<dim> x;
                for (int k = 0; k < dim; ++k) x[k] = c[k];
                mesh.x.push_back(x);
            }
            mesh.elements[e][a] = it->second;
        }
    mesh.finalize(context);
    return mesh;
}

template <int dim>
Mesh<dim> collect(int type, const std::string& context) {
    return build_mesh<dim>(query_gmsh_mesh(type), context);
}

// The pipe protocol of read_mesh_file's child: a status byte ('k' ok, 'e' error), then for an error
// its message, for a mesh each array as its length and its raw elements.
template <typename T>
void put_array(std::string& out, const std::vector<T>& a) {
    const std::uint64_t n = a.size();
    out.append(reinterpret_cast<const char*>(&n), sizeof n);
    if (!a.empty()) out.append(reinterpret_cast<const char*>(a.data()), a.size() * sizeof(T));
}

template <typename T>
bool take_array(const std::string& in, std::size_t& at, std::vector<T>& a) {
    std::uint64_t n = 0;
    if (in.size() - at < sizeof n) return false;
    std::memcpy(&n, in.data() + at, sizeof n);
    at += sizeof n;
    if (n > (in.size() - at) / sizeof(T)) return false;
    a.resize(n);
    if (n > 0) std::memcpy(a.data(), in.data() + at, n * sizeof(T));
    at += n * sizeof(T);
    return true;
}

void write_all(int fd, const std::string& bytes) {
    for (std::size_t done = 0; done < bytes.size();) {
        const ssize_t w = ::write(fd, bytes.data() + done, bytes.size() - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return;
        done += std::size_t(w);
    }
}

/// Reads `path` with gmsh in a child process, so that a file that crashes gmsh's reader (its MSH
/// parser has crashed on malformed files) is a MeshError, not the end of the caller.
GmshMeshData read_in_child(const std::string& path, int type) {
    int fds[2];
    if (::pipe(fds) != 0) throw MeshError(path + ": cannot create a pipe to read the mesh: " + std::strerror(errno));
    std::fflush(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw MeshError(path + ": cannot start the mesh reader: " + std::strerror(errno));
    }
    if (pid == 0) {  // the child: gmsh only, then _exit (no destructors, no atexit handlers of the parent)
        ::close(fds[0]);
        std::string out;
        try {
            GmshSession session;
            gmsh::open(path);
            const GmshMeshData d = query_gmsh_mesh(type);
            out = "k";
            put_array(out, d.element_tags);
            put_array(out, d.node_tags);
            put_array(out, d.all_tags);
            put_array(out, d.coord);
        } catch (const std::exception& e) {
            out = std::string("e") + e.what();
        } catch (...) {
            out = "eunknown error";
        }
        write_all(fds[1], out);
        ::close(fds[1]);
        ::_exit(0);
    }
    ::close(fds[1]);
    std::string in;
    char buffer[1 << 16];
    for (;;) {
        const ssize_t r = ::read(fds[0], buffer, sizeof buffer);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) break;
        in.append(buffer, std::size_t(r));
    }
    ::close(fds[0]);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (WIFSIGNALED(status))
        throw MeshError(path + ": gmsh crashed reading it (signal " + std::to_string(WTERMSIG(status)) +
                        "): a malformed mesh file");
    if (in.empty() || (in[0] != 'k' && in[0] != 'e')) throw MeshError(path + ": the mesh reader ended without a result");
    if (in[0] == 'e') throw MeshError(path + ": gmsh cannot read it: " + in.substr(1));
    GmshMeshData d;
    std::size_t at = 1;
    if (!take_array(in, at, d.element_tags) || !take_array(in, at, d.node_tags) || !take_array(in, at, d.all_tags) ||
        !take_array(in, at, d.coord))
        throw MeshError(path + ": the mesh reader's result is incomplete");
    return d;
}

/// Cuts the entity `hole` (a frame's opening) out of the entity `tag` of dimension `dim`; MeshError
/// naming `context` if gmsh leaves other than one piece.
void cut_hole(int dim, int tag, int hole, const std::string& context) {
    gmsh::vectorpair out;
    std::vector<gmsh::vectorpair> map;
    gmsh::model::occ::cut({{dim, tag}}, {{dim, hole}}, out, map);
    if (out.size() != 1) throw MeshError(context + ": gmsh could not cut the frame's hole");
}

/// Meshes the model's geometry in `dim` dimensions with elements of one size.
void generate_mesh(int dim, double element_size) {
    gmsh::model::occ::synchronize();
    gmsh::option::setNumber("Mesh.CharacteristicLengthMin", element_size);
    gmsh::option::setNumber("Mesh.CharacteristicLengthMax", element_size);
    if (dim == 3) gmsh::option::setNumber("Mesh.Algorithm3D", 1);  // Delaunay
    gmsh::model::mesh::generate(dim);
}

/// build() (a shape's geometry in gmsh's OpenCASCADE kernel, returning nothing), meshed in `dim`
/// dimensions with elements of one size; every gmsh error as a MeshError naming `context`.
template <int dim, typename Build>
Mesh<dim> mesh_geometry(const std::string& context, double element_size, Build&& build) {
    std::lock_guard<std::mutex> lock(gmsh_mutex);
    GmshSession session;
    try {
        gmsh::model::add("shape");
        build();
        generate_mesh(dim, element_size);
        return collect<dim>(dim == 2 ? 2 : 4, context);
    } catch (const MeshError&) {
        throw;
    } catch (const std::exception& e) {
        throw MeshError(context + ": gmsh failed: " + e.what());
    } catch (...) {
        throw MeshError(context + ": gmsh failed");
    }
}

}  // namespace

Mesh<2> mesh_shape(const Shape2d& shape, const std::string& context) {
    auto fail = [&](const std::string& what) { throw MeshError(context + ": " + what); };
    const Vec<2> size = shape.max - shape.min;
    double extent = 0.0;
    switch (shape.kind) {
        case Shape2d::Kind::Box:
        case Shape2d::Kind::Frame:
            if (!(size.minCoeff() > 0.0) || !size.allFinite()) fail("the box must have max > min on both axes");
            extent = size.minCoeff();
            // A hole narrower than round-off (0.55 - 0.45 - 2 x 0.05 = 3e-17) is none: gmsh would fail to cut it.
            if (shape.kind == Shape2d::Kind::Frame &&
                !(shape.thickness > 0.0 && 2.0 * shape.thickness < extent * (1.0 - 1e-6)))
                fail("the frame's thickness must be > 0 and leave a hole (less than half of " + std::to_string(extent) +
                     " m)");
            break;
        case Shape2d::Kind::Disk:
            if (!(shape.radius > 0.0) || !shape.center.allFinite()) fail("the disk's radius must be > 0");
            extent = 2.0 * shape.radius;
            break;
    }
    // Up to round-off: 0.1911 - 0.1811 is 0.00999999... (a 1 cm plate of 1 cm triangles).
    if (!(shape.element_size > 0.0) || !(shape.element_size <= extent * (1.0 + 1e-9)))
        fail("element_size must be > 0 and at most the shape's size (" + std::to_string(extent) + " m)");

    return mesh_geometry<2>(context, shape.element_size, [&] {
        if (shape.kind == Shape2d::Kind::Disk) {
            gmsh::model::occ::addDisk(shape.center[0], shape.center[1], 0.0, shape.radius, shape.radius);
            return;
        }
        const int surface = gmsh::model::occ::addRectangle(shape.min[0], shape.min[1], 0.0, size[0], size[1]);
        if (shape.kind == Shape2d::Kind::Frame) {
            const double t = shape.thickness;
            const int hole = gmsh::model::occ::addRectangle(shape.min[0] + t, shape.min[1] + t, 0.0, size[0] - 2.0 * t,
                                                            size[1] - 2.0 * t);
            cut_hole(2, surface, hole, context);
        }
    });
}

Mesh<3> mesh_shape(const Shape3d& shape, const std::string& context) {
    auto fail = [&](const std::string& what) { throw MeshError(context + ": " + what); };
    const Vec<3> size = shape.max - shape.min;
    double extent = 0.0;
    switch (shape.kind) {
        case Shape3d::Kind::Box:
        case Shape3d::Kind::Frame:
            if (!(size.minCoeff() > 0.0) || !size.allFinite()) fail("the box must have max > min on every axis");
            extent = size.minCoeff();
            if (shape.kind == Shape3d::Kind::Frame) {
                const double narrowest = size.head<2>().minCoeff();  // the hole runs along z
                if (!(shape.thickness > 0.0 && 2.0 * shape.thickness < narrowest * (1.0 - 1e-6)))
                    fail("the frame's thickness must be > 0 and leave a hole (less than half of " +
                         std::to_string(narrowest) + " m)");
                extent = std::min(shape.thickness, size[2]);
            }
            break;
        case Shape3d::Kind::Sphere:
            if (!(shape.radius > 0.0) || !shape.center.allFinite()) fail("the sphere's radius must be > 0");
            extent = 2.0 * shape.radius;
            break;
    }
    if (!(shape.element_size > 0.0) || !(shape.element_size <= 4.0 * extent * (1.0 + 1e-9)))
        fail("element_size must be > 0 and at most 4 x the shape's thinnest part (" + std::to_string(extent) + " m)");

    return mesh_geometry<3>(context, shape.element_size, [&] {
        if (shape.kind == Shape3d::Kind::Sphere) {
            gmsh::model::occ::addSphere(shape.center[0], shape.center[1], shape.center[2], shape.radius);
            return;
        }
        const int volume = gmsh::model::occ::addBox(shape.min[0], shape.min[1], shape.min[2], size[0], size[1], size[2]);
        if (shape.kind == Shape3d::Kind::Frame) {
            // The hole box overshoots both ends along z so that the cut goes cleanly through.
            const double t = shape.thickness;
            const int hole = gmsh::model::occ::addBox(shape.min[0] + t, shape.min[1] + t, shape.min[2] - size[2],
                                                      size[0] - 2.0 * t, size[1] - 2.0 * t, 3.0 * size[2]);
            cut_hole(3, volume, hole, context);
        }
    });
}

namespace {

/// The triangles of a Wavefront OBJ file (v and f lines; polygons fan-triangulated; texture
/// and normal indices ignored; negative indices count from the end), as nodes and triangles.
void read_obj(const std::string& path, std::vector<double>& xyz, std::vector<std::size_t>& triangles) {
    std::ifstream in(path);
    if (!in) throw MeshError(path + ": cannot open it");
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        ++number;
        std::istringstream words(line);
        std::string key;
        words >> key;
        if (key == "v") {
            double c[3];
            if (!(words >> c[0] >> c[1] >> c[2]) || !std::isfinite(c[0] + c[1] + c[2]))
                throw MeshError(path + ": line " + std::to_string(number) + ": a vertex needs 3 finite coordinates");
            xyz.insert(xyz.end(), c, c + 3);
        } else if (key == "f") {
            std::vector<std::size_t> face;
            for (std::string corner; words >> corner;) {
                long index = 0;
                try {
                    index = std::stol(corner.substr(0, corner.find('/')));
                } catch (const std::exception&) {
                    throw MeshError(path + ": line " + std::to_string(number) + ": bad face index '" + corner + "'");
                }
                const long vertices = static_cast<long>(xyz.size() / 3);
                if (index < 0) index += vertices + 1;
                if (index < 1 || index > vertices)
                    throw MeshError(path + ": line " + std::to_string(number) + ": face index " + corner +
                                    " out of range (" + std::to_string(vertices) + " vertices so far)");
                face.push_back(static_cast<std::size_t>(index));  // gmsh node tags start at 1 too
            }
            if (face.size() < 3) throw MeshError(path + ": line " + std::to_string(number) + ": a face needs 3 corners");
            for (std::size_t k = 1; k + 1 < face.size(); ++k) triangles.insert(triangles.end(), {face[0], face[k], face[k + 1]});
        }
    }
    if (triangles.empty()) throw MeshError(path + ": no faces (expected a closed triangle surface)");
}

}  // namespace

Mesh<3> tetrahedralize_surface_file(const std::string& path, double element_size) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) throw MeshError(path + ": no such surface file");
    if (!(element_size > 0.0) || !std::isfinite(element_size)) throw MeshError(path + ": element_size must be > 0");
    const std::string extension = std::filesystem::path(path).extension().string();
    std::vector<double> xyz;
    std::vector<std::size_t> triangles;
    if (extension == ".obj") read_obj(path, xyz, triangles);
    std::lock_guard<std::mutex> lock(gmsh_mutex);
    GmshSession session;
    try {
        gmsh::model::add("surface");
        if (extension == ".obj") {
            const int surface = gmsh::model::addDiscreteEntity(2);
            std::vector<std::size_t> tags(xyz.size() / 3);
            for (std::size_t i = 0; i < tags.size(); ++i) tags[i] = i + 1;
            gmsh::model::mesh::addNodes(2, surface, tags, xyz);
            gmsh::model::mesh::addElementsByType(surface, 2, {}, triangles);
        } else {
            gmsh::merge(path);  // .stl, .ply (gmsh's readers)
        }
        gmsh::model::mesh::removeDuplicateNodes();
        // Surfaces split at sharp (> 40 degree) creases, remeshed to element_size; then the volume
        // they close.
        gmsh::model::mesh::classifySurfaces(40.0 * M_PI / 180.0, true, false, M_PI);
        gmsh::model::mesh::createGeometry();
        gmsh::vectorpair surfaces;
        gmsh::model::getEntities(surfaces, 2);
        if (surfaces.empty()) throw MeshError(path + ": no surface in the file");
        std::vector<int> tags;
        for (const auto& [d, tag] : surfaces) tags.push_back(tag);
        const int loop = gmsh::model::geo::addSurfaceLoop(tags);
        gmsh::model::geo::addVolume({loop});
        gmsh::model::geo::synchronize();
        gmsh::option::setNumber("Mesh.CharacteristicLengthMin", element_size);
        gmsh::option::setNumber("Mesh.CharacteristicLengthMax", element_size);
        gmsh::option::setNumber("Mesh.Algorithm3D", 1);
        gmsh::model::mesh::generate(3);
        return collect<3>(4, path);
    } catch (const MeshError&) {
        throw;
    } catch (const std::exception& e) {
        throw MeshError(path + ": gmsh could not tetrahedralize it (is the surface closed?): " + e.what());
    } catch (...) {
        throw MeshError(path + ": gmsh could not tetrahedralize it (is the surface closed?)");
    }
}

template <int dim>
Mesh<dim> read_mesh_file(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) throw MeshError(path + ": no such mesh file");
    std::lock_guard<std::mutex> lock(gmsh_mutex);
    // gmsh types: 2 = 3-node triangle, 4 = 4-node tetrahedron.
    return build_mesh<dim>(read_in_child(path, dim == 2 ? 2 : 4), path);
}

template Mesh<2> read_mesh_file<2>(const std::string&);
template Mesh<3> read_mesh_file<3>(const std::string&);

}  // namespace pnet
