#include "pnet/sim/mpm_simulation.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/checkpoint_arrays.hpp"
#include "pnet/mpm/step_predictor.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/frame_files.hpp"
#include "pnet/solver/method_energy.hpp"

namespace pnet {

template <int dim>
MpmSystem<dim> make_mpm_system(const Scene& scene) {
    if (scene.dim != dim)
        throw std::invalid_argument(scene.file + ": a " + std::to_string(scene.dim) + "D scene, not " +
                                    std::to_string(dim) + "D");
    if (!scene.has_particles())
        throw std::invalid_argument(scene.file + ": a FEM scene (meshes, no particles): run it with FemSimulation");
    MpmSystem<dim> s;
    for (int a = 0; a < dim; ++a) {
        s.origin[a] = scene.domain_min[a];
        s.gravity[a] = scene.gravity[a];
        s.cells[a] = scene.cells(a);
    }
    s.dx = scene.dx;
    s.boundary.slip_walls = scene.boundary.slip_walls;
    s.boundary.sticky_floor_cells = scene.boundary.sticky_floor_cells;
    s.boundary.floor_friction = scene.boundary.floor_friction;
    s.flip_relaxation_time = scene.flip_relaxation_time;
    for (const SceneObject& object : scene.objects) {
        s.materials.emplace_back(object.material);
        s.density.push_back(object.material.density);
    }
    return s;
}

template <int dim>
Simulation<dim>::Simulation(const Scene& scene, double dt, double cfl)
    : Simulation(scene, [&] {
          IntegratorSettings s;
          s.dt = dt;
          s.cfl = cfl;
          return s;
      }()) {}

template <int dim>
Simulation<dim>::Simulation(const Scene& scene, const IntegratorSettings& settings)
    : SimulationBase(scene, settings), system_(make_mpm_system<dim>(scene)), particles_(sample_particles<dim>(scene)) {
    const Method method = settings.method();
    if (method == Method::Explicit) {
        integrator_ = std::make_unique<ExplicitIntegrator<dim>>(system_);
    } else {
        if (!integrator_info(method).particles)
            throw std::invalid_argument("the " + settings.name + " integrator is not for particles (expected " +
                                        integrator_names(true, false) + ")");
        std::vector<std::string> where;
        for (const SceneObject& object : scene.objects) where.push_back(scene.file + ": " + object.json_path);
        MethodEnergy<dim> energy = make_method_energy<dim>(settings.method(), {settings.implicit, system_.materials, settings.models, where});
        integrator_ = std::make_unique<ImplicitIntegrator<dim>>(system_, method, settings.implicit, settings.mpm,
                                                                std::move(energy.energy), energy.return_maps);
    }
    integrator_->reset(particles_);
}

template <int dim>
StepRecord Simulation<dim>::step() {
    const bool implicit = settings_.dt > 0.0 && settings_.method() != Method::Explicit;
    const double limited =
        implicit ? advection_time_step(system_, particles_, settings_.dt, settings_.mpm.advection_cfl) : 0.0;
    const double dt = clip_to_frame(implicit ? limited : settings_.dt > 0.0 ? settings_.dt
                                                                            : cfl_time_step(system_, particles_, settings_.cfl));
    StepRecord s = integrator_->step(particles_, dt, steps_);
    s.advection_capped = implicit && limited < settings_.dt;
    count_step(dt);
    return s;
}

template <int dim>
FrameStats Simulation<dim>::advance_frame(const std::function<void()>& after_step) {
    return advance_one_frame(
        [&] { return step(); },
        [&](FrameStats& stats) {
            for (std::size_t p = 0; p < particles_.size(); ++p)
                add_point_mass<dim>(stats, particles_.mass[p], particles_.x[p], particles_.v[p], system_.gravity);
        },
        after_step);
}

namespace {

// PNETCKP3 adds the Newton start's prediction after the integrator's state (MpmIntegrator::
// checkpoint_prediction); a PNETCKP2 file loads without one (the next step starts at v*).
constexpr char kMagic[8] = {'P', 'N', 'E', 'T', 'C', 'K', 'P', '3'};
constexpr char kMagicWithoutPrediction[8] = {'P', 'N', 'E', 'T', 'C', 'K', 'P', '2'};

}  // namespace

template <int dim>
void Simulation<dim>::save_checkpoint(const std::string& path) const {
    write_sealed_checkpoint(path, [&](std::ostream& out) {
        write_checkpoint_preamble(out, kMagic, {dim, static_cast<std::int64_t>(particles_.size()), frame_, steps_},
                                  integrator_->name());
        const std::vector<Mat<dim>> state = integrator_->checkpoint_state();
        const std::int64_t state_size = static_cast<std::int64_t>(state.size());
        out.write(reinterpret_cast<const char*>(&state_size), sizeof state_size);
        write_array(out, particles_.x);
        write_array(out, particles_.v);
        write_array(out, particles_.C);
        write_array(out, particles_.F_elastic);
        write_array(out, particles_.hardening);
        write_array(out, particles_.mass);
        write_array(out, particles_.rest_volume);
        write_array(out, particles_.object);
        write_array(out, state);
        write_sized_array(out, integrator_->checkpoint_prediction());
    });
}

template <int dim>
void Simulation<dim>::load_checkpoint(const std::string& path) {
    std::istringstream in = read_sealed_checkpoint(path);
    std::vector<std::int64_t> header(4);
    double time = 0.0;
    const bool with_prediction = read_checkpoint_preamble(in, path, {kMagic, kMagicWithoutPrediction}, "", header, time,
                                                          integrator_->name()) == 0;
    std::int64_t state_size = 0;
    in.read(reinterpret_cast<char*>(&state_size), sizeof state_size);
    if (!in) throw std::invalid_argument(path + ": not a PlasticityNet checkpoint");
    if (header[0] != dim) throw std::invalid_argument(path + ": a " + std::to_string(header[0]) + "D checkpoint");
    // The integrator's state: explicit's n stresses, or the implicit BDF2 history's 3 n + 1 matrices.
    if (state_size < 0 || state_size > 3 * header[1] + 1) throw std::invalid_argument(path + ": corrupt checkpoint header");
    const std::size_t n = static_cast<std::size_t>(header[1]);
    if (n != particles_.size())
        throw std::invalid_argument(path + ": holds " + std::to_string(n) + " particles, the scene has " +
                                    std::to_string(particles_.size()));
    Particles<dim> p;
    read_array(in, p.x, n, path);
    read_array(in, p.v, n, path);
    read_array(in, p.C, n, path);
    read_array(in, p.F_elastic, n, path);
    read_array(in, p.hardening, n, path);
    read_array(in, p.mass, n, path);
    read_array(in, p.rest_volume, n, path);
    read_array(in, p.object, n, path);
    std::vector<Mat<dim>> state;
    read_array(in, state, static_cast<std::size_t>(state_size), path);
    // A state that could not have come from a run (a bug upstream, or an edited file whose seal was
    // remade) is refused here, naming the particle, rather than blowing up steps later.
    const int objects = static_cast<int>(system_.materials.size());
    for (std::size_t i = 0; i < n; ++i) {
        auto bad = [&](const char* what) {
            throw std::invalid_argument(path + ": particle " + std::to_string(i) + "'s " + what +
                                        " (corrupt checkpoint state)");
        };
        if (!p.x[i].allFinite()) bad("position is not finite");
        if (!p.v[i].allFinite()) bad("velocity is not finite");
        if (!p.C[i].allFinite()) bad("affine velocity C is not finite");
        if (!p.F_elastic[i].allFinite() || !(p.F_elastic[i].determinant() > 0.0))
            bad("deformation gradient is not finite or not invertible");
        if (!std::isfinite(p.hardening[i])) bad("hardening is not finite");
        if (!(p.mass[i] > 0.0) || !std::isfinite(p.mass[i])) bad("mass is not a positive number");
        if (!(p.rest_volume[i] > 0.0) || !std::isfinite(p.rest_volume[i])) bad("rest volume is not a positive number");
        if (p.object[i] < 0 || p.object[i] >= objects) bad("object index is out of range");
    }
    for (const Mat<dim>& m : state)
        if (!m.allFinite()) throw std::invalid_argument(path + ": the integrator's state is not finite (corrupt checkpoint)");
    std::vector<Mat<dim>> prediction;
    if (with_prediction) {  // refused before anything is restored
        const std::int64_t storage = Grid<dim>::storage_size(system_.cells);
        read_sized_array(in, prediction, storage, path, "the Newton start's prediction");
        StepPredictor<dim>().restore(prediction, storage, path);
    }
    restore_clock(path, header[2], header[3], time);
    particles_ = p;  // copy assignment keeps each array's storage (Python views of it stay valid)
    integrator_->restore_checkpoint_state(std::move(state));
    integrator_->restore_checkpoint_prediction(prediction);
}

template MpmSystem<2> make_mpm_system<2>(const Scene&);
template MpmSystem<3> make_mpm_system<3>(const Scene&);
template <int dim>
nlohmann::json Simulation<dim>::describe() const {
    return {{"dx", system_.dx}, {"particles", particles_.size()}};
}

template <int dim>
void Simulation<dim>::write_frame(const FrameFiles& files) const {
    write_particle_frame(files, particles_, frame(), time());
}

template <int dim>
std::string Simulation<dim>::size_text() const {
    return std::to_string(particles_.size()) + " particles";
}

template class Simulation<2>;
template class Simulation<3>;

}  // namespace pnet
