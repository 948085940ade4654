#pragma once
// A constructed MPM-like linear system for tests and benchmarks of the linear solvers
// (tests/cpp/solver/test_multigrid.cpp, cpp/bench/bench_preconditioners.cpp): the grid velocities of
// an implicit MPM step's Newton system on an N x N grid, with particles 2 x 2 per cell (the grid's
// border of two cells left empty), quadratic B-spline stencils, an isotropic linear elasticity
// (Lame mu, lambda from E and nu) and the lumped mass,
//
//   A = M + dt^2 sum_p V_p G_p^T C G_p,
//
// and the floor layer's y components (grid rows <= 3) held fixed: their rows and columns hold the
// mass alone. dt^2 E / (rho dx^2) is the stiffness-to-mass ratio that sets Jacobi's condition number.
#include <array>
#include <cmath>
#include <vector>

#include "pnet/solver/objective.hpp"  // VecX, SparseMatrix

namespace pnet {

/// A = M + dt^2 K on the nodes of an N x N grid (node (i, j) is unknowns 2 (i + (N + 1) j) + a; only
/// the nodes some particle reaches are unknowns), with the components of the floor layer (j <= 3)
/// along y fixed: their rows and columns hold the mass alone.
struct GridModelProblem {
    int dim = 2;
    std::vector<int> coordinates;
    VecX free;
    SparseMatrix A;

    GridModelProblem(int cells, double youngs, double dt = 1e-3, double nu = 0.3, bool floor = true,
                     double rho = 1000.0) {
        const double dx = 1.0 / cells;
        const double mu = youngs / (2 * (1 + nu)), lambda = youngs * nu / ((1 + nu) * (1 - 2 * nu));
        const int n1 = cells + 1;
        std::vector<int> dof(static_cast<std::size_t>(n1 * n1), -1);
        struct Particle {
            std::array<int, 9> node;
            std::array<double, 9> w;
            std::array<Eigen::Vector2d, 9> grad;
        };
        std::vector<Particle> particles;
        for (int cj = 2; cj < cells - 2; ++cj)
            for (int ci = 2; ci < cells - 2; ++ci)
                for (int q = 0; q < 4; ++q) {
                    const double x[2] = {ci + 0.25 + 0.5 * (q % 2), cj + 0.25 + 0.5 * (q / 2)};  // in cells
                    int base[2];
                    double w[2][3], dw[2][3];
                    for (int a = 0; a < 2; ++a) {
                        base[a] = static_cast<int>(std::floor(x[a] - 0.5));
                        const double f = x[a] - base[a];
                        w[a][0] = 0.5 * (1.5 - f) * (1.5 - f);
                        w[a][1] = 0.75 - (f - 1) * (f - 1);
                        w[a][2] = 0.5 * (f - 0.5) * (f - 0.5);
                        dw[a][0] = (f - 1.5) / dx;
                        dw[a][1] = -2 * (f - 1) / dx;
                        dw[a][2] = (f - 0.5) / dx;
                    }
                    Particle p;
                    for (int s = 0; s < 9; ++s) {
                        const int si = s % 3, sj = s / 3;
                        const int node = (base[0] + si) + n1 * (base[1] + sj);
                        if (dof[node] < 0) {
                            dof[node] = static_cast<int>(coordinates.size() / 2);
                            coordinates.push_back(base[0] + si);
                            coordinates.push_back(base[1] + sj);
                        }
                        p.node[s] = dof[node];
                        p.w[s] = w[0][si] * w[1][sj];
                        p.grad[s] = Eigen::Vector2d(dw[0][si] * w[1][sj], w[0][si] * dw[1][sj]);
                    }
                    particles.push_back(p);
                }
        const Eigen::Index n = static_cast<Eigen::Index>(coordinates.size());
        free = VecX::Ones(n);
        for (Eigen::Index k = 0; k < n / 2; ++k)
            if (floor && coordinates[2 * k + 1] <= 3) free[2 * k + 1] = 0.0;
        const double mp = rho * dx * dx / 4, volume = dx * dx / 4;
        VecX mass = VecX::Zero(n);
        std::vector<Eigen::Triplet<double>> t;
        for (const Particle& p : particles)
            for (int s = 0; s < 9; ++s) {
                mass[2 * p.node[s]] += p.w[s] * mp;
                mass[2 * p.node[s] + 1] += p.w[s] * mp;
                for (int r = 0; r < 9; ++r)
                    for (int a = 0; a < 2; ++a)
                        for (int b = 0; b < 2; ++b) {
                            const Eigen::Index row = 2 * p.node[s] + a, col = 2 * p.node[r] + b;
                            if (free[row] == 0.0 || free[col] == 0.0) continue;
                            const double k = mu * p.grad[s].dot(p.grad[r]) * (a == b) +
                                             mu * p.grad[s][b] * p.grad[r][a] + lambda * p.grad[s][a] * p.grad[r][b];
                            t.emplace_back(row, col, dt * dt * volume * k);
                        }
            }
        for (Eigen::Index i = 0; i < n; ++i) t.emplace_back(i, i, mass[i]);
        A.resize(n, n);
        A.setFromTriplets(t.begin(), t.end());
    }
};

}  // namespace pnet
