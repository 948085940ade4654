// Gradients of simulated outcomes (issue 57; docs/adjoint.md): FemRollout, MpmRollout and CoupledRollout, the
// adjoints of implicit FEM, MPM and MPM-FEM coupled rollouts (cpp/pnet/fem/fem_adjoint.hpp,
// cpp/pnet/mpm/mpm_adjoint.hpp, cpp/pnet/coupling/coupled_adjoint.hpp) as numpy calls.
// plasticitynet.adjoint wraps it as a torch.autograd.Function.
#include <memory>

#include "common.hpp"
#include "pnet/coupling/coupled_adjoint.hpp"
#include "pnet/fem/fem_adjoint.hpp"
#include "pnet/mpm/mpm_adjoint.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "pnet/sim/fem_simulation.hpp"
#include "pnet/sim/mpm_simulation.hpp"

namespace pnet::bindings {

namespace {

template <int dim>
std::vector<Vec<dim>> to_points(const py::handle& obj, const std::string& name, py::ssize_t n) {
    const py::array_t<double, py::array::c_style> a = batch_array(obj, name, {dim}, n);
    std::vector<Vec<dim>> p(static_cast<std::size_t>(n));
    for (py::ssize_t i = 0; i < n; ++i)
        for (int c = 0; c < dim; ++c) p[i][c] = a.data()[i * dim + c];
    return p;
}

/// The states a forward pass keeps: all (None) or those listed, each in 0..steps (ValueError otherwise).
std::vector<char> wanted_states(const py::object& states, int steps) {
    std::vector<char> wanted(static_cast<std::size_t>(steps) + 1, states.is_none());
    if (!states.is_none())
        for (const py::handle k : states) {
            const long state = py::cast<long>(k);
            if (state < 0 || state > steps)
                throw py::value_error("states: " + std::to_string(state) + " is not a state of a " +
                                      std::to_string(steps) + "-step rollout (0.." + std::to_string(steps) + ")");
            wanted[static_cast<std::size_t>(state)] = 1;
        }
    return wanted;
}

/// The kept states of a forward pass as {"x": {k: array}, "v": {k: array}}.
template <int dim>
py::dict kept_states(const std::vector<int>& index, const std::vector<std::vector<Vec<dim>>>& xs,
                     const std::vector<std::vector<Vec<dim>>>& vs) {
    py::dict x, v;
    for (std::size_t j = 0; j < index.size(); ++j) {
        x[py::int_(index[j])] = rows<dim>(xs[j]);
        v[py::int_(index[j])] = rows<dim>(vs[j]);
    }
    py::dict d;
    d["x"] = x;
    d["v"] = v;
    return d;
}

/// A loss's cotangents {state: (count, dim) array} into out[state] (None: none), each state in 0..states - 1.
template <int dim>
void read_cotangents(const py::object& obj, const std::string& name, std::size_t states, py::ssize_t count,
                     std::vector<std::vector<Vec<dim>>>& out) {
    out.assign(states, {});
    if (obj.is_none()) return;
    const py::dict d = py::cast<py::dict>(obj);
    for (const auto& [key, value] : d) {
        const long k = py::cast<long>(key);
        if (k < 0 || k >= static_cast<long>(states))
            throw py::value_error(name + "[" + std::to_string(k) + "]: the rollout kept states 0.." +
                                  std::to_string(states - 1) + " (the start and each step's end)");
        out[static_cast<std::size_t>(k)] = to_points<dim>(value, name + "[" + std::to_string(k) + "]", count);
    }
}

/// A forward pass's steps, dt and checkpoint spacing, checked (ValueError naming the argument).
void check_forward(int steps, double dt, int checkpoint_every) {
    if (steps < 0) throw py::value_error("steps: expected an integer >= 0");
    if (!(dt > 0.0)) throw py::value_error("dt: expected a positive number (s)");
    if (checkpoint_every < 0) throw py::value_error("checkpoint_every: expected an integer >= 0");
}

/// The forward steps' solver of a particle rollout: Newton to newton_tolerance (m/s) on the velocity residual
/// alone, at most 1000 iterations.
ImplicitOptions particle_rollout_options(double newton_tolerance) {
    if (!(newton_tolerance > 0.0)) throw py::value_error("newton_tolerance: expected a positive number");
    ImplicitOptions options;
    options.newton_tolerance = newton_tolerance;
    options.newton_acceleration_tolerance = 0.0;
    options.max_newton_iterations = 1000;
    return options;
}

/// {field: dL/dp} of the material fields asked for.
py::dict fields_dict(const std::vector<std::string>& fields, const std::vector<double>& values) {
    py::dict d;
    for (std::size_t f = 0; f < fields.size() && f < values.size(); ++f) d[py::str(fields[f])] = values[f];
    return d;
}

/// d["hardening"]: dL/dh0 per element or particle, and d["initial_hardening"]: their sum (every one's start
/// hardening moved together).
void add_hardening(const std::vector<double>& hardening, py::dict& d) {
    py::array_t<double> h(static_cast<py::ssize_t>(hardening.size()));
    double total = 0.0;
    for (std::size_t k = 0; k < hardening.size(); ++k) total += h.mutable_data()[k] = hardening[k];
    d["hardening"] = h;
    d["initial_hardening"] = total;
}

/// An MPM rollout's gradient into d: "x0", "v0", "C0", "F0", the hardening's, "youngs_modulus", "friction_angle",
/// "xi", "beta" and "fields" ({material field: dL/dp} of the fields asked for).
template <int dim>
void add_particle_gradient(const MpmRolloutGradient<dim>& g, py::dict& d, const std::vector<std::string>& fields = {}) {
    d["fields"] = fields_dict(fields, g.fields);
    d["x0"] = rows<dim>(g.x);
    d["v0"] = rows<dim>(g.v);
    d["C0"] = from_matrices<dim>(g.C);
    d["F0"] = from_matrices<dim>(g.F);
    d["youngs_modulus"] = g.youngs_modulus;
    d["friction_angle"] = g.friction_angle;
    d["xi"] = g.xi;
    d["beta"] = g.beta;
    add_hardening(g.hardening, d);
}

struct Rollout {
    virtual ~Rollout() = default;
    virtual py::dict start() const = 0;
    virtual py::dict forward(int steps, double dt, const py::object& x0, const py::object& v0, int checkpoint_every,
                             const py::object& states) = 0;
    virtual py::dict backward(const py::object& dL_dx, const py::object& dL_dv) const = 0;
    virtual double youngs_modulus() const = 0;
    virtual int nodes() const = 0;
    virtual std::size_t peak_states() const = 0;
};

template <int dim>
struct RolloutOf final : Rollout {
    Scene scene;
    FemSceneSystem<dim> fem;
    std::unique_ptr<ContactPotential<dim>> contact;
    FemAdjoint<dim> adjoint;
    FemState<dim> initial;

