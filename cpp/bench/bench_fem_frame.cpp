// bench_fem_frame: the paper's metal frame experiment (Fig. 8; DESIGN.md §5,
// metal_frame_2d) built from the FEM library, until FEM scene files exist: a
// hollow frame (outer 0.10 x 0.18 m, walls 0.012 m, gmsh triangles of ~3 mm,
// preset metal: StVK-Hencky + von Mises) standing on the ground (Coulomb 0.3)
// under a rigid plate (0.16 x 0.01 m) that starts 1 mm above it and moves down
// at 0.05 m/s. Rows: plasticitynet (models/metal_2d.pt), analytic (ECI) and
// lagged at dt 1e-2, explicit at 1e-5 and at its CFL step, over the same
// frames, measured in one run: seconds per frame, Newton per step, speed-up
// against explicit 1e-5, and the mean and max nodal distance to explicit 1e-5
// at the last frame (m and % of the bounding-box diagonal), and the smallest
// contact distance over the run (> 0: nothing ever touched).
//
//   bench_fem_frame [--frames N] [--threads T] [--dt-implicit S] [--kappa-scale K]
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "pnet/contact/adaptive_stiffness.hpp"
#include "pnet/contact/friction.hpp"
#include "pnet/energy/analytic_elastoplastic.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "pnet/nn/model_file.hpp"

namespace {

using namespace pnet;

constexpr double kFrameDt = 0.02;  // s

struct Experiment {
    FemSystem<2> system;
    std::size_t frame_nodes = 0;
    double diagonal = 0.0, dhat = 0.0, kappa = 0.0;
};

Experiment metal_frame() {
    Experiment ex;
    Shape2d frame;
    frame.kind = Shape2d::Kind::Frame;
    frame.min = Vec<2>(0.45, 0.0);
    frame.max = Vec<2>(0.55, 0.18);
    frame.thickness = 0.012;
    frame.element_size = 0.003;
    Shape2d plate;
    plate.kind = Shape2d::Kind::Box;
    plate.min = Vec<2>(0.42, 0.181);  // 1 mm above the frame
    plate.max = Vec<2>(0.58, 0.191);
    plate.element_size = 0.01;
    FemSystem<2>& s = ex.system;
    s.mesh = mesh_shape(frame, "metal frame");
    ex.frame_nodes = s.mesh.nodes();
    s.mesh.append(mesh_shape(plate, "plate"));
    const auto [lo, hi] = s.mesh.bounding_box();
    ex.diagonal = (hi - lo).norm();
    ex.dhat = 1e-3 * ex.diagonal;
    // The frame stands on the ground inside the barrier's reach: lift the whole mesh by dhat / 2.
    for (Vec<2>& x : s.mesh.x) x[1] += 0.5 * ex.dhat;
    s.mesh.finalize("metal frame and plate");
    s.materials = {Material<2>(material_preset("metal"))};
    s.element_object.assign(s.mesh.elements.size(), 0);
    s.gravity = Vec<2>(0.0, -9.8);
    s.fixed_node.assign(s.mesh.nodes(), 0);
    s.prescribed_velocity.assign(s.mesh.nodes(), Vec<2>::Zero());
    for (std::size_t i = ex.frame_nodes; i < s.mesh.nodes(); ++i) {
        s.fixed_node[i] = 1;
        s.prescribed_velocity[i] = Vec<2>(0.0, -0.05);
    }
    s.make_rest();
    return ex;
}

struct Row {
    std::string name;
    double dt = 0.0, seconds_per_frame = 0.0, newton = 0.0, fixed_point = 0.0, min_distance = 1e300;
    int steps = 0, unconverged = 0;
    FemState<2> state;
    std::string failure;
};

Row run(const Experiment& ex, const std::string& name, double dt, int frames, double kappa) {
    Row row;
    row.name = name;
    row.dt = dt;
    Contact2d contact(ex.system.mesh.boundary, ex.dhat, kappa);
    contact.add_half_space({Vec<2>(0.0, 0.0), Vec<2>(0.0, 1.0)});
    Friction2d friction(0.3, 1e-4);
    row.state = FemState<2>::at_rest(ex.system);
    const auto start = std::chrono::steady_clock::now();
    try {
        if (name == "explicit") {
            FemExplicitIntegrator<2> integrator(ex.system, &contact);
            integrator.set_friction(&friction, &contact);
            if (dt == 0.0) row.dt = dt = integrator.cfl_time_step(0.5);
            const int steps = static_cast<int>(std::ceil(frames * kFrameDt / dt - 1e-9));
            const double h = frames * kFrameDt / steps;
            for (int s = 0; s < steps; ++s) {
                integrator.step(row.state, h, s);
                row.min_distance = std::min(row.min_distance, contact.min_distance(row.state.x));
            }
            row.steps = steps;
        } else {
            ImplicitOptions options;
            options.newton_tolerance = 1e-5;
            options.max_newton_iterations = 200;
            options.fixed_point_tolerance = 1e-6;  // FEM: far tighter than MPM (see tests/cpp/fem/test_fem_learned.cpp)
            options.max_fixed_point_iterations = 50;
            std::unique_ptr<ParticleEnergy<2>> energy;
            FemMethod method = FemMethod::Lagged;
            const std::vector<std::string> context = {"metal frame"};
            if (name == "analytic") {
                method = FemMethod::Analytic;
                energy = std::make_unique<AnalyticElastoplasticEnergy<2>>(ex.system.materials, context);
            } else if (name == "plasticitynet") {
                method = FemMethod::PlasticityNet;
                auto model = std::make_shared<const ModelFile>(load_model_file(std::string(PNET_MODELS_DIR) + "/metal_2d.pt"));
                energy = std::make_unique<NeuralParticleEnergy<2>>(std::vector<std::shared_ptr<const ModelFile>>{model},
                                                                   ex.system.materials, context, 1.0);
            } else {
                energy = std::make_unique<ElasticParticleEnergy<2>>(ex.system.materials);
            }
            FemImplicitIntegrator<2> integrator(ex.system, method, options, std::move(energy), &contact);
            integrator.set_friction(&friction, &contact);
            const int steps = static_cast<int>(std::lround(frames * kFrameDt / dt));
            for (int s = 0; s < steps; ++s) {
                const StepStats st = integrator.step(row.state, dt, s);
                row.newton += st.newton_iterations;
                row.fixed_point += st.fixed_point_iterations;
                row.unconverged += !st.converged;
                row.min_distance = std::min(row.min_distance, contact.min_distance(row.state.x));
                std::fprintf(stderr, "\r  %s dt %g: step %d/%d   ", name.c_str(), dt, s + 1, steps);
            }
            row.steps = steps;
            row.newton /= steps;
            row.fixed_point /= steps;
        }
    } catch (const std::exception& e) {
        row.failure = e.what();
    }
    row.seconds_per_frame = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / frames;
    std::fprintf(stderr, "\n  %s dt %g: %.3f s/frame%s%s\n", name.c_str(), row.dt, row.seconds_per_frame,
                 row.failure.empty() ? "" : ", failed: ", row.failure.c_str());
    return row;
}

std::pair<double, double> nodal_distance(const Experiment& ex, const FemState<2>& a, const FemState<2>& b) {
    double sum = 0.0, worst = 0.0;
    for (std::size_t i = 0; i < ex.frame_nodes; ++i) {
        const double d = (a.x[i] - b.x[i]).norm();
        sum += d;
        worst = std::max(worst, d);
    }
    return {sum / ex.frame_nodes, worst};
}

}  // namespace

