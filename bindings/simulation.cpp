// A running simulation (MPM particles or FEM meshes): stepping with the GIL
// released, Ctrl-C between steps, particle arrays as numpy views (meshes: node
// and element arrays as copies), per-step statistics, checkpoints.
#include <omp.h>

#include <chrono>
#include <memory>
#include <type_traits>
#include <utility>

#include "common.hpp"
#include "pnet/metrics/iou.hpp"
#include "pnet/nn/torchscript.hpp"
#include "pnet/sim/threads.hpp"
#include "pnet/sim/scene_models.hpp"
#include "pnet/sim/fem_simulation.hpp"  // WithMesh
#include "pnet/sim/run.hpp"

namespace pnet::bindings {

namespace {

/// Thrown from between two steps when Python has a pending signal (Ctrl-C).
struct Interrupted {};

py::dict to_dict(const StepRecord& s) {
    py::dict d;
    for_each_step_field([&](const StepField& field, auto member) {
        if (field.key) d[field.key] = s.*member;
    });
    return d;
}

py::dict to_dict(const FrameStats& f) {
    py::dict d;
    for_each_frame_field([&](const FrameField& field, auto get) {
        if (field.key) d[field.key] = get(f);
    });
    return d;
}

[[noreturn]] void no_particles() {
    throw py::value_error("a FEM scene (meshes) has no particles: see nodes, node_velocities, elements");
}

[[noreturn]] void no_mesh() { throw py::value_error("an MPM scene (particles) has no mesh: see positions, velocities"); }

/// One column of the step history as a numpy array: float64, int64 or bool.
template <typename T, typename Part>
py::array column(const std::vector<StepRecord>& steps, T Part::*member) {
    using Out = std::conditional_t<std::is_same_v<T, bool>, bool,
                                   std::conditional_t<std::is_integral_v<T>, std::int64_t, double>>;
    py::array_t<Out> a(static_cast<py::ssize_t>(steps.size()));
    Out* out = a.mutable_data();
    for (std::size_t k = 0; k < steps.size(); ++k) out[k] = static_cast<Out>(steps[k].*member);
    return std::move(a);
}

/// A read-only numpy view of `count` records of `record_bytes` each, whose
/// element [p, i, j] sits at data + p record_bytes + i stride_i + j stride_j;
/// it keeps `owner` (the Python simulation) alive.
template <typename T>
py::array view(const T* data, std::vector<py::ssize_t> shape, std::vector<py::ssize_t> strides,
               const py::object& owner) {
    py::array a(py::dtype::of<T>(), std::move(shape), std::move(strides), data, owner);
    a.attr("setflags")(py::arg("write") = false);
    return a;
}

class PySimulation {
public:
    PySimulation(const py::object& scene, const py::object& integrator, const py::object& dt, const py::object& cfl,
                 const py::object& solver, bool trust_models)
        : scene_(scene_of(scene)) {
        IntegratorSettings settings =
            integrator_settings(scene_, integrator.is_none() ? std::string() : to_text(integrator, "integrator"));
        if (!dt.is_none()) settings.dt = to_number(dt, "dt");
        if (!cfl.is_none()) settings.cfl = to_number(cfl, "cfl");
        if (!solver.is_none()) {
            nlohmann::json options = settings.options_json();
            const nlohmann::json given = to_json(solver, "solver");
            if (!given.is_object()) throw py::value_error("solver: expected a dict of implicit solver options");
            for (const auto& [key, value] : given.items()) {
                if (!options.contains(key))
                    throw py::value_error("solver: unknown option \"" + key + "\" (known: " + key_list(options) + ")");
                options[key] = value;
            }
            settings.read_options(options, "solver");
        }
        load_scene_models(scene_, trust_models, settings);
        py::gil_scoped_release release;
        sim_ = make_simulation(scene_, settings);
    }

