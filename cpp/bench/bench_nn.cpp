// bench_nn: the fused neural-energy kernel against LibTorch autograd, and
// against the machine's FP64 FMA peak, all measured in this run.
//
//   bench_nn [--particles N] [--seconds S] [--models DIR]
//
// For the 2D net (snow_2d, width 32) and the 3D net (snow_3d, width 64):
// nanoseconds per particle for N (value), N + grad and N + grad + Hessian
// (with respect to F), with 1 and 2 threads, fused (EnergyNetwork: the fused
// MLP and, for a principal-input model, the change of frame) and LibTorch (the
// model file's TorchScript forward on [F, F0, h], torch::autograd::grad: one
// reverse pass for the gradient, one more per entry of F for the Hessian), on
// the same batch; the ratio; the fused kernel's GFLOP/s (matrix-product flops,
// FusedMlp::flops_per_row) as a fraction of the FMA peak of the same thread
// count; and the full energy (NeuralElastoplasticEnergy, with and without the
// PSD projection of the Hessian).
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/nn/energy_network.hpp"
#include "pnet/nn/simd.hpp"
#include "pnet/nn/torchscript.hpp"

namespace {

using pnet::FusedMlp;
using Clock = std::chrono::steady_clock;

/// Seconds per call of `fn`: the best of 5 rounds, each repeating fn for at
/// least `seconds` / 5 (at least once). The best, not the mean: other load on
/// the machine only ever slows a round down.
double time_per_call(const std::function<void()>& fn, double seconds) {
    double best = 1e300;
    fn();  // warm up
    for (int round = 0; round < 5; ++round) {
        const auto start = Clock::now();
        int calls = 0;
        double elapsed = 0.0;
        do {
            fn();
            ++calls;
            elapsed = std::chrono::duration<double>(Clock::now() - start).count();
        } while (elapsed < seconds / 5.0);
        best = std::min(best, elapsed / calls);
    }
    return best;
}

/// FP64 FMA throughput (GFLOP/s, 2 flops per lane per FMA) of `threads`
/// threads running 12 independent chains of 4-lane FMAs each.
double fma_peak_gflops(int threads, double seconds) {
    using pnet::simd::Vd;
    double best = 0.0;
    for (int round = 0; round < 3; ++round) {
        const long iterations = static_cast<long>(2e8 * seconds / 3.0);
        double sink = 0.0;
        const auto start = Clock::now();
#pragma omp parallel num_threads(threads) reduction(+ : sink)
        {
            Vd a[12];
            for (int k = 0; k < 12; ++k) a[k] = pnet::simd::splat(1.0 + 1e-9 * (k + omp_get_thread_num()));
            const Vd m = pnet::simd::splat(0.9999999), c = pnet::simd::splat(1e-9);
            for (long i = 0; i < iterations; ++i) {
#pragma GCC unroll 12
                for (int k = 0; k < 12; ++k) a[k] = a[k] * m + c;
            }
            for (int k = 0; k < 12; ++k) sink += a[k][0] + a[k][3];
        }
        const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
        if (sink == 42.0) std::printf(" ");  // keeps the chains alive
        best = std::max(best, 12.0 * 4 * 2 * iterations * threads / elapsed / 1e9);
    }
    return best;
}

/// Network inputs [vec F, vec F0, h] like a simulation's: F0 = R1 diag(e^eps) R2,
/// eps in [-0.5, 0.5], F = F0 + 0.05 G with G Gaussian, h in [-0.5, 0].
std::vector<double> make_inputs(int dim, int input_width, std::size_t n, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal;
    std::uniform_real_distribution<double> uniform(-0.5, 0.5);
    const int m = dim * dim;
    std::vector<double> x(n * input_width);
    for (std::size_t p = 0; p < n; ++p) {
        double* row = &x[p * input_width];
        // A random F0 near a rotation-stretch; accuracy of the net is not the point here.
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) row[m + i * dim + j] = (i == j ? std::exp(uniform(rng)) : 0.2 * uniform(rng));
        for (int k = 0; k < m; ++k) row[k] = row[m + k] + 0.05 * normal(rng);
        if (input_width > 2 * m) row[2 * m] = uniform(rng) - 0.5;
    }
    return x;
}

struct Net {
    const char* label;
    std::string file;
    int dim;
};