int main(int argc, char** argv) {
    int frames = 3, threads = 0;
    double dt_implicit = 1e-2, kappa_scale = 1.0;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (i + 1 >= argc) {
            std::fprintf(stderr, "usage: bench_fem_frame [--frames N] [--threads T] [--dt-implicit S]\n");
            return 2;
        }
        if (arg == "--frames") frames = std::atoi(argv[++i]);
        else if (arg == "--threads") threads = std::atoi(argv[++i]);
        else if (arg == "--dt-implicit") dt_implicit = std::atof(argv[++i]);
        else if (arg == "--kappa-scale") kappa_scale = std::atof(argv[++i]);
        else {
            std::fprintf(stderr, "usage: bench_fem_frame [--frames N] [--threads T] [--dt-implicit S] [--kappa-scale K]\n");
            return 2;
        }
    }
    if (frames < 1 || !(dt_implicit > 0.0)) {
        std::fprintf(stderr, "bench_fem_frame: --frames must be >= 1 and --dt-implicit > 0\n");
        return 2;
    }
    if (threads > 0) omp_set_num_threads(threads);
    const Experiment ex = metal_frame();
    // IPC's kappa for the implicit step (velocity form at dt_implicit), with no contact force to
    // balance at the start: the lower bound. The same kappa, a physical stiffness, in every row.
    double mass = 0.0;
    for (double m : ex.system.rest.node_mass) mass += m;
    BarrierStiffness k = initial_barrier_stiffness(ex.diagonal, ex.dhat, mass / ex.system.mesh.nodes(), dt_implicit,
                                                   Eigen::VectorXd::Zero(2), Eigen::VectorXd::Zero(2));
    // --kappa-scale K: K times IPC's lower bound (at most its upper bound, 100).
    k.kappa = std::min(k.kappa_max, kappa_scale * k.kappa);
    std::printf("Metal frame (2D, %zu frame nodes, %zu elements, dhat %.3g m, kappa %.3g): frames 0-%d (%.2f s "
                "of plate travel), %d threads\n\n",
                ex.frame_nodes, ex.system.mesh.elements.size(), ex.dhat, k.kappa, frames, frames * kFrameDt,
                omp_get_max_threads());
    std::vector<Row> rows;
    rows.push_back(run(ex, "explicit", 1e-5, frames, k.kappa));
    rows.push_back(run(ex, "explicit", 0.0, frames, k.kappa));
    rows.push_back(run(ex, "plasticitynet", dt_implicit, frames, k.kappa));
    rows.push_back(run(ex, "analytic", dt_implicit, frames, k.kappa));
    rows.push_back(run(ex, "lagged", dt_implicit, frames, k.kappa));
    const Row& gt = rows[0];
    std::printf("| integrator | dt (s) | s/frame | Newton/step | fixed-point/step | unconverged | speed-up vs explicit "
                "1e-5 | mean / max nodal distance to explicit 1e-5 (%% of diagonal) | to analytic | min contact "
                "distance (m) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (const Row& r : rows) {
        const bool implicit = r.name != "explicit";
        std::string distance = "-", to_analytic = "-";
        if (&r != &gt && r.failure.empty() && gt.failure.empty()) {
            const auto [mean, worst] = nodal_distance(ex, r.state, gt.state);
            char text[96];
            std::snprintf(text, sizeof text, "%.3g / %.3g m (%.3f%% / %.3f%%)", mean, worst, 100 * mean / ex.diagonal,
                          100 * worst / ex.diagonal);
            distance = text;
        }
        if (implicit && r.name != "analytic" && rows[3].failure.empty() && r.failure.empty()) {
            const auto [mean, worst] = nodal_distance(ex, r.state, rows[3].state);
            char text[64];
            std::snprintf(text, sizeof text, "%.3f%% / %.3f%%", 100 * mean / ex.diagonal, 100 * worst / ex.diagonal);
            to_analytic = text;
        }
        char speedup[32] = "-";  // only when both runs covered the whole interval
        if (gt.failure.empty() && r.failure.empty())
            std::snprintf(speedup, sizeof speedup, "%.2fx", gt.seconds_per_frame / r.seconds_per_frame);
        char dt[32];
        std::snprintf(dt, sizeof dt, "%.3g%s", r.dt, implicit || r.dt == 1e-5 ? "" : " (CFL)");
        std::printf("| %s | %s | %.4g%s | %s | %s | %s | %s | %s | %s | %.3g |\n", r.name.c_str(), dt,
                    r.seconds_per_frame, r.failure.empty() ? "" : " (failed)",
                    implicit ? std::to_string(r.newton).substr(0, 5).c_str() : "-",
                    implicit ? std::to_string(r.fixed_point).substr(0, 5).c_str() : "-",
                    implicit ? std::to_string(r.unconverged).c_str() : "-", speedup,
                    distance.c_str(), to_analytic.c_str(), r.min_distance);
    }
    std::printf("\nFrame's centre of mass moved by (m), and its top and bottom nodes' mean height change (m):\n");
    for (const Row& r : rows) {
        if (!r.failure.empty()) continue;
        Vec<2> shift = Vec<2>::Zero();
        double top = 0.0, bottom = 0.0;
        int n_top = 0, n_bottom = 0;
        for (std::size_t i = 0; i < ex.frame_nodes; ++i) {
            shift += r.state.x[i] - ex.system.mesh.x[i];
            if (ex.system.mesh.x[i][1] > 0.18) top += r.state.x[i][1] - ex.system.mesh.x[i][1], ++n_top;
            if (ex.system.mesh.x[i][1] < 0.001) bottom += r.state.x[i][1] - ex.system.mesh.x[i][1], ++n_bottom;
        }
        shift /= ex.frame_nodes;
        std::printf("  %s dt %.3g: (%.3e, %.3e), top %.3e, bottom %.3e\n", r.name.c_str(), r.dt, shift[0], shift[1],
                    top / std::max(n_top, 1), bottom / std::max(n_bottom, 1));
    }
    for (const Row& r : rows)
        if (!r.failure.empty()) std::printf("\n%s (dt %g) failed: %s\n", r.name.c_str(), r.dt, r.failure.c_str());
    return 0;
}