    const Scene& scene() const { return scene_; }
    int dim() const { return scene_.dim; }
    SimulationBase& sim() { return *sim_; }
    const SimulationBase& sim() const { return *sim_; }
    /// fn(the particles) of a method with material points (MPM, coupling), in its dimension;
    /// ValueError for a scene of meshes alone.
    template <typename Fn>
    decltype(auto) with_particles(Fn&& fn) const {
        if (const auto* p = dynamic_cast<const WithParticles<2>*>(sim_.get())) return fn(*p);
        if (const auto* p = dynamic_cast<const WithParticles<3>*>(sim_.get())) return fn(*p);
        no_particles();
    }
    /// fn(the meshes' state) of a method with meshes (FEM, coupling); ValueError for an MPM scene.
    template <typename Fn>
    decltype(auto) with_mesh(Fn&& fn) const {
        if (const auto* f = dynamic_cast<const WithMesh<2>*>(sim_.get())) return fn(*f);
        if (const auto* f = dynamic_cast<const WithMesh<3>*>(sim_.get())) return fn(*f);
        no_mesh();
    }

    py::dict step() {
        StepRecord s;
        {
            py::gil_scoped_release release;
            s = sim().step();
        }
        history_.push_back(s);
        return to_dict(s);
    }

    py::list advance(const py::object& self, int frames, const py::object& callback) {
        if (frames < 0) throw py::value_error("frames: expected a number >= 0, got " + std::to_string(frames));
        py::list out;
        for (int f = 0; f < frames; ++f) {
            FrameStats stats;
            bool interrupted = false;
            try {
                py::gil_scoped_release release;
                // Signals are checked (which needs the GIL) at most every 20 ms, so
                // that other Python threads get the GIL while short steps run.
                auto last_check = std::chrono::steady_clock::now();
                stats = sim().advance_frame([&] {
                    const auto now = std::chrono::steady_clock::now();
                    if (now - last_check < std::chrono::milliseconds(20)) return;
                    last_check = now;
                    py::gil_scoped_acquire acquire;
                    if (PyErr_CheckSignals() != 0) throw Interrupted{};
                });
            } catch (const Interrupted&) {
                interrupted = true;
            } catch (...) {
                record_frame_steps();
                throw;
            }
            record_frame_steps();
            if (interrupted) throw py::error_already_set();  // KeyboardInterrupt, between two steps
            py::dict d = to_dict(stats);
            out.append(d);
            if (!callback.is_none()) {
                const py::object keep_going = callback(self, d);
                if (!keep_going.is_none() && !keep_going.cast<bool>()) break;
            }
        }
        return out;
    }

    py::dict step_stats() const {
        py::dict d;
        for_each_step_field([&](const StepField& field, auto member) {
            if (field.key) d[field.key] = column(history_, member);
        });
        return d;
    }

    /// run_to_folder(): the run's folder as `pnet simulate` writes it. The steps it takes join the
    /// step history.
    void run(const py::object& out, const py::object& frames, int checkpoint_every, bool resume, bool overwrite,
             bool vtu, const std::string& color) {
        RunOptions o;
        o.out = path_string(out);
        o.frames = frames.is_none() ? -1 : py::cast<int>(frames);
        if (!frames.is_none() && o.frames < 1) throw py::value_error("frames: expected at least 1");
        if (checkpoint_every < 0) throw py::value_error("checkpoint_every: expected >= 0 (0: no checkpoints)");
        o.checkpoint_every = checkpoint_every;
        o.resume = resume;
        o.overwrite = overwrite;
        o.vtu = vtu;
        o.color = color;
        const IntegratorSettings settings = sim().settings();
        auto last_check = std::chrono::steady_clock::now();
        o.after_step = [&] {  // as advance(): Ctrl-C between two steps, checked at most every 20 ms
            const auto now = std::chrono::steady_clock::now();
            if (now - last_check < std::chrono::milliseconds(20)) return;
            last_check = now;
            py::gil_scoped_acquire acquire;
            if (PyErr_CheckSignals() != 0) throw Interrupted{};
        };
        if (resume) history_.clear();  // the state becomes the checkpoint's
        try {
            py::gil_scoped_release release;
            run_to_folder(*sim_, scene_, settings, o);
        } catch (const Interrupted&) {
            throw py::error_already_set();  // KeyboardInterrupt
        }
    }

