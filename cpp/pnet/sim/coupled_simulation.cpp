#include "pnet/sim/coupled_simulation.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>

#include "pnet/contact/adaptive_stiffness.hpp"
#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/io/atomic_file.hpp"
#include "pnet/io/checkpoint_arrays.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/frame_files.hpp"
#include "pnet/solver/method_energy.hpp"

namespace pnet {

namespace {

constexpr double kKappaReferenceDt = 1e-3;  // s: the implicit MPM step of docs/scenes.md

}  // namespace

template <int dim>
std::unique_ptr<Contact<dim>> make_particle_contact(const Scene& scene, const FemSystem<dim>& fem,
                                                    const Particles<dim>& particles) {
    // dhat at most half a cell; kappa IPC's lower bound for the average particle mass at the implicit MPM step,
    // unless the scene gives them.
    const double dhat = scene.contact.particle_dhat > 0.0 ? scene.contact.particle_dhat : 0.5 * scene.dx;
    double kappa = scene.contact.particle_kappa;
    if (!(kappa > 0.0)) {
        double mass = 0.0;
        for (double m : particles.mass) mass += m;
        const double diagonal = (scene.domain_max - scene.domain_min).norm();
        kappa = initial_barrier_stiffness(diagonal, dhat, mass / particles.size(), kKappaReferenceDt,
                                          Eigen::VectorXd::Zero(dim), Eigen::VectorXd::Zero(dim))
                    .kappa;
    }
    return std::make_unique<Contact<dim>>(fem.mesh.boundary, std::vector<Vec<dim>>{}, dhat, kappa,
                                          ContactPoints{static_cast<int>(fem.mesh.nodes()), true});
}

template std::unique_ptr<Contact<2>> make_particle_contact<2>(const Scene&, const FemSystem<2>&, const Particles<2>&);
template std::unique_ptr<Contact<3>> make_particle_contact<3>(const Scene&, const FemSystem<3>&, const Particles<3>&);

template <int dim>
CoupledSimulation<dim>::CoupledSimulation(const Scene& scene, const IntegratorSettings& settings)
    : SimulationBase(scene, settings),
      mpm_(make_mpm_system<dim>(scene)),
      particles_(sample_particles<dim>(scene)),
      fem_(make_fem_system<dim>(scene)) {
    const FemSystem<dim>& s = fem_.system;
    for (char fixed : s.fixed_node)
        if (fixed) throw SceneError(scene.file + ": meshes: kinematic meshes are not supported beside particles");

    // The meshes' own contact (ground, between meshes), as a FEM run has it.
    fem_contact_ = make_fem_contact<dim>(scene, fem_);
    const CouplingFriction friction{scene.contact.friction, scene.contact.friction_eps_v};

    coupling_ = make_particle_contact<dim>(scene, s, particles_);
    const std::string inside = first_inside<dim>(particles_.x, s.mesh.x, s.mesh.boundary, "particle");
    if (!inside.empty())
        throw SceneError(scene.file + ": objects and meshes overlap at the start: " + inside +
                         " (particles are numbered in object order)");

    state_ = FemState<dim>::at_rest(s);
    for (std::size_t k = 0; k < scene.meshes.size(); ++k)
        for (int i = fem_.first_node[k]; i < fem_.first_node[k + 1]; ++i)
            state_.v[i] = scene.meshes[k].velocity.template head<dim>();

    if (settings.method() == Method::Explicit) {
        explicit_ = std::make_unique<CoupledExplicitIntegrator<dim>>(mpm_, s, fem_contact_.get(), *coupling_, friction);
        explicit_->mpm().reset(particles_);
        dt_ = settings.dt;
    } else {
        if (!(settings.dt > 0.0))
            throw std::invalid_argument("dt must be > 0 for the implicit integrator " + settings.name +
                                        " (the CFL step is explicit's)");
        dt_ = settings.dt;
        const Method method = settings.method();
        if (!integrator_info(method).particles || !integrator_info(method).meshes)
            throw std::invalid_argument("the " + settings.name +
                                        " integrator is not for particles beside meshes "
                                        "(expected explicit, plasticitynet, return_map or lagged)");
        // settings.models: objects first, then meshes; the meshes are elastic.
        std::vector<std::string> where;
        for (const SceneObject& object : scene.objects) where.push_back(scene.file + ": " + object.json_path);
        MethodEnergy<dim> made =
            make_method_energy<dim>(settings.method(), {settings.implicit, mpm_.materials, settings.models, where});
        std::unique_ptr<ParticleEnergy<dim>> energy = std::move(made.energy);
        std::vector<const LearnedReturnMap<dim>*> return_maps = std::move(made.return_maps);
        implicit_ = std::make_unique<CoupledImplicitIntegrator<dim>>(
            mpm_, s, method, settings.implicit, settings.mpm, settings.coupling, std::move(energy),
            std::move(return_maps), fem_contact_.get(), *coupling_, friction);
    }
}

template <int dim>
const std::vector<Vec<dim>>& CoupledSimulation<dim>::contact_positions() const {
    CoupledVertices<dim>::join(state_.x, particles_.x, contact_x_);
    return contact_x_;
}

template <int dim>
StepRecord CoupledSimulation<dim>::step() {
    const bool limit = dt_ > 0.0 && implicit_;
    const double limited = limit ? advection_time_step(mpm_, particles_, dt_, settings_.mpm.advection_cfl) : 0.0;
    const double dt = clip_to_frame(limit       ? limited
                                    : dt_ > 0.0 ? dt_
                                                : explicit_->cfl_time_step(particles_, settings_.cfl));
    StepRecord s =
        implicit_ ? implicit_->step(particles_, state_, dt, steps_) : explicit_->step(particles_, state_, dt, steps_);
    s.advection_capped = limit && limited < dt_;
    const std::vector<Vec<dim>>& x = contact_positions();
    s.contact_pairs = coupling_->active_pairs(x);
    s.min_distance = coupling_->min_distance(x);
    count_step(dt);
    return s;
}

template <int dim>
FrameStats CoupledSimulation<dim>::advance_frame(const std::function<void()>& after_step) {
    return advance_one_frame(
        [&] { return step(); },
        [&](FrameStats& stats) {
            const std::string inside = first_inside<dim>(particles_.x, state_.x, mesh().boundary, "particle");
            if (!inside.empty()) throw SimulationError("frame " + std::to_string(frame_) + ": " + inside);
            const std::string pair = fem_contact_->first_intersection(state_.x);
            if (!pair.empty())
                throw SimulationError("frame " + std::to_string(frame_) + ": the meshes intersect: " + pair);
            for (std::size_t p = 0; p < particles_.size(); ++p)
                add_point_mass<dim>(stats, particles_.mass[p], particles_.x[p], particles_.v[p], mpm_.gravity);
            const FemSystem<dim>& s = fem_.system;
            for (std::size_t i = 0; i < s.mesh.nodes(); ++i)
                add_point_mass<dim>(stats, s.rest.node_mass[i], state_.x[i], state_.v[i], s.gravity);
        },
        after_step);
}

namespace {

// PNETCPL2 adds the implicit grid's Newton start prediction at the end (CoupledImplicitIntegrator::
// predictor); a PNETCPL1 file loads without one (the next step starts at v*).
constexpr char kMagic[8] = {'P', 'N', 'E', 'T', 'C', 'P', 'L', '2'};
constexpr char kMagicWithoutPrediction[8] = {'P', 'N', 'E', 'T', 'C', 'P', 'L', '1'};

}  // namespace

template <int dim>
void CoupledSimulation<dim>::save_checkpoint(const std::string& path) const {
    write_sealed_checkpoint(path, [&](std::ostream& out) {
        const std::vector<Mat<dim>> stress = explicit_ ? explicit_->mpm().checkpoint_state() : std::vector<Mat<dim>>{};
        write_checkpoint_preamble(
            out, kMagic,
            {static_cast<std::int64_t>(particles_.size()), static_cast<std::int64_t>(state_.x.size()),
             static_cast<std::int64_t>(state_.hardening.size()), static_cast<std::int64_t>(stress.size()), frame_,
             steps_},
            settings_.name);
        write_array(out, particles_.x);
        write_array(out, particles_.v);
        write_array(out, particles_.C);
        write_array(out, particles_.F_elastic);
        write_array(out, particles_.hardening);
        write_array(out, stress);
        write_array(out, state_.x);
        write_array(out, state_.v);
        write_array(out, state_.plastic_inverse);
        write_array(out, state_.hardening);
        write_sized_array(out, implicit_ ? implicit_->predictor().state() : std::vector<Mat<dim>>{});
    });
}

template <int dim>
void CoupledSimulation<dim>::load_checkpoint(const std::string& path) {
    std::istringstream in = read_sealed_checkpoint(path);
    std::vector<std::int64_t> header(6);
    double time = 0.0;
    const bool with_prediction = read_checkpoint_preamble(in, path, {kMagic, kMagicWithoutPrediction},
                                                          "MPM-FEM coupling", header, time, settings_.name) == 0;
    const std::size_t n = particles_.size();
    const std::int64_t stress_expected = explicit_ ? static_cast<std::int64_t>(n) : 0;
    if (header[0] != static_cast<std::int64_t>(n) || header[1] != static_cast<std::int64_t>(state_.x.size()) ||
        header[2] != static_cast<std::int64_t>(state_.hardening.size()) || header[3] != stress_expected ||
        header[4] < 0 || header[5] < 0)
        throw std::invalid_argument(path + ": holds " + std::to_string(header[0]) + " particles and " +
                                    std::to_string(header[1]) + " nodes, the scene has " + std::to_string(n) + " and " +
                                    std::to_string(state_.x.size()) + " (or a corrupt header)");
    Particles<dim> p = particles_;
    read_array(in, p.x, n, path);
    read_array(in, p.v, n, path);
    read_array(in, p.C, n, path);
    read_array(in, p.F_elastic, n, path);
    read_array(in, p.hardening, n, path);
    std::vector<Mat<dim>> stress;
    read_array(in, stress, static_cast<std::size_t>(header[3]), path);
    FemState<dim> s;
    read_array(in, s.x, state_.x.size(), path);
    read_array(in, s.v, state_.v.size(), path);
    read_array(in, s.plastic_inverse, state_.plastic_inverse.size(), path);
    read_array(in, s.hardening, state_.hardening.size(), path);
    StepPredictor<dim> prediction;
    if (with_prediction) {
        const std::int64_t storage = Grid<dim>::storage_size(mpm_.cells);
        std::vector<Mat<dim>> entries;
        read_sized_array(in, entries, storage, path, "the Newton start's prediction");
        prediction.restore(entries, storage, path);
    }
    in.peek();
    if (!in.eof()) throw std::invalid_argument(path + ": longer than its header says (corrupt checkpoint)");
    restore_clock(path, header[4], header[5], time);
    particles_ = p;
    state_ = std::move(s);
    if (explicit_) explicit_->mpm().restore_checkpoint_state(std::move(stress));
    if (implicit_) implicit_->predictor() = std::move(prediction);
}

template <int dim>
nlohmann::json CoupledSimulation<dim>::describe() const {
    return {{"dx", mpm_.dx},
            {"particles", particles_.size()},
            {"nodes", mesh().nodes()},
            {"elements", mesh().elements.size()},
            {"particle_dhat", coupling_->dhat()},
            {"particle_kappa", coupling_->kappa()},
            {"step", dt_}};
}

template <int dim>
void CoupledSimulation<dim>::write_frame(const FrameFiles& files) const {
    write_coupled_frame(files, particles_, state_, mesh(), frame(), time());
}

template <int dim>
nlohmann::json CoupledSimulation<dim>::contact_state() const {
    const std::vector<Vec<dim>>& x = contact_positions();
    return {{"dhat", coupling_->dhat()},
            {"kappa", coupling_->kappa()},
            {"min_distance", coupling_->min_distance(x)},
            {"active_pairs", coupling_->active_pairs(x)},
            {"penetrations", penetrations()}};
}

template <int dim>
std::string CoupledSimulation<dim>::size_text() const {
    return std::to_string(particles_.size()) + " particles";
}

template class CoupledSimulation<2>;
template class CoupledSimulation<3>;

}  // namespace pnet
