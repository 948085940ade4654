// Accuracy metrics (docs/metrics.md): IoU of grid mass fields, the B-spline
// rasterization behind it, and the frame-by-frame comparison of two runs.
#include <algorithm>
#include <filesystem>

#include "common.hpp"
#include "pnet/contact/collisions/point_facet.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/metrics/iou.hpp"
#include "pnet/metrics/mesh_comparison.hpp"
#include "pnet/metrics/run_comparison.hpp"
#include "pnet/nn/model_file.hpp"  // FileNotFoundError

namespace pnet::bindings {

namespace {

/// A 2D or 3D float64 array as a GridField (unit spacing; iou() only needs both on the same grid).
GridField field(const py::handle& obj, const std::string& name) {
    if (!py::isinstance<py::array>(obj) && !py::isinstance<py::list>(obj) && !py::isinstance<py::tuple>(obj))
        throw py::value_error(name + ": expected a float64 array of shape (nx, ny) or (nx, ny, nz), got " +
                              py::str(py::type::of(obj)).cast<std::string>());
    const py::array probe = py::array::ensure(obj);
    const py::ssize_t ndim = probe ? probe.ndim() : 0;
    if (ndim != 2 && ndim != 3)
        throw py::value_error(name + ": expected a float64 array of shape (nx, ny) or (nx, ny, nz), got " +
                              std::to_string(ndim) + " dimensions");
    std::vector<py::ssize_t> tail(probe.shape() + 1, probe.shape() + ndim);
    const auto a = batch_array(obj, name, tail);
    GridField g;
    g.dim = static_cast<int>(ndim);
    g.dx = 1.0;
    for (int k = 0; k < g.dim; ++k) g.nodes[k] = static_cast<int>(a.shape(k));
    g.value.assign(a.data(), a.data() + a.size());
    return g;
}

/// fn(a, b) on two run directories (each must exist: FileNotFoundError), without the GIL; a
/// RunInputError (runs that cannot be compared) as ValueError.
template <typename Fn>
auto compare_directories(const py::object& dir_a, const py::object& dir_b, Fn&& fn) {
    const std::string a = path_string(dir_a), b = path_string(dir_b);
    for (const std::string& dir : {a, b})
        if (!std::filesystem::exists(dir)) throw FileNotFoundError(dir + ": no such directory");
    try {
        py::gil_scoped_release release;
        return fn(a, b);
    } catch (const RunInputError& e) {
        throw py::value_error(e.what());
    }
}

/// d[name] = the frames' values of each (name, member) field, as a float64 array, and d["frame"].
template <typename Frame, std::size_t N>
void add_frame_columns(py::dict& d, const std::vector<Frame>& frames,
                       const std::pair<const char*, double Frame::*> (&fields)[N]) {
    const py::ssize_t n = static_cast<py::ssize_t>(frames.size());
    py::array_t<std::int64_t> frame(n);
    for (py::ssize_t k = 0; k < n; ++k) frame.mutable_data()[k] = frames[k].frame;
    d["frame"] = frame;
    for (const auto& [name, field] : fields) {
        py::array_t<double> values(n);
        for (py::ssize_t k = 0; k < n; ++k) values.mutable_data()[k] = frames[k].*field;
        d[name] = values;
    }
}

/// (n, d) float64 rows of a flat array.
py::array_t<double> rows_of(const std::vector<double>& flat, int dim) {
    const py::ssize_t n = static_cast<py::ssize_t>(flat.size()) / dim;
    py::array_t<double> a({n, static_cast<py::ssize_t>(dim)});
    std::copy(flat.begin(), flat.end(), a.mutable_data());
    return a;
}

/// What particle and mesh frames share: dim, position and velocity (n, dim), hardening, run_id.
template <typename Frame>
py::dict frame_dict(const Frame& frame) {
    py::dict d;
    d["dim"] = frame.dim;
    d["position"] = rows_of(frame.position, frame.dim);
    d["velocity"] = rows_of(frame.velocity, frame.dim);
    d["hardening"] = py::array_t<double>(static_cast<py::ssize_t>(frame.hardening.size()), frame.hardening.data());
    d["run_id"] = frame.run_id;
    return d;
}

/// A frame file read by `read`: FileNotFoundError when it is missing, ValueError naming the file and the
/// problem when it is not a frame `pnet simulate` writes.
template <typename Read>
auto read_frame(const py::object& path, Read&& read) {
    const std::string file = path_string(path);
    if (!std::filesystem::is_regular_file(file)) throw FileNotFoundError(file + ": no such file");
    try {
        py::gil_scoped_release release;
        return read(file);
    } catch (const std::runtime_error& e) {
        throw py::value_error(e.what());
    }
}

}  // namespace

py::array to_numpy(const GridField& g) {
    const int n0 = g.nodes[0], n1 = g.nodes[1], n2 = g.nodes[2];
    py::array_t<double> out = g.dim == 2 ? py::array_t<double>({n0, n1}) : py::array_t<double>({n0, n1, n2});
    double* data = out.mutable_data();
    for (int i = 0; i < n0; ++i)
        for (int j = 0; j < n1; ++j)
            for (int k = 0; k < n2; ++k) data[(static_cast<std::size_t>(i) * n1 + j) * n2 + k] = g.value[g.index(i, j, k)];
    return std::move(out);
}

void define_metrics(py::module_& m) {
    m.def(
        "iou",
        [](const py::object& a, const py::object& b) {
            const GridField fa = field(a, "a"), fb = field(b, "b");
            if (fa.nodes != fb.nodes) throw py::value_error("a and b: the mass fields have different shapes");
            const IouResult r = iou(fa, fb);
            py::dict d;
            d["soft"] = r.soft;
            d["binary"] = r.binary;
            d["plasticinelab"] = r.plasticinelab;
            return d;
        },
        py::arg("a"), py::arg("b"),
        R"doc(IoU of two nodal mass fields of the same shape (e.g. Simulation.grid_mass()):
a dict with soft = sum min(a, b) / sum max(a, b) (the project's accuracy metric),
binary (occupied nodes, > 1e-3 of each field's maximum) and plasticinelab
(PlasticineLab's formula, kept for reference; docs/metrics.md). ValueError for negative or
non-finite values, an all-zero field, or different shapes.)doc");

    m.def(
        "rasterize_mass",
        [](const py::object& positions, const py::object& mass, const std::vector<double>& domain_min,
           const std::vector<double>& domain_max, double dx) {
            const auto x = batch_array(positions, "positions", {static_cast<py::ssize_t>(domain_min.size())});
            const auto w = batch_array(mass, "mass", {}, x.shape(0));
            if (domain_max.size() != domain_min.size())
                throw py::value_error("domain_max: expected as many coordinates as domain_min");
            std::vector<double> xs(x.data(), x.data() + x.size()), ms(w.data(), w.data() + w.size());
            const int d = static_cast<int>(domain_min.size());
            GridField g;
            {
                py::gil_scoped_release release;
                g = rasterize_mass(d, xs, ms, domain_min.data(), domain_max.data(), dx);
            }
            return to_numpy(g);
        },
        py::arg("positions"), py::arg("mass"), py::arg("domain_min"), py::arg("domain_max"), py::arg("dx"),
        R"doc(Nodal mass (kg) of particles (positions (n, d) m, mass (n,) kg) with the
quadratic B-spline on the grid of nodes domain_min + i dx: an array of shape
(nodes_x, nodes_y[, nodes_z]), index [i, j(, k)].)doc");

    m.def(
        "compare_runs",
        [](const py::object& dir_a, const py::object& dir_b, double dx) {
            const RunComparison c = compare_directories(
                dir_a, dir_b, [&](const std::string& a, const std::string& b) { return compare_runs(a, b, dx); });
            py::dict d;
            const std::pair<const char*, double FrameIou::*> fields[] = {
                {"time", &FrameIou::time},         {"soft", &FrameIou::soft},
                {"binary", &FrameIou::binary},     {"plasticinelab", &FrameIou::plasticinelab},
                {"soft_coarse", &FrameIou::soft_coarse}, {"spread_a", &FrameIou::spread_a},
                {"spread_b", &FrameIou::spread_b}, {"height_a", &FrameIou::height_a},
                {"height_b", &FrameIou::height_b}};
            add_frame_columns(d, c.frames, fields);
            d["only_a"] = c.only_a;
            d["only_b"] = c.only_b;
            d["clamped_a"] = c.clamped_a;
            d["clamped_b"] = c.clamped_b;
            d["dx"] = c.dx;
            return d;
        },
        py::arg("dir_a"), py::arg("dir_b"), py::arg("dx") = 0.0,
        R"doc(Compare two `pnet simulate` output directories frame by frame (what `pnet compare`
computes): a dict of arrays over the frames both hold - frame, time (s), soft,
binary and plasticinelab IoU, soft_coarse (soft IoU of the mass at 4 dx),
spread_a / spread_b and height_a / height_b (deposit shape of each run, m) - plus only_a / only_b (frames in one run only),
clamped_a / clamped_b (particle positions at the domain's edge) and dx, the
grid spacing used (dx = 0: DIR_A's). FileNotFoundError for a missing
directory, ValueError for runs that cannot be compared (naming the file and field).)doc");

    m.def(
        "compare_meshes",
        [](const py::object& dir_a, const py::object& dir_b) {
            const MeshComparison c = compare_directories(
                dir_a, dir_b, [](const std::string& a, const std::string& b) { return compare_meshes(pair_runs(a, b)); });
            py::dict d;
            const std::pair<const char*, double FrameMeshError::*> fields[] = {
                {"time", &FrameMeshError::time},         {"mean", &FrameMeshError::mean},
                {"max", &FrameMeshError::max},           {"mean_pct", &FrameMeshError::mean_pct},
                {"max_pct", &FrameMeshError::max_pct}};
            add_frame_columns(d, c.frames, fields);
            py::array_t<std::int64_t> penetrations(static_cast<py::ssize_t>(c.frames.size()));
            for (std::size_t k = 0; k < c.frames.size(); ++k) penetrations.mutable_data()[k] = c.frames[k].penetrations;
            d["penetrations"] = penetrations;
            d["nodes"] = c.nodes;
            d["size"] = c.size;
            return d;
        },
        py::arg("dir_a"), py::arg("dir_b"),
        R"doc(Compare the meshes of two `pnet simulate` output directories of FEM or coupled runs frame by
frame (what `pnet compare` writes to nodal.csv): a dict of arrays over the frames both hold - frame,
time (s), mean and max nodal distance of the body (m) and both in % of its size, penetrations (a coupled
run B's particles inside its body; -1 for FEM) - plus nodes (the body's) and size (m).
FileNotFoundError for a missing directory, ValueError for runs that cannot be compared.)doc");

    m.def(
        "inside_count",
        [](const py::object& points, const py::object& nodes, const py::object& facets) {
            const py::array probe = py::array::ensure(nodes);
            if (!probe || probe.ndim() != 2 || (probe.shape(1) != 2 && probe.shape(1) != 3))
                throw py::value_error("nodes: expected a float64 array of shape (n, 2) or (n, 3)");
            const py::ssize_t d = probe.shape(1);
            const auto x = batch_array(nodes, "nodes", {d});
            const auto p = batch_array(points, "points", {d});
            const auto f = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(facets);
            if (!f || f.ndim() != 2 || f.shape(1) != d)
                throw py::value_error("facets: expected an integer array of shape (k, " + std::to_string(d) + ")");
            const std::int64_t n = x.shape(0);
            for (py::ssize_t k = 0; k < f.size(); ++k)
                if (f.data()[k] < 0 || f.data()[k] >= n)
                    throw py::value_error("facets: node index " + std::to_string(f.data()[k]) + " outside [0, " +
                                          std::to_string(n) + ")");
            auto count = [&](auto dim_tag) {
                constexpr int dim = decltype(dim_tag)::value;
                std::vector<Vec<dim>> nodes_v(static_cast<std::size_t>(n));
                for (std::int64_t i = 0; i < n; ++i)
                    for (int a = 0; a < dim; ++a) nodes_v[i][a] = x.data()[i * dim + a];
                std::vector<std::array<int, dim>> facets_v(static_cast<std::size_t>(f.shape(0)));
                for (py::ssize_t k = 0; k < f.shape(0); ++k)
                    for (int a = 0; a < dim; ++a) facets_v[k][a] = static_cast<int>(f.data()[k * dim + a]);
                std::vector<Vec<dim>> points_v(static_cast<std::size_t>(p.shape(0)));
                for (py::ssize_t i = 0; i < p.shape(0); ++i)
                    for (int a = 0; a < dim; ++a) points_v[i][a] = p.data()[i * dim + a];
                py::gil_scoped_release release;
                return count_inside<dim>(points_v, nodes_v, facets_v);
            };
            return d == 2 ? count(std::integral_constant<int, 2>{}) : count(std::integral_constant<int, 3>{});
        },
        py::arg("points"), py::arg("nodes"), py::arg("facets"),
        R"doc(How many of the points (n, d) lie inside the body bounded by the closed boundary `facets`
(k, d) node indices into nodes (m, d) - edges in 2D, triangles in 3D - or on it: the simulator's own
test (2D: crossing number with an exact collinearity test; 3D: generalized winding number), the one
that finds particles inside a mesh in a coupled run.)doc");

    m.def(
        "read_particle_frame",
        [](const py::object& path) {
            const PlyParticles p = read_frame(path, [](const std::string& f) { return read_particles_ply(f); });
            py::dict d = frame_dict(p);
            d["mass"] = py::array_t<double>(static_cast<py::ssize_t>(p.mass.size()), p.mass.data());
            return d;
        },
        py::arg("path"),
        R"doc(A particle frame (frame_NNNNN.ply) as `pnet simulate` writes it, read by the simulator's
own reader: a dict of dim, position and velocity (n, dim), mass and hardening (n,) and run_id.
FileNotFoundError for a missing file, ValueError naming the file and the problem for anything
else than such a frame.)doc");

    m.def(
        "read_mesh_frame",
        [](const py::object& path) {
            const PlyMesh p = read_frame(path, [](const std::string& f) { return read_mesh_ply(f); });
            py::dict d = frame_dict(p);
            const py::ssize_t m = static_cast<py::ssize_t>(p.triangles.size() / 3);
            py::array_t<std::int64_t> triangles({m, py::ssize_t{3}});
            std::copy(p.triangles.begin(), p.triangles.end(), triangles.mutable_data());
            d["triangles"] = triangles;
            return d;
        },
        py::arg("path"),
        R"doc(A FEM mesh frame (frame_NNNNN.ply, or frame_NNNNN_mesh.ply of a coupled run): a dict of dim,
position and velocity (n, dim) of every node, triangles (m, 3) int64 (2D: the elements; 3D: the
boundary triangles), hardening (m,) of each triangle's element, and run_id. Errors as
read_particle_frame.)doc");
}

}  // namespace pnet::bindings