    void save_checkpoint(const py::object& path) const {
        const std::string file = path_string(path);
        py::gil_scoped_release release;
        sim().save_checkpoint(file);
    }

    void load_checkpoint(const py::object& path) {
        const std::string file = path_string(path);
        {
            py::gil_scoped_release release;
            sim().load_checkpoint(file);
        }
        history_.clear();  // the statistics of the steps since construction no longer describe this state
    }

    py::array grid_mass() const {
        GridField g = with_particles([&](const auto& with) {
            constexpr int d = std::decay_t<decltype(with)>::kDim;
            const auto& p = with.particles();
            std::vector<double> x(p.size() * d);
            for (std::size_t k = 0; k < p.size(); ++k)
                for (int a = 0; a < d; ++a) x[k * d + a] = p.x[k][a];
            py::gil_scoped_release release;
            return rasterize_mass(d, x, p.mass, scene_.domain_min.data(), scene_.domain_max.data(), scene_.dx);
        });
        return to_numpy(g);
    }

private:
    static std::string key_list(const nlohmann::json& options) {
        std::string s;
        for (const auto& [key, value] : options.items()) s += (s.empty() ? "" : ", ") + key;
        return s;
    }

    void record_frame_steps() {
        const auto& steps = sim().last_frame_steps();
        history_.insert(history_.end(), steps.begin(), steps.end());
    }