const char* order_name(FusedMlp::Order order) {
    return order == FusedMlp::Order::Value ? "N" : order == FusedMlp::Order::Gradient ? "N+grad" : "N+grad+Hess";
}

/// The rows [vec F, vec F0, (h)] of make_inputs() as matrices.
template <int dim>
struct Batch {
    std::vector<pnet::Mat<dim>> F, F0;
    std::vector<double> h;
};

template <int dim>
Batch<dim> unpack(const std::vector<double>& x, int in, std::size_t n) {
    constexpr int m = dim * dim;
    Batch<dim> b{std::vector<pnet::Mat<dim>>(n), std::vector<pnet::Mat<dim>>(n), std::vector<double>(n, 0.0)};
    for (std::size_t p = 0; p < n; ++p) {
        for (int k = 0; k < m; ++k) {
            b.F[p](k / dim, k % dim) = x[p * in + k];
            b.F0[p](k / dim, k % dim) = x[p * in + m + k];
        }
        if (in > 2 * m) b.h[p] = x[p * in + 2 * m];
    }
    return b;
}

/// The fused evaluation of N and its derivatives in F, frame included.
struct FusedEvaluator {
    std::function<void(FusedMlp::Order, double*, double*, double*)> evaluate;
    double flops_per_row[3];
};

template <int dim>
FusedEvaluator fused_evaluator(const pnet::ModelFile& model, const std::vector<double>& x, std::size_t n) {
    auto batch = std::make_shared<Batch<dim>>(unpack<dim>(x, model.metadata.forward_input_width(), n));
    auto network = std::make_shared<pnet::EnergyNetwork<dim>>(model.weights, model.metadata.representation,
                                                              model.metadata.has_hardening, model.path);
    network->set_reference(batch->F0.data(), batch->h.data(), n);
    FusedEvaluator e;
    e.evaluate = [batch, network](FusedMlp::Order order, double* value, double* gradient, double* hessian) {
        network->evaluate(batch->F.data(), order, value, gradient, hessian);
    };
    for (FusedMlp::Order order : {FusedMlp::Order::Value, FusedMlp::Order::Gradient, FusedMlp::Order::Hessian})
        e.flops_per_row[static_cast<int>(order)] = network->mlp().flops_per_row(order);
    return e;
}

template <int dim>
void energy_rows(const pnet::ModelFile& model, const std::vector<double>& x, std::size_t n, double seconds,
                 int threads) {
    using pnet::Mat;
    Batch<dim> b = unpack<dim>(x, model.metadata.forward_input_width(), n);
    std::vector<Mat<dim>>& F = b.F;
    std::vector<Mat<dim>>& F0 = b.F0;
    std::vector<double>& h = b.h;
    std::vector<double> psi(n);
    pnet::NeuralElastoplasticEnergy<dim> energy(model, {1.4e5, 1.0});
    energy.set_reference(F0.data(), h.data(), n);
    std::vector<Mat<dim>> grad(n);
    std::vector<pnet::Tensor4<dim>> hess(n);
    omp_set_num_threads(threads);
    const double raw = time_per_call(
        [&] { energy.value_gradient_hessian(F.data(), psi.data(), grad.data(), hess.data(), false); }, seconds);
    const double psd = time_per_call(
        [&] { energy.value_gradient_hessian(F.data(), psi.data(), grad.data(), hess.data(), true); }, seconds);
    std::printf("| %dD energy Psi+grad+Hess (scaled, regularized) | %d | %.0f | with PSD projection: %.0f |\n", dim,
                threads, raw / n * 1e9, psd / n * 1e9);
}

}  // namespace