    std::vector<std::string> fields;

    RolloutOf(Scene s, const ImplicitOptions& options, Method method, std::vector<std::string> material_fields)
        : scene(std::move(s)),
          fem(make_fem_system<dim>(scene)),
          contact(make_fem_contact<dim>(scene, fem)),
          adjoint(fem.system, contact.get(), options, method),
          initial(FemState<dim>::at_rest(fem.system)),
          fields(std::move(material_fields)) {
        adjoint.set_parameter_fields(fields);
        if (scene.contact.friction > 0.0) adjoint.set_friction(scene.contact.friction, scene.contact.friction_eps_v);
        for (std::size_t k = 0; k < scene.meshes.size(); ++k)
            for (int i = fem.first_node[k]; i < fem.first_node[k + 1]; ++i)
                initial.v[i] = scene.meshes[k].velocity.template head<dim>();
    }
    int nodes() const override { return static_cast<int>(fem.system.mesh.nodes()); }
    std::size_t peak_states() const override { return adjoint.peak_states(); }
    double youngs_modulus() const override { return fem.system.materials[0].description().elastic.E; }
    py::dict start() const override {
        py::dict d;
        d["x"] = rows<dim>(initial.x);
        d["v"] = rows<dim>(initial.v);
        return d;
    }
    py::dict forward(int steps, double dt, const py::object& x0, const py::object& v0, int checkpoint_every,
                     const py::object& states) override {
        if (steps < 0) throw py::value_error("steps: expected an integer >= 0");
        if (checkpoint_every < 0) throw py::value_error("checkpoint_every: expected an integer >= 0");
        const std::vector<char> wanted = wanted_states(states, steps);
        FemState<dim> s = initial;
        if (!x0.is_none()) s.x = to_points<dim>(x0, "x0", nodes());
        if (!v0.is_none()) s.v = to_points<dim>(v0, "v0", nodes());
        const std::string inside = contact->first_intersection(s.x);
        if (!inside.empty()) throw py::value_error("x0: the start intersects: " + inside);
        std::vector<int> index;
        std::vector<std::vector<Vec<dim>>> xs, vs;
        {
            py::gil_scoped_release release;
            adjoint.forward(s, dt, steps, checkpoint_every, [&](int k, const FemState<dim>& state) {
                if (!wanted[static_cast<std::size_t>(k)]) return;
                index.push_back(k);
                xs.push_back(state.x);
                vs.push_back(state.v);
            });
        }
        return kept_states<dim>(index, xs, vs);
    }
    py::dict backward(const py::object& dL_dx, const py::object& dL_dv) const override {
        if (adjoint.steps() < 0) throw py::value_error("backward: run forward() first");
        const std::size_t states = static_cast<std::size_t>(adjoint.steps()) + 1;
        std::vector<std::vector<Vec<dim>>> xs, vs;
        read_cotangents<dim>(dL_dx, "dL_dx", states, nodes(), xs);
        read_cotangents<dim>(dL_dv, "dL_dv", states, nodes(), vs);
        FemRolloutGradient<dim> g;
        {
            py::gil_scoped_release release;
            g = adjoint.backward(xs, vs);
        }
        py::dict d;
        d["x0"] = rows<dim>(g.x);
        d["v0"] = rows<dim>(g.v);
        d["youngs_modulus"] = g.youngs_modulus;
        add_hardening(g.hardening, d);
        d["fields"] = fields_dict(fields, g.fields);
        return d;
    }
};

struct MpmRolloutBase {
    virtual ~MpmRolloutBase() = default;
    virtual py::dict start() const = 0;
    virtual py::dict forward(int steps, double dt, const py::object& v0, const py::object& states,
                             int checkpoint_every) = 0;
    virtual py::dict backward(const py::object& dL_dx, const py::object& dL_dv) const = 0;
    virtual int particles() const = 0;
    virtual std::size_t peak_states() const = 0;
    virtual int unconverged_steps() const = 0;
};

template <int dim>
struct MpmRolloutOf final : MpmRolloutBase {
    Scene scene;
    MpmSystem<dim> system;
    Particles<dim> initial;
    MpmAdjoint<dim> adjoint;

