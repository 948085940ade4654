#include "pnet/metrics/mesh_comparison.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "pnet/contact/collisions/point_facet.hpp"
#include "pnet/fem/mesh.hpp"
#include "pnet/io/ply.hpp"

namespace pnet {
namespace {

PlyMesh read_mesh_frame(const std::string& path, const RunInfo& run) {
    PlyMesh m;
    try {
        m = read_mesh_ply(path);
    } catch (const std::runtime_error& e) {
        throw RunInputError(e.what());  // names the path
    }
    if (m.dim != run.dim)
        throw RunInputError(path + ": a " + std::to_string(m.dim) + "D mesh, but " + run.json_file + " has dim " +
                            std::to_string(run.dim));
    if (!run.run_id.empty() && m.run_id != run.run_id)
        throw RunInputError(path + ": not written by the run in " + run.json_file +
                            "; the folder mixes runs: simulate again with --overwrite");
    return m;
}

template <int dim>
std::vector<Vec<dim>> points(const std::vector<double>& flat, std::size_t count) {
    std::vector<Vec<dim>> out(count);
    for (std::size_t i = 0; i < count; ++i)
        for (int a = 0; a < dim; ++a) out[i][a] = flat[i * dim + a];
    return out;
}

/// The closed boundary of a run's body from one of its mesh frames (the topology is that of every
/// frame): 2D, the outline of the elements (Mesh::finalize's boundary facets); 3D, the frame's
/// triangles (a 3D mesh frame holds the boundary).
template <int dim>
std::vector<std::array<int, dim>> boundary_facets(const PlyMesh& m, const std::string& path) {
    std::vector<std::array<int, dim>> facets;
    if constexpr (dim == 3) {
        for (std::size_t t = 0; t < m.triangles.size(); t += 3)
            facets.push_back({m.triangles[t], m.triangles[t + 1], m.triangles[t + 2]});
    } else {
        Mesh<2> mesh;
        mesh.x = points<2>(m.position, m.nodes());
        for (std::size_t t = 0; t < m.triangles.size(); t += 3)
            mesh.elements.push_back({m.triangles[t], m.triangles[t + 1], m.triangles[t + 2]});
        try {
            mesh.finalize(path);
        } catch (const MeshError& e) {
            throw RunInputError(e.what());
        }
        facets = std::move(mesh.boundary);
    }
    return facets;
}

/// How many of B's particles (frame file particle_path) are inside its body (mesh positions, boundary).
template <int dim>
long particles_inside(const std::string& particle_path, const PlyMesh& mesh,
                      const std::vector<std::array<int, dim>>& boundary, const RunInfo& run) {
    PlyParticles p;
    try {
        p = read_particles_ply(particle_path, run.dim);
    } catch (const std::runtime_error& e) {
        throw RunInputError(e.what());
    }
    return static_cast<long>(
        count_inside<dim>(points<dim>(p.position, p.size()), points<dim>(mesh.position, mesh.nodes()), boundary));
}

}  // namespace

MeshComparison compare_meshes(const RunPair& pair, const std::function<void(std::size_t, std::size_t)>& progress) {
    const RunInfo& a = pair.a;
    const RunInfo& b = pair.b;
    if (!a.meshes) throw RunInputError(a.json_file + ": the run has no meshes to compare");
    MeshComparison c;
    std::vector<std::array<int, 2>> boundary_2d;  // B's body, from its first compared frame (coupled runs)
    std::vector<std::array<int, 3>> boundary_3d;
    for (std::size_t k = 0; k < pair.common.size(); ++k) {
        const int frame = pair.common[k];
        auto mesh_path = [&](const RunInfo& run) {
            const auto found = run.mesh_frames.find(frame);
            if (found == run.mesh_frames.end())
                throw RunInputError(run.dir + ": frame " + std::to_string(frame) + " has no mesh file");
            return found->second;
        };
        const std::string path_a = mesh_path(a), path_b = mesh_path(b);
        const PlyMesh ma = read_mesh_frame(path_a, a), mb = read_mesh_frame(path_b, b);
        if (c.frames.empty()) {
            c.nodes = a.body_nodes > 0 ? a.body_nodes : ma.nodes();
            if (c.nodes > ma.nodes())
                throw RunInputError(path_a + ": " + std::to_string(ma.nodes()) + " nodes, but " + a.json_file +
                                    "'s first mesh has " + std::to_string(c.nodes));
            c.size = a.body_size;
            if (!(c.size > 0.0)) {
                double sq = 0.0;
                for (int d = 0; d < a.dim; ++d) {
                    double lo = INFINITY, hi = -INFINITY;
                    for (std::size_t i = 0; i < c.nodes; ++i) {
                        lo = std::min(lo, ma.position[i * a.dim + d]);
                        hi = std::max(hi, ma.position[i * a.dim + d]);
                    }
                    sq += (hi - lo) * (hi - lo);
                }
                c.size = std::sqrt(sq);
            }
        }
        if (mb.nodes() < c.nodes)
            throw RunInputError(path_b + ": " + std::to_string(mb.nodes()) + " nodes, fewer than the " +
                                std::to_string(c.nodes) + " of the body in " + path_a);
        FrameMeshError f;
        f.frame = frame;
        f.time = frame * a.frame_dt;
        for (std::size_t i = 0; i < c.nodes; ++i) {
            double sq = 0.0;
            for (int d = 0; d < a.dim; ++d) {
                const double diff = ma.position[i * a.dim + d] - mb.position[i * a.dim + d];
                sq += diff * diff;
            }
            const double dist = std::sqrt(sq);
            f.mean += dist;
            f.max = std::max(f.max, dist);
        }
        f.mean /= static_cast<double>(std::max<std::size_t>(c.nodes, 1));
        f.mean_pct = 100.0 * f.mean / c.size;
        f.max_pct = 100.0 * f.max / c.size;
        if (b.particles) {
            const auto found = b.frames.find(frame);
            if (found == b.frames.end())
                throw RunInputError(b.dir + ": frame " + std::to_string(frame) + " has meshes but no particles");
            if (b.dim == 2) {
                if (boundary_2d.empty()) boundary_2d = boundary_facets<2>(mb, path_b);
                f.penetrations = particles_inside<2>(found->second, mb, boundary_2d, b);
            } else {
                if (boundary_3d.empty()) boundary_3d = boundary_facets<3>(mb, path_b);
                f.penetrations = particles_inside<3>(found->second, mb, boundary_3d, b);
            }
        }
        c.frames.push_back(f);
        if (progress) progress(k + 1, pair.common.size());
    }
    return c;
}

std::string mesh_comparison_csv(const MeshComparison& c) {
    const bool coupled = !c.frames.empty() && c.frames.front().penetrations >= 0;
    std::string out =
        std::string("frame,time_s,mean_m,max_m,mean_pct,max_pct,size_m") + (coupled ? ",penetrations" : "") + "\n";
    char line[256];
    for (const FrameMeshError& f : c.frames) {
        std::snprintf(line, sizeof line, "%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g", f.frame, f.time, f.mean, f.max,
                      f.mean_pct, f.max_pct, c.size);
        out += line;
        if (coupled) out += "," + std::to_string(f.penetrations);
        out += "\n";
    }
    return out;
}

}  // namespace pnet