int main(int argc, char** argv) {
    std::size_t particles = 8192;
    double seconds = 1.0;
    std::string models = PNET_MODELS_DIR;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto next = [&]() -> std::string {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "bench_nn: %s needs a value\n", arg.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (arg == "--particles")
            particles = std::stoul(next());
        else if (arg == "--seconds")
            seconds = std::stod(next());
        else if (arg == "--models")
            models = next();
        else {
            std::fprintf(stderr, "usage: bench_nn [--particles N] [--seconds S] [--models DIR]\n");
            return 2;
        }
    }

    const double peak[3] = {0.0, fma_peak_gflops(1, seconds), fma_peak_gflops(2, seconds)};
    std::printf("FP64 FMA peak measured: %.1f GFLOP/s (1 thread), %.1f GFLOP/s (2 threads)\n", peak[1], peak[2]);
    std::printf("batch: %zu particles; times are the best of 5 rounds of >= %.2f s\n\n", particles, seconds / 5);
    std::printf("| net | quantity | threads | fused ns/particle | LibTorch ns/particle | LibTorch / fused | fused "
                "GFLOP/s | %% of peak | max rel. diff |\n|---|---|---|---|---|---|---|---|---|\n");

    const Net nets[] = {{"2D snow_2d", models + "/snow_2d.pt", 2}, {"3D snow_3d", models + "/snow_3d.pt", 3}};
    std::vector<std::pair<const Net*, pnet::ModelFile>> loaded;
    for (const Net& net : nets) {
        const pnet::ModelFile model = pnet::load_model_file(net.file);
        const pnet::TorchAutograd torch_ref = pnet::TorchAutograd::from_file(net.file);
        const int in = model.metadata.forward_input_width(), m = model.metadata.derivative_inputs();
        const std::vector<double> x = make_inputs(net.dim, in, particles, 7);
        const FusedEvaluator fused =
            net.dim == 2 ? fused_evaluator<2>(model, x, particles) : fused_evaluator<3>(model, x, particles);
        std::string label = std::string(net.label) + " " + pnet::to_string(model.metadata.representation) + " [";
        for (std::size_t k = 0; k < model.metadata.widths.size(); ++k)
            label += (k ? "," : "") + std::to_string(model.metadata.widths[k]);
        label += "]";
        std::vector<double> value(particles), gradient(particles * m), hessian(particles * m * m);
        std::vector<double> tvalue(particles), tgradient(particles * m), thessian(particles * m * m);
        for (FusedMlp::Order order : {FusedMlp::Order::Value, FusedMlp::Order::Gradient, FusedMlp::Order::Hessian}) {
            double fused_ns[3] = {0, 0, 0};
            for (int threads : {1, 2}) {
                omp_set_num_threads(threads);
                pnet::TorchAutograd::set_threads(threads);
                const double tf = time_per_call(
                    [&] { fused.evaluate(order, value.data(), gradient.data(), hessian.data()); },
                    seconds);
                const double tt = time_per_call(
                    [&] {
                        torch_ref.evaluate(x.data(), particles, m, order, tvalue.data(), tgradient.data(),
                                           thessian.data());
                    },
                    seconds);
                // Agreement, relative to the largest entry of each quantity.
                auto rel = [](const std::vector<double>& a, const std::vector<double>& b) {
                    double diff = 0.0, scale = 0.0;
                    for (std::size_t i = 0; i < a.size(); ++i) {
                        diff = std::max(diff, std::abs(a[i] - b[i]));
                        scale = std::max(scale, std::abs(b[i]));
                    }
                    return scale > 0 ? diff / scale : diff;
                };
                double diff = rel(value, tvalue);
                if (order != FusedMlp::Order::Value) diff = std::max(diff, rel(gradient, tgradient));
                if (order == FusedMlp::Order::Hessian) diff = std::max(diff, rel(hessian, thessian));
                fused_ns[threads] = tf / particles * 1e9;
                const double gflops = fused.flops_per_row[static_cast<int>(order)] * particles / tf / 1e9;
                std::printf("| %s | %s | %d | %.1f | %.1f | %.1fx | %.1f | %.0f%% | %.1e |\n", label.c_str(),
                            order_name(order), threads, fused_ns[threads], tt / particles * 1e9, tt / tf, gflops,
                            100.0 * gflops / peak[threads], diff);
            }
            std::printf("| %s | %s | 2 vs 1 thread | speed-up %.2fx | | | | | |\n", label.c_str(), order_name(order),
                        fused_ns[1] / fused_ns[2]);
        }
        loaded.emplace_back(&net, model);
    }
    std::printf("\n| energy | threads | ns/particle | |\n|---|---|---|---|\n");
    for (auto& [net, model] : loaded) {
        const std::vector<double> x = make_inputs(net->dim, model.metadata.forward_input_width(), particles, 7);
        for (int threads : {1, 2}) {
            if (net->dim == 2)
                energy_rows<2>(model, x, particles, seconds, threads);
            else
                energy_rows<3>(model, x, particles, seconds, threads);
        }
    }
    return 0;
}