    std::vector<std::string> fields;

    MpmRolloutOf(Scene s, const ImplicitOptions& options, Method method, std::vector<std::string> material_fields)
        : scene(std::move(s)),
          system(make_mpm_system<dim>(scene)),
          initial(sample_particles<dim>(scene)),
          adjoint(system, options, MpmOptions{}, method),
          fields(std::move(material_fields)) {
        adjoint.set_parameter_fields(fields);
    }
    int particles() const override { return static_cast<int>(initial.size()); }
    std::size_t peak_states() const override { return adjoint.peak_states(); }
    int unconverged_steps() const override { return adjoint.unconverged_steps(); }
    py::dict start() const override {
        py::dict d;
        d["x"] = rows<dim>(initial.x);
        d["v"] = rows<dim>(initial.v);
        py::array_t<double> mass(static_cast<py::ssize_t>(initial.size()));
        std::copy(initial.mass.begin(), initial.mass.end(), mass.mutable_data());
        d["mass"] = mass;
        return d;
    }
    py::dict forward(int steps, double dt, const py::object& v0, const py::object& states,
                     int checkpoint_every) override {
        check_forward(steps, dt, checkpoint_every);
        const std::vector<char> wanted = wanted_states(states, steps);
        Particles<dim> s = initial;
        if (!v0.is_none()) s.v = to_points<dim>(v0, "v0", particles());
        std::vector<int> index;
        std::vector<std::vector<Vec<dim>>> xs, vs;
        {
            py::gil_scoped_release release;
            adjoint.forward(
                s, dt, steps,
                [&](int k, const Particles<dim>& state) {
                    if (!wanted[static_cast<std::size_t>(k)]) return;
                    index.push_back(k);
                    xs.push_back(state.x);
                    vs.push_back(state.v);
                },
                checkpoint_every);
        }
        return kept_states<dim>(index, xs, vs);
    }
    py::dict backward(const py::object& dL_dx, const py::object& dL_dv) const override {
        if (adjoint.steps() < 0) throw py::value_error("backward: run forward() first");
        const std::size_t states = static_cast<std::size_t>(adjoint.steps()) + 1;
        std::vector<std::vector<Vec<dim>>> xs, vs;
        read_cotangents<dim>(dL_dx, "dL_dx", states, particles(), xs);
        read_cotangents<dim>(dL_dv, "dL_dv", states, particles(), vs);
        MpmRolloutGradient<dim> g;
        {
            py::gil_scoped_release release;
            g = adjoint.backward(xs, vs);
        }
        py::dict d;
        add_particle_gradient<dim>(g, d, fields);
        return d;
    }
};

struct CoupledRolloutBase {
    virtual ~CoupledRolloutBase() = default;
    virtual py::dict start() const = 0;
    virtual py::dict forward(int steps, double dt, const py::object& v0, const py::object& mesh_v0,
                             const py::object& states, int checkpoint_every) = 0;
    virtual py::dict backward(const py::object& dL_dx, const py::object& dL_dv, const py::object& dL_dmesh_x,
                              const py::object& dL_dmesh_v) const = 0;
    virtual int particles() const = 0;
    virtual int nodes() const = 0;
    virtual std::size_t peak_states() const = 0;
    virtual int unconverged_steps() const = 0;
};

template <int dim>
struct CoupledRolloutOf final : CoupledRolloutBase {
    Scene scene;
    MpmSystem<dim> mpm;
    FemSceneSystem<dim> fem;
    CoupledState<dim> initial;
    std::unique_ptr<ContactPotential<dim>> mesh_contact;
    std::unique_ptr<Contact<dim>> contact;
    CoupledAdjoint<dim> adjoint;

