#include "pnet/mpm/simulation.hpp"

#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/sha256.hpp"
#include "pnet/scene/sampler.hpp"

namespace pnet {

template <int dim>
MpmSystem<dim> make_mpm_system(const Scene& scene) {
    if (scene.dim != dim)
        throw std::invalid_argument(scene.file + ": a " + std::to_string(scene.dim) + "D scene, not " +
                                    std::to_string(dim) + "D");
    MpmSystem<dim> s;
    for (int a = 0; a < dim; ++a) {
        s.origin[a] = scene.domain_min[a];
        s.gravity[a] = scene.gravity[a];
        s.cells[a] = scene.cells(a);
    }
    s.dx = scene.dx;
    s.boundary.slip_walls = scene.boundary.slip_walls;
    s.boundary.sticky_floor_cells = scene.boundary.sticky_floor_cells;
    for (const SceneObject& object : scene.objects) {
        s.materials.emplace_back(object.material);
        s.density.push_back(object.material.density);
    }
    return s;
}

template <int dim>
Simulation<dim>::Simulation(const Scene& scene, double dt, double cfl)
    : scene_(scene), scene_digest_(sha256_hex(scene_to_json(scene).dump())), system_(make_mpm_system<dim>(scene)),
      particles_(sample_particles<dim>(scene)), dt_(dt), cfl_(cfl) {
    if (!(dt >= 0.0) || !std::isfinite(dt)) throw std::invalid_argument("dt must be >= 0 (0: the CFL step)");
    if (!(cfl > 0.0 && cfl <= 1.0)) throw std::invalid_argument("cfl must be in (0, 1]");
    integrator_ = std::make_unique<ExplicitIntegrator<dim>>(system_);
    integrator_->compute_stress(particles_);
}

template <int dim>
FrameStats Simulation<dim>::advance_frame() {
    const auto start = std::chrono::steady_clock::now();
    FrameStats stats;
    const double frame_end = (frame_ + 1) * scene_.frame_dt;
    stats.dt_min = 1e300;
    while (time_ < frame_end * (1.0 - 1e-12)) {
        double dt = dt_ > 0.0 ? dt_ : integrator_->stable_dt(particles_, cfl_);
        // Land exactly on the frame (within round-off), never overshoot it.
        if (time_ + dt > frame_end * (1.0 - 1e-12)) dt = frame_end - time_;
        const StepStats s = integrator_->step(particles_, dt, steps_);
        time_ += dt;
        ++steps_;
        ++stats.steps;
        stats.clamped += s.clamped;
        stats.dt_min = std::min(stats.dt_min, dt);
        stats.dt_max = std::max(stats.dt_max, dt);
    }
    time_ = frame_end;
    ++frame_;
    stats.frame = frame_;
    stats.time = time_;
    for (std::size_t p = 0; p < particles_.size(); ++p) {
        const double m = particles_.mass[p];
        stats.kinetic += 0.5 * m * particles_.v[p].squaredNorm();
        stats.potential -= m * system_.gravity.dot(particles_.x[p]);
        for (int a = 0; a < dim; ++a) stats.momentum[a] += m * particles_.v[p][a];
    }
    stats.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
}

namespace {

constexpr char kMagic[8] = {'P', 'N', 'E', 'T', 'C', 'K', 'P', '1'};

template <typename T>
void write_array(std::ostream& out, const std::vector<T>& a) {
    out.write(reinterpret_cast<const char*>(a.data()), static_cast<std::streamsize>(a.size() * sizeof(T)));
}

template <typename T>
void read_array(std::istream& in, std::vector<T>& a, std::size_t n, const std::string& path) {
    a.resize(n);
    in.read(reinterpret_cast<char*>(a.data()), static_cast<std::streamsize>(n * sizeof(T)));
    if (!in) throw std::invalid_argument(path + ": truncated checkpoint");
}

}  // namespace

template <int dim>
void Simulation<dim>::save_checkpoint(const std::string& path) const {
    write_file_atomically(path, [&](std::ostream& out) {
        out.write(kMagic, sizeof kMagic);
        const std::int64_t header[4] = {dim, static_cast<std::int64_t>(particles_.size()), frame_, steps_};
        out.write(reinterpret_cast<const char*>(header), sizeof header);
        out.write(reinterpret_cast<const char*>(&time_), sizeof time_);
        out.write(scene_digest_.data(), 64);
        write_array(out, particles_.x);
        write_array(out, particles_.v);
        write_array(out, particles_.C);
        write_array(out, particles_.F_elastic);
        write_array(out, particles_.hardening);
        write_array(out, particles_.mass);
        write_array(out, particles_.rest_volume);
        write_array(out, particles_.object);
        write_array(out, integrator_->cached_stress());
    });
}

template <int dim>
void Simulation<dim>::load_checkpoint(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::invalid_argument(path + ": cannot open the checkpoint");
    char magic[8];
    std::int64_t header[4];
    double time;
    std::string digest(64, '\0');
    in.read(magic, sizeof magic);
    in.read(reinterpret_cast<char*>(header), sizeof header);
    in.read(reinterpret_cast<char*>(&time), sizeof time);
    in.read(digest.data(), 64);
    if (!in || std::memcmp(magic, kMagic, sizeof kMagic) != 0)
        throw std::invalid_argument(path + ": not a PlasticityNet checkpoint");
    if (header[0] != dim) throw std::invalid_argument(path + ": a " + std::to_string(header[0]) + "D checkpoint");
    if (digest != scene_digest_)
        throw std::invalid_argument(path + ": written for a different scene (or a changed scene file)");
    const std::size_t n = static_cast<std::size_t>(header[1]);
    Particles<dim> p;
    read_array(in, p.x, n, path);
    read_array(in, p.v, n, path);
    read_array(in, p.C, n, path);
    read_array(in, p.F_elastic, n, path);
    read_array(in, p.hardening, n, path);
    read_array(in, p.mass, n, path);
    read_array(in, p.rest_volume, n, path);
    read_array(in, p.object, n, path);
    std::vector<Mat<dim>> stress;
    read_array(in, stress, n, path);
    particles_ = std::move(p);
    integrator_->set_cached_stress(std::move(stress));
    frame_ = static_cast<int>(header[2]);
    steps_ = header[3];
    time_ = time;
}

template MpmSystem<2> make_mpm_system<2>(const Scene&);
template MpmSystem<3> make_mpm_system<3>(const Scene&);
template class Simulation<2>;
template class Simulation<3>;

}  // namespace pnet
