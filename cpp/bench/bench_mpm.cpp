// bench_mpm: throughput of the explicit ground-truth MPM integrator in
// particle-steps per second, on the canonical scenes, with 1 and 2 threads.
//
//   bench_mpm [--seconds S] [--warmup T] [--scenes DIR] [--only NAME]
//
// Each scene is first run (2 threads, CFL step) to t = T of simulated time
// (default 0.2 s: the column is collapsing, the snowball has hit the floor and
// plasticity is active), so that the timed steps see a typical state rather
// than the resting initial one. From a copy of that state, every thread count
// then runs the same steps at the CFL step of that state, repeated in rounds
// of about S/3 seconds; the best round is reported (other load on the machine
// only ever slows a round down). Phases: P2G (binning, stress forces,
// scatter), grid update, G2P (gather, return mapping, advection, clamping).
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "pnet/mpm/explicit_integrator.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/scene/scene.hpp"

namespace {

struct Measurement {
    double particle_steps_per_second = 0.0;
    double p2g = 0.0, grid = 0.0, g2p = 0.0;  // fractions of the step time
    long steps = 0;
};

template <int dim>
Measurement time_steps(const pnet::MpmSystem<dim>& system, const pnet::Particles<dim>& start, double dt, int threads,
                       double seconds) {
    omp_set_num_threads(threads);
    Measurement best;
    // Steps per round: about seconds/3 at 4 M particle-steps/s, at least 20.
    const long steps = std::max<long>(20, static_cast<long>(4e6 * seconds / 3.0 / start.size()));
    for (int round = 0; round < 3; ++round) {
        pnet::Particles<dim> particles = start;
        pnet::ExplicitIntegrator<dim> integrator(system);
        integrator.compute_stress(particles);
        double p2g = 0.0, grid = 0.0, g2p = 0.0;
        const auto t0 = std::chrono::steady_clock::now();
        for (long s = 0; s < steps; ++s) {
            const pnet::MpmStepStats stats = integrator.step(particles, dt, s);
            p2g += stats.p2g_seconds;
            grid += stats.grid_seconds;
            g2p += stats.g2p_seconds;
        }
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const double rate = static_cast<double>(steps) * start.size() / elapsed;
        if (rate > best.particle_steps_per_second) {
            const double total = p2g + grid + g2p;
            best = {rate, p2g / total, grid / total, g2p / total, steps};
        }
    }
    return best;
}

template <int dim>
void bench_scene(const pnet::Scene& scene, double seconds, double warmup, double cfl, double& rate_two_threads) {
    const pnet::MpmSystem<dim> system = pnet::make_mpm_system<dim>(scene);
    pnet::Particles<dim> particles = pnet::sample_particles<dim>(scene);
    {
        omp_set_num_threads(2);
        pnet::ExplicitIntegrator<dim> integrator(system);
        double t = 0.0;
        long step = 0;
        while (t < warmup) {
            const double dt = pnet::cfl_time_step(system, particles, cfl);
            integrator.step(particles, dt, step++);
            t += dt;
        }
    }
    const double dt = pnet::cfl_time_step(system, particles, cfl);
    Measurement m[2];
    for (int threads = 1; threads <= 2; ++threads) {
        m[threads - 1] = time_steps<dim>(system, particles, dt, threads, seconds);
        const Measurement& r = m[threads - 1];
        std::printf("| %s | %zu | %d | %.2e | %ld | %.2f | %.0f | %.0f%% | %.0f%% | %.0f%% |\n", scene.name.c_str(),
                    particles.size(), threads, dt, r.steps, r.particle_steps_per_second / 1e6,
                    1e9 / r.particle_steps_per_second * threads, 100 * r.p2g, 100 * r.grid, 100 * r.g2p);
        std::fflush(stdout);
    }
    std::printf("| %s | | 2 vs 1 | | | speed-up %.2fx | | | | |\n", scene.name.c_str(),
                m[1].particle_steps_per_second / m[0].particle_steps_per_second);
    rate_two_threads = m[1].particle_steps_per_second;
}

}  // namespace

int main(int argc, char** argv) {
    double seconds = 3.0, warmup = 0.2, cfl = 0.5;
    std::string scenes_dir = PNET_SCENES_DIR, only;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> const char* {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "bench_mpm: %s needs a value\n", arg.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (arg == "--seconds") seconds = std::atof(value());
        else if (arg == "--warmup") warmup = std::atof(value());
        else if (arg == "--cfl") cfl = std::atof(value());
        else if (arg == "--scenes") scenes_dir = value();
        else if (arg == "--only") only = value();
        else {
            std::fprintf(stderr,
                         "usage: bench_mpm [--seconds S] [--warmup T] [--cfl C] [--scenes DIR] [--only NAME]\n");
            return 2;
        }
    }
    std::printf("Explicit MPM (double), CFL %.2f, after %.2f s of simulated warm-up; best of 3 rounds of ~%.1f s\n\n",
                cfl, warmup, seconds / 3.0);
    std::printf("| scene | particles | threads | dt (s) | steps/round | M particle-steps/s | ns/particle-step/thread | "
                "P2G | grid | G2P |\n|---|---|---|---|---|---|---|---|---|---|\n");
    const char* names[] = {"sand_column_2d", "snowball_2d", "sand_column_3d", "snowball_3d"};
    double rate[4] = {0, 0, 0, 0};
    for (int k = 0; k < 4; ++k) {
        if (!only.empty() && only != names[k]) continue;
        try {
            const pnet::Scene scene = pnet::load_scene(scenes_dir + "/" + names[k] + ".json");
            if (scene.dim == 2) bench_scene<2>(scene, seconds, warmup, cfl, rate[k]);
            else bench_scene<3>(scene, seconds, warmup, cfl, rate[k]);
        } catch (const std::exception& e) {
            std::fprintf(stderr, "bench_mpm: %s: %s\n", names[k], e.what());
            return 1;
        }
    }
    std::printf("\nTargets (2 threads): 2D >= 25 M particle-steps/s: sand %.1f M, snow %.1f M; 3D >= 8 M: sand %.1f M, "
                "snow %.1f M\n",
                rate[0] / 1e6, rate[1] / 1e6, rate[2] / 1e6, rate[3] / 1e6);
    return 0;
}