    std::vector<std::string> fields;

    CoupledRolloutOf(Scene s, const ImplicitOptions& options, Method method, std::vector<std::string> material_fields)
        : scene(std::move(s)),
          mpm(make_mpm_system<dim>(scene)),
          fem(make_fem_system<dim>(scene)),
          initial{sample_particles<dim>(scene), FemState<dim>::at_rest(fem.system)},
          mesh_contact(make_fem_contact<dim>(scene, fem)),
          contact(make_particle_contact<dim>(scene, fem.system, initial.particles)),
          adjoint(mpm, fem.system, mesh_contact.get(), *contact, options, MpmOptions{}, coupling_options(scene),
                  method),
          fields(std::move(material_fields)) {
        adjoint.set_parameter_fields(fields);
        if (scene.contact.friction > 0.0) adjoint.set_friction(scene.contact.friction, scene.contact.friction_eps_v);
        for (std::size_t k = 0; k < scene.meshes.size(); ++k)
            for (int i = fem.first_node[k]; i < fem.first_node[k + 1]; ++i)
                initial.mesh.v[i] = scene.meshes[k].velocity.template head<dim>();
    }
    /// The assembled coupled solve (the forward steps solved as exactly as asked).
    static CouplingOptions coupling_options(const Scene&) {
        CouplingOptions o;
        o.coupled_solver = "cholesky";
        return o;
    }
    int particles() const override { return static_cast<int>(initial.particles.size()); }
    int nodes() const override { return static_cast<int>(fem.system.mesh.nodes()); }
    std::size_t peak_states() const override { return adjoint.peak_states(); }
    int unconverged_steps() const override { return adjoint.unconverged_steps(); }
    py::dict start() const override {
        py::dict d;
        d["x"] = rows<dim>(initial.particles.x);
        d["v"] = rows<dim>(initial.particles.v);
        d["mesh_x"] = rows<dim>(initial.mesh.x);
        d["mesh_v"] = rows<dim>(initial.mesh.v);
        return d;
    }
    py::dict forward(int steps, double dt, const py::object& v0, const py::object& mesh_v0, const py::object& states,
                     int checkpoint_every) override {
        check_forward(steps, dt, checkpoint_every);
        const std::vector<char> wanted = wanted_states(states, steps);
        CoupledState<dim> s = initial;
        if (!v0.is_none()) s.particles.v = to_points<dim>(v0, "v0", particles());
        if (!mesh_v0.is_none()) s.mesh.v = to_points<dim>(mesh_v0, "mesh_v0", nodes());
        std::vector<int> index;
        std::vector<std::vector<Vec<dim>>> xs, vs, mesh_xs, mesh_vs;
        {
            py::gil_scoped_release release;
            adjoint.forward(
                s, dt, steps,
                [&](int k, const CoupledState<dim>& state) {
                    if (!wanted[static_cast<std::size_t>(k)]) return;
                    index.push_back(k);
                    xs.push_back(state.particles.x);
                    vs.push_back(state.particles.v);
                    mesh_xs.push_back(state.mesh.x);
                    mesh_vs.push_back(state.mesh.v);
                },
                checkpoint_every);
        }
        py::dict d = kept_states<dim>(index, xs, vs), mesh = kept_states<dim>(index, mesh_xs, mesh_vs);
        d["mesh_x"] = mesh["x"];
        d["mesh_v"] = mesh["v"];
        return d;
    }
    py::dict backward(const py::object& dL_dx, const py::object& dL_dv, const py::object& dL_dmesh_x,
                      const py::object& dL_dmesh_v) const override {
        if (adjoint.steps() < 0) throw py::value_error("backward: run forward() first");
        const std::size_t states = static_cast<std::size_t>(adjoint.steps()) + 1;
        std::vector<std::vector<Vec<dim>>> xs, vs, mesh_xs, mesh_vs;
        read_cotangents<dim>(dL_dx, "dL_dx", states, particles(), xs);
        read_cotangents<dim>(dL_dv, "dL_dv", states, particles(), vs);
        read_cotangents<dim>(dL_dmesh_x, "dL_dmesh_x", states, nodes(), mesh_xs);
        read_cotangents<dim>(dL_dmesh_v, "dL_dmesh_v", states, nodes(), mesh_vs);
        CoupledRolloutGradient<dim> g;
        {
            py::gil_scoped_release release;
            g = adjoint.backward(xs, vs, mesh_xs, mesh_vs);
        }
        py::dict d;
        add_particle_gradient<dim>(g.particles, d, fields);
        d["mesh_x0"] = rows<dim>(g.node_x);
        d["mesh_v0"] = rows<dim>(g.node_v);
        d["mesh_youngs_modulus"] = g.mesh_youngs_modulus;
        return d;
    }
};

}  // namespace

void define_adjoint(py::module_& m) {
    py::class_<Rollout>(m, "FemRollout", R"doc(A rollout of an implicit FEM scene of elastic bodies and its adjoint.

FemRollout(scene, newton_tolerance=1e-10, integrator="lagged", time_integrator="backward_euler"; or
"bdf2", fields=[]): scene as a path, a dict or a Scene with
meshes of one material, elastic or von Mises with StVK-Hencky (the metal preset), no moving kinematic
nodes (ValueError naming the field otherwise); the scene's friction is lagged and held at its lagged
values in the gradient (docs/adjoint.md). Steps are the integrator's:
"lagged" (backward Euler on the elastic energy, then the return mapping) or "return_map" (the
return-mapped stress within the solve; plasticitynet converges to the same step), with the scene's IPC
contact, each solved to newton_tolerance (m/s), which sets how exact the gradient is.

forward(steps, dt, x0=None, v0=None, checkpoint_every=0, states=None) runs the rollout from the
scene's start (or x0, v0: (nodes, dim) arrays) and returns {"x": {k: array}, "v": {k: array}}, the
states k asked for (None: all; 0 is the start, k the end of step k), (nodes, dim) arrays. It keeps a
checkpoint every checkpoint_every steps (0: about sqrt(steps); 1: every state). backward(dL_dx,
dL_dv) takes dicts {state: (nodes, dim) array} of the loss's gradient with respect to those states
and returns {"x0", "v0": (nodes, dim) arrays, "youngs_modulus": float, "hardening": (elements,)
array, "initial_hardening": float}: dL/dx0, dL/dv0, dL/dE, dL/dh0 per element and summed (the
material's initial_hardening: von Mises' yield stress tau_Y = 2 mu h) and "fields": {field: dL/dp} of the material
fields asked for by fields=[...] ("elasticity.nu", "plasticity.hardening_coefficient"), by the adjoint of every step,
recomputing the steps between checkpoints (docs/adjoint.md). peak_states:
the most states held at once by the last forward and backward.)doc")
        .def(py::init([](const py::object& scene, double newton_tolerance, const std::string& integrator,
                         const std::string& time_integrator,
                         const std::vector<std::string>& fields) -> std::unique_ptr<Rollout> {
                 Scene s = scene_of(scene);
                 if (!s.has_meshes() || s.has_particles())
                     throw py::value_error(s.file + ": FemRollout takes a scene of meshes only");
                 if (!(newton_tolerance > 0.0)) throw py::value_error("newton_tolerance: expected a positive number");
                 ImplicitOptions options;
                 options.newton_tolerance = newton_tolerance;
                 options.max_newton_iterations = 1000;
                 if (time_integrator != "backward_euler" && time_integrator != "bdf2")
                     throw py::value_error("time_integrator: \"" + time_integrator +
                                           "\" (expected backward_euler or bdf2)");
                 options.time_integrator = time_integrator;
                 try {
                     const Method method = parse_integrator(integrator, "integrator");
                     if (s.dim == 2) return std::make_unique<RolloutOf<2>>(std::move(s), options, method, fields);
                     return std::make_unique<RolloutOf<3>>(std::move(s), options, method, fields);
                 } catch (const std::invalid_argument& e) {
                     throw py::value_error(std::string(e.what()));
                 }
             }),
             py::arg("scene"), py::arg("newton_tolerance") = 1e-10, py::arg("integrator") = "lagged",
             py::arg("time_integrator") = "backward_euler", py::arg("fields") = std::vector<std::string>{})
        .def_property_readonly("nodes", &Rollout::nodes)
        .def_property_readonly("youngs_modulus", &Rollout::youngs_modulus, "The material's E, Pa.")
        .def("start", &Rollout::start, "The scene's start: {\"x\", \"v\"}, (nodes, dim) arrays.")
        .def("forward", &Rollout::forward, py::arg("steps"), py::arg("dt"), py::arg("x0") = py::none(),
             py::arg("v0") = py::none(), py::arg("checkpoint_every") = 0, py::arg("states") = py::none())
        .def_property_readonly("peak_states", &Rollout::peak_states)
        .def("backward", &Rollout::backward, py::arg("dL_dx") = py::none(), py::arg("dL_dv") = py::none());

    py::class_<MpmRolloutBase>(m, "MpmRollout", R"doc(A rollout of an implicit MPM scene and its adjoint.

MpmRollout(scene, newton_tolerance=1e-10, integrator="lagged", fields=[]): scene as a path, a dict or a Scene with
particle objects of elastic, Drucker-Prager (sand), Cam-Clay (snow, its exact variant) or von Mises
(metal, StVK-Hencky) materials, APIC or AFLIP transfers, slip walls and a sticky or Coulomb floor (the
Coulomb floor under "return_map": its friction within the one solve); ValueError naming what otherwise. Steps are backward Euler at a fixed dt (the advection limit is not applied) by "lagged" (the
elastic solve, then the return mapping) or "return_map" (the return-mapped stress within the solve;
plasticitynet converges to its step), each solved to newton_tolerance (m/s), which sets how exact the
gradient is.

forward(steps, dt, v0=None, states=None, checkpoint_every=0) runs the rollout from the scene's particles
(v0: their start velocities instead, a (particles, dim) array) and returns {"x": {k: array}, "v": {k:
array}}, the states k asked for (None: all; 0 is the start, k the end of step k), keeping a checkpoint
every checkpoint_every steps (0: about sqrt(steps); 1: every state). backward(dL_dx, dL_dv) takes dicts {state: (particles, dim) array} of the loss's gradient with
respect to those states and returns {"x0", "v0": (particles, dim), "C0", "F0": (particles, dim, dim)
arrays, "hardening": (particles,) array, "youngs_modulus", "friction_angle", "xi", "beta",
"initial_hardening": floats}: dL/d of the start's positions, velocities, APIC matrices, F and hardening
(Cam-Clay's a, von Mises' h = tau_Y / (2 mu)), dL/dE (every material's E scaled together), dL/dphi (every
Drucker-Prager and Cam-Clay material's friction angle, per degree), dL/dxi and dL/dbeta (Cam-Clay's) and
dL/dh0 (every particle's start hardening together), and "fields": {field: dL/dp} for each material field asked
for by fields=[...] ("elasticity.nu", "plasticity.hardening_coefficient", any field of docs/physics.md's material
that has a number; every material with it moved together; by central differences of each particle's stress and
return mapping), by the adjoint of every step, recomputing the steps between
checkpoints (docs/adjoint.md). peak_states: the most states held at once by the last forward and
backward; unconverged_steps: the last forward's steps whose solve stopped short of newton_tolerance (the
gradient is then that of the path taken).)doc")
        .def(py::init([](const py::object& scene, double newton_tolerance, const std::string& integrator,
                         const std::vector<std::string>& fields) -> std::unique_ptr<MpmRolloutBase> {
                 Scene s = scene_of(scene);
                 if (!s.has_particles() || s.has_meshes())
                     throw py::value_error(s.file + ": MpmRollout takes a scene of particle objects only");
                 const ImplicitOptions options = particle_rollout_options(newton_tolerance);
                 try {
                     const Method method = parse_integrator(integrator, "integrator");
                     if (s.dim == 2) return std::make_unique<MpmRolloutOf<2>>(std::move(s), options, method, fields);
                     return std::make_unique<MpmRolloutOf<3>>(std::move(s), options, method, fields);
                 } catch (const std::invalid_argument& e) {
                     throw py::value_error(std::string(e.what()));
                 }
             }),
             py::arg("scene"), py::arg("newton_tolerance") = 1e-10, py::arg("integrator") = "lagged",
             py::arg("fields") = std::vector<std::string>{})
        .def_property_readonly("particles", &MpmRolloutBase::particles)
        .def("start", &MpmRolloutBase::start,
             "The scene's particles: {\"x\", \"v\"}, (particles, dim) arrays, and \"mass\", (particles,), kg (per "
             "metre of depth in 2D).")
        .def("forward", &MpmRolloutBase::forward, py::arg("steps"), py::arg("dt"), py::arg("v0") = py::none(),
             py::arg("states") = py::none(), py::arg("checkpoint_every") = 0)
        .def_property_readonly("peak_states", &MpmRolloutBase::peak_states)
        .def_property_readonly("unconverged_steps", &MpmRolloutBase::unconverged_steps)
        .def("backward", &MpmRolloutBase::backward, py::arg("dL_dx") = py::none(), py::arg("dL_dv") = py::none());

    py::class_<CoupledRolloutBase>(m, "CoupledRollout",
                                   R"doc(A rollout of an implicit MPM-FEM coupled scene and its adjoint.

CoupledRollout(scene, newton_tolerance=1e-10, integrator="lagged", fields=[]): scene as a path, a dict or a Scene with
particle objects (the materials MpmRollout takes) and elastic meshes of one material, without a Coulomb floor;
ValueError naming what otherwise. The scene's friction is lagged and held at its lagged values in the gradient
(exact for one step's start velocities and the moduli; docs/adjoint.md). Steps are the coupled integrator's
backward Euler at a fixed dt with the particle / mesh barrier, the particles' energy "lagged" (the elastic
solve, then the return mapping) or "return_map" (the return-mapped stress within the solve), each solved to
newton_tolerance (m/s) with the assembled coupled solve.

forward(steps, dt, v0=None, mesh_v0=None, states=None, checkpoint_every=0) runs the rollout from the scene's
particles and meshes (v0, mesh_v0: their start velocities instead, (particles, dim) and (nodes, dim) arrays)
and returns {"x", "v", "mesh_x", "mesh_v": {k: array}} for the states k asked for (None: all). backward(dL_dx,
dL_dv, dL_dmesh_x, dL_dmesh_v) takes dicts {state: array} of the loss's gradient with respect to those states
and returns MpmRollout's gradient of the particles' start and material ("x0", "v0", "C0", "F0", "hardening",
"youngs_modulus", "friction_angle", "xi", "beta", "initial_hardening", "fields": the particles' material fields
asked for) with "mesh_x0", "mesh_v0" ((nodes, dim))
and "mesh_youngs_modulus" (dL/dE of the mesh's material) (docs/adjoint.md). peak_states and unconverged_steps
as MpmRollout's.)doc")
        .def(py::init([](const py::object& scene, double newton_tolerance, const std::string& integrator,
                         const std::vector<std::string>& fields) -> std::unique_ptr<CoupledRolloutBase> {
                 Scene s = scene_of(scene);
                 if (!s.has_particles() || !s.has_meshes())
                     throw py::value_error(s.file + ": CoupledRollout takes a scene of particle objects and meshes");
                 const ImplicitOptions options = particle_rollout_options(newton_tolerance);
                 try {
                     const Method method = parse_integrator(integrator, "integrator");
                     if (s.dim == 2)
                         return std::make_unique<CoupledRolloutOf<2>>(std::move(s), options, method, fields);
                     return std::make_unique<CoupledRolloutOf<3>>(std::move(s), options, method, fields);
                 } catch (const std::invalid_argument& e) {
                     throw py::value_error(std::string(e.what()));
                 }
             }),
             py::arg("scene"), py::arg("newton_tolerance") = 1e-10, py::arg("integrator") = "lagged",
             py::arg("fields") = std::vector<std::string>{})
        .def_property_readonly("particles", &CoupledRolloutBase::particles)
        .def_property_readonly("nodes", &CoupledRolloutBase::nodes)
        .def("start", &CoupledRolloutBase::start,
             "The scene's start: {\"x\", \"v\"} (particles, dim) and {\"mesh_x\", \"mesh_v\"} (nodes, dim) arrays.")
        .def("forward", &CoupledRolloutBase::forward, py::arg("steps"), py::arg("dt"), py::arg("v0") = py::none(),
             py::arg("mesh_v0") = py::none(), py::arg("states") = py::none(), py::arg("checkpoint_every") = 0)
        .def_property_readonly("peak_states", &CoupledRolloutBase::peak_states)
        .def_property_readonly("unconverged_steps", &CoupledRolloutBase::unconverged_steps)
        .def("backward", &CoupledRolloutBase::backward, py::arg("dL_dx") = py::none(), py::arg("dL_dv") = py::none(),
             py::arg("dL_dmesh_x") = py::none(), py::arg("dL_dmesh_v") = py::none());
}

}  // namespace pnet::bindings