    Scene scene_;
    AnySimulation sim_;
    std::vector<StepRecord> history_;  // every step since construction or the last load_checkpoint()
};

/// A live read-only view of a particle array (see the Simulation docstring).
template <typename Member>
py::array particle_view(const py::object& self, Member member) {
    const PySimulation& s = self.cast<const PySimulation&>();
    return s.with_particles([&](const auto& with) -> py::array {
        constexpr int d = std::decay_t<decltype(with)>::kDim;
        const auto& array = member(with.particles());
        using Element = typename std::decay_t<decltype(array)>::value_type;
        const py::ssize_t n = static_cast<py::ssize_t>(array.size());
        const py::ssize_t record = sizeof(Element);
        if constexpr (std::is_same_v<Element, Vec<d>>) {
            return view(array.data()->data(), {n, d}, {record, sizeof(double)}, self);
        } else if constexpr (std::is_same_v<Element, Mat<d>>) {
            // Eigen matrices are column-major: (i, j) sits at (i + j d) doubles.
            return view(array.data()->data(), {n, d, d}, {record, sizeof(double), d * sizeof(double)}, self);
        } else {
            return view(array.data(), {n}, {record}, self);
        }
    });
}

/// Rows of node indices (elements, boundary facets) as an (m, k) int64 array.
template <std::size_t k>
py::array_t<std::int64_t> index_rows(const std::vector<std::array<int, k>>& v) {
    py::array_t<std::int64_t> a({static_cast<py::ssize_t>(v.size()), static_cast<py::ssize_t>(k)});
    std::int64_t* out = a.mutable_data();
    for (std::size_t e = 0; e < v.size(); ++e)
        for (std::size_t c = 0; c < k; ++c) out[k * e + c] = v[e][c];
    return a;
}

}  // namespace

void define_simulation(py::module_& m) {
    py::class_<PySimulation>(m, "Simulation", R"doc(A simulation of a scene with one of the integrators: MPM
(particles) or, for a scene of meshes, FEM with IPC contact (is_fem); particles and meshes
together are an MPM-FEM coupling (is_coupled: both the particle views and the mesh arrays).

    sim = pns.Simulation("scenes/snowball_2d.json", integrator="plasticitynet", dt=1e-3)
    sim.advance(10, callback=lambda sim, frame: print(frame["frame"], frame["wall_s"]))

Stepping releases the GIL; Ctrl-C (KeyboardInterrupt) stops advance() between
two steps with a consistent state. A failed step raises SimulationError.

Particle arrays (positions, velocities, F_elastic, hardening, mass,
rest_volume, object) are zero-copy, read-only numpy views of the simulator's
storage: they stay valid as long as the array (which keeps the simulation
alive) and always show the current state, so take .copy() to keep a
snapshot. grid_mass() and step_stats() return new arrays.)doc")
        .def(py::init<const py::object&, const py::object&, const py::object&, const py::object&, const py::object&,
                      bool>(),
             py::arg("scene"), py::arg("integrator") = py::none(), py::arg("dt") = py::none(),
             py::arg("cfl") = py::none(), py::arg("solver") = py::none(), py::arg("trust_models") = false,
             R"doc(scene: a Scene, a scene file path, or a scene dict (relative model paths
resolved against the working directory).
integrator: one of plasticitynet_sim.integrators() (default: the scene's):
"plasticitynet" (the learned energy on every Newton iteration), "return_map" (the
classical solver: the return mapping's stress and consistent tangent, no model),
"lagged", "explicit" or (FEM) "analytic". Another integrator than the scene's
starts from its own default dt (explicit: the CFL step; implicit: 1e-3 s for MPM,
1e-2 s for FEM).
dt: time step, s (0: the CFL step); cfl: the CFL number of that step.
solver: implicit solver options overriding the scene's integrator block, e.g.
{"newton_tolerance": 1e-3, "max_fixed_point_iterations": 2, "regularizer_weight": 1}.
trust_models: load model files that no MANIFEST pins (they are code to LibTorch).
Every model the scene names is loaded and checked when the integrator reads models
(plasticitynet); the others open none.)doc")
        .def_property_readonly("scene", &PySimulation::scene)
        .def_property_readonly("dim", &PySimulation::dim)
        .def_property_readonly("integrator", [](const PySimulation& s) { return s.sim().settings().name; },
                               "The integrator's name (plasticitynet_sim.integrators()).")
        .def_property_readonly("dt", [](const PySimulation& s) { return s.sim().settings().dt; },
                               "Time step, s (0: the CFL step).")
        .def_property_readonly("solver", [](const PySimulation& s) {
            return to_python(s.sim().settings().options_json());
        }, "The implicit solver options in use.")
        .def_property_readonly("frame", [](const PySimulation& s) { return s.sim().frame(); },
                               "Frames completed.")
        .def_property_readonly("time", [](const PySimulation& s) { return s.sim().time(); }, "s.")
        .def_property_readonly("total_steps", [](const PySimulation& s) { return s.sim().total_steps(); })
        .def_property_readonly("num_particles", [](const PySimulation& s) {
            const auto* with_2d = dynamic_cast<const WithParticles<2>*>(&s.sim());
            const auto* with_3d = dynamic_cast<const WithParticles<3>*>(&s.sim());
            return with_2d ? with_2d->particles().size() : with_3d ? with_3d->particles().size() : std::size_t{0};
        }, "Particles (0 in a FEM scene).")
        .def_property_readonly("is_fem", [](const PySimulation& s) { return s.scene().has_meshes(); },
                               "Whether the scene has FEM meshes (node and element arrays); with particles beside "
                               "them it is an MPM-FEM coupling (is_coupled).")
        .def_property_readonly("nodes", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) { return rows<std::decay_t<decltype(f)>::kDim>(f.state().x); });
        }, "FEM: (n, d) float64 node positions, m (a new array).")
        .def_property_readonly("node_velocities", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) { return rows<std::decay_t<decltype(f)>::kDim>(f.state().v); });
        }, "FEM: (n, d) float64 node velocities, m/s (a new array).")
        .def_property_readonly("rest_nodes", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) { return rows<std::decay_t<decltype(f)>::kDim>(f.mesh().x); });
        }, "FEM: (n, d) float64 rest positions, m.")
        .def_property_readonly("elements", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) { return index_rows(f.mesh().elements); });
        }, "FEM: (m, d + 1) int64 node indices of the triangles (2D) or tetrahedra (3D), positively oriented at rest.")
        .def_property_readonly("boundary_faces", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) { return index_rows(f.mesh().boundary); });
        }, "FEM: (k, d) int64 node indices of the boundary edges (2D) or triangles (3D), outward oriented.")
        .def_property_readonly("element_hardening", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) {
                const auto& h = f.state().hardening;
                return py::array_t<double>(static_cast<py::ssize_t>(h.size()), h.data());
            });
        }, "FEM: (m,) float64 hardening state per element (von Mises h).")
        .def_property_readonly("mesh_first_node", [](const PySimulation& s) {
            return s.with_mesh([](const auto& f) { return f.scene_system().first_node; });
        }, "FEM: the first node of each scene mesh, and the node count at the end.")
        .def_property_readonly("contact", [](const PySimulation& s) {
            const nlohmann::json state = s.sim().contact_state();
            if (state.empty()) no_mesh();
            return to_python(state);
        }, "FEM: barrier dhat (m), kappa (J/m^4), the bounding-box diagonal (m), and now the smallest pair "
           "distance (m) and the pairs within dhat. MPM-FEM coupling: the particle / mesh barrier's dhat and "
           "kappa, the smallest particle-edge distance, the pairs within dhat and the particles inside a mesh "
           "(penetrations, always 0).")
        .def_property_readonly("is_coupled", [](const PySimulation& s) { return s.scene().has_meshes() && s.scene().has_particles(); },
                               "Whether the scene couples particles (MPM) and meshes (FEM): both array sets are there.")
        .def("step", &PySimulation::step,
             "One time step (shortened to land on the end of the frame); returns its statistics as a dict.")
        .def("advance",
             [](const py::object& self, int frames, const py::object& callback) {
                 return self.cast<PySimulation&>().advance(self, frames, callback);
             },
             py::arg("frames") = 1, py::arg("callback") = py::none(),
             R"doc(Advance by whole frames; returns one dict per frame (frame, time, steps,
dt_min, dt_max, wall_s, kinetic_energy and potential_energy in J, Newton / CG /
line-search / fixed-point totals, max_residual in m/s, converged, unconverged_steps,
clamped, hardening_clamped: the most particles in a step whose hardening input
was clamped to the model's trained range).

callback(sim, frame_stats) runs after every frame; returning False stops early.
Ctrl-C raises KeyboardInterrupt between two steps (the state stays consistent;
a later advance finishes the frame).)doc")
        .def("step_stats", &PySimulation::step_stats,
             R"doc(Per-step statistics of every step since construction (or the last
load_checkpoint) as a dict of arrays: dt, wall_s, p2g_s, solve_s, g2p_s, energy_s,
cg_s (seconds), newton_iterations, cg_iterations, line_search_steps,
fixed_point_iterations, fixed_point_change, initial_residual and residual (m/s),
energy (J), converged, line_search_failed, fixed_point_converged, clamped, hardening_clamped,
max_grid_speed (m/s; in implicit MPM steps, grid nodes that only the far corner of a particle's
stencil reaches hold almost no mass and can move far faster than any particle, up to 3000 m/s on
snowball_2d at 1e-3 s, while a particle sees them only through weights of about 1e-6 or less).)doc")
        .def("run", &PySimulation::run, py::arg("out"), py::arg("frames") = py::none(),
             py::arg("checkpoint_every") = 10, py::arg("resume") = false, py::arg("overwrite") = false,
             py::arg("vtu") = false, py::arg("color") = "speed",
             R"doc(Run to `frames` (default: the scene's frame count) writing the folder `out` exactly
as `pnet simulate` does: frame_NNNNN.ply and .png (and .vtu with vtu=True), run.json,
stats.csv, steps.csv and checkpoint.bin every checkpoint_every frames, with a progress
line on stderr. A folder holding another run is refused (ValueError naming it) unless
overwrite=True, which first removes that run's files; resume=True continues the run in
`out` from its checkpoint (one written by pnet simulate or by run()). The steps taken are
in steps.csv (step_stats() does not gather them). A failed step raises SimulationError
naming the frames that are complete; Ctrl-C raises KeyboardInterrupt between two steps.)doc")
        .def("save_checkpoint", &PySimulation::save_checkpoint, py::arg("path"),
             "Write the whole state to a file atomically (what is there is replaced only when the write succeeds).")
        .def("load_checkpoint", &PySimulation::load_checkpoint, py::arg("path"),
             "Restore a state saved by save_checkpoint for the same scene and integrator (ValueError otherwise, "
             "FileNotFoundError for a missing file). Resuming gives the same results as an uninterrupted run.")
        .def("grid_mass", &PySimulation::grid_mass,
             "Nodal mass of the particles on the scene's grid (quadratic B-spline), kg: a new array of shape "
             "(nodes_x, nodes_y[, nodes_z]), index [i, j(, k)] = node at domain_min + (i, j, k) dx.")
        .def_property_readonly("positions", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.x; }); }, "(n, d) float64, m.")
        .def_property_readonly("velocities", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.v; }); }, "(n, d) float64, m/s.")
        .def_property_readonly("F_elastic", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.F_elastic; }); }, "(n, d, d) float64: the elastic deformation gradients.")
        .def_property_readonly("affine", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.C; }); }, "(n, d, d) float64, 1/s: the APIC affine velocity matrices.")
        .def_property_readonly("hardening", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.hardening; }); }, "(n,) float64: Cam-Clay a, von Mises h; 0 for sand.")
        .def_property_readonly("mass", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.mass; }); }, "(n,) float64, kg.")
        .def_property_readonly("rest_volume", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.rest_volume; }); }, "(n,) float64, m^d.")
        .def_property_readonly("object", [](const py::object& self) { return particle_view(self, [](const auto& p) -> const auto& { return p.object; }); }, "(n,) int32: the scene object of each particle.")
        .def("__repr__", [](const PySimulation& s) {
            return "<plasticitynet_sim.Simulation " + s.scene().name + ": " + s.sim().settings().name + ", frame " +
                   std::to_string(s.sim().frame()) + ", " + s.sim().size_text() + ">";
        });

    // Every core the process may use by default, set before any model loads (LibTorch would
    // otherwise impose its own, smaller, intra-op count on OpenMP; sim/threads.hpp).
    use_threads();
    m.def("integrators", [] {
        py::list out;
        for (const IntegratorInfo& info : integrators()) {
            py::dict d;
            d["name"] = info.name;
            d["solves"] = info.solves;
            d["implicit"] = info.implicit;
            d["reads_models"] = info.reads_models;
            d["particles"] = info.particles;
            d["meshes"] = info.meshes;
            d["options"] = info.options;
            out.append(d);
        }
        return out;
    }, "The integrators (solver/integrators.hpp): a list of dicts with name, what a step solves, whether it is "
       "implicit, reads the objects' models, runs particles and meshes, and the options that apply.");
    m.def("set_threads", [](int n) {
        if (n < 1) throw py::value_error("threads: expected a number >= 1, got " + std::to_string(n));
        use_threads(n);
    }, py::arg("n"), "Number of OpenMP threads the simulator uses (all cores by default). Results do not depend on it.");
    m.def("threads", [] { return thread_count(); }, "Number of OpenMP threads the simulator uses.");
    m.def("available_cores", [] { return available_cores(); },
          "The cores this process may use (OMP_NUM_THREADS where set, else its CPU affinity): the default thread "
          "count.");
}

}  // namespace pnet::bindings
