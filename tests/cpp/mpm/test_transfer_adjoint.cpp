// The adjoints of the APIC transfers (mpm/transfer_adjoint.hpp) against central differences of the
// production transfers themselves (field_to_grid, gather_velocity and the trial F of grid_to_particles):
// a random loss on P2G's node masses and momenta, and on G2P's velocities, affine matrices, trial F and
// advected positions, differenced along random directions in every input (positions included, through the
// B-spline weights), 2D and 3D.
#include <gtest/gtest.h>

#include <vector>

#include "pnet/mpm/transfer.hpp"
#include "pnet/mpm/transfer_adjoint.hpp"
#include "support/dims.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

PNET_TYPED_TEST_SUITE_2D_3D(TransferAdjointTest);

template <int dim>
Grid<dim> small_grid(double dx) {
    std::array<int, dim> cells;
    cells.fill(16);
    return Grid<dim>(Vec<dim>::Zero(), dx, cells);
}

/// A few particles well inside the grid with random velocities, affine matrices and F, none within 0.05
/// cells of a stencil boundary (where the weights' Hessian jumps and a difference straddles it).
template <int dim>
Mat<dim> random_matrix(test::Random& random) {
    Mat<dim> M;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) M(i, j) = random.uniform(-1.0, 1.0);
    return M;
}

template <int dim>
Particles<dim> random_particles(test::Random& random, double dx, int count) {
    Particles<dim> P;
    P.resize(count);
    for (int p = 0; p < count; ++p) {
        Vec<dim> x;
        for (int a = 0; a < dim; ++a) {
            double cells;
            do {
                cells = random.uniform(5.0, 10.0);
            } while (std::abs(cells - std::floor(cells) - 0.5) < 0.05);
            x[a] = cells * dx;
        }
        P.x[p] = x;
        P.v[p] = random.template uniform_vec<dim>(-1.0, 1.0);
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) {
                P.C[p](i, j) = random.uniform(-5.0, 5.0);
                P.F_elastic[p](i, j) = (i == j ? 1.0 : 0.0) + random.uniform(-0.2, 0.2);
            }
        P.mass[p] = random.uniform(0.5, 2.0);
    }
    return P;
}

TYPED_TEST(TransferAdjointTest, ParticlesToGridAdjointIsTheTransposeOfItsDerivative) {
    constexpr int dim = TypeParam::value;
    const double dx = 1.0 / 16;
    test::Random random(61);
    const Particles<dim> P = random_particles<dim>(random, dx, 12);
    Grid<dim> grid = small_grid<dim>(dx);
    const std::int64_t nodes = grid.storage_size();
    std::vector<double> mass_bar(nodes);
    std::vector<Vec<dim>> momentum_bar(nodes);
    for (std::int64_t i = 0; i < nodes; ++i) {
        mass_bar[i] = random.uniform(-1.0, 1.0);
        momentum_bar[i] = random.template uniform_vec<dim>(-1.0, 1.0);
    }
    auto loss = [&](const Particles<dim>& Q) {
        field_to_grid<dim>(grid, Q, Q.v, Q.C, nullptr);
        double L = 0.0;
        for (std::int64_t i = 0; i < nodes; ++i)
            L += mass_bar[i] * grid.node(i).mass + momentum_bar[i].dot(grid.node(i).momentum);
        return L;
    };
    std::vector<Vec<dim>> x_bar(P.size(), Vec<dim>::Zero()), v_bar(P.size(), Vec<dim>::Zero());
    std::vector<Mat<dim>> C_bar(P.size(), Mat<dim>::Zero());
    particles_to_grid_adjoint<dim>(grid, P, mass_bar, momentum_bar, x_bar, v_bar, C_bar);

    // One direction per input kind, then all at once.
    for (int kind = 0; kind < 4; ++kind) {
        Particles<dim> direction = P;
        double predicted = 0.0;
        for (std::size_t p = 0; p < P.size(); ++p) {
            direction.x[p] = kind == 0 || kind == 3 ? random.template uniform_vec<dim>(-dx, dx) : Vec<dim>::Zero();
            direction.v[p] = kind == 1 || kind == 3 ? random.template uniform_vec<dim>(-1.0, 1.0) : Vec<dim>::Zero();
            direction.C[p] = kind == 2 || kind == 3 ? random_matrix<dim>(random) : Mat<dim>::Zero();
            predicted += x_bar[p].dot(direction.x[p]) + v_bar[p].dot(direction.v[p]) +
                         C_bar[p].cwiseProduct(direction.C[p]).sum();
        }
        const double h = 1e-6;
        Particles<dim> plus = P, minus = P;
        for (std::size_t p = 0; p < P.size(); ++p) {
            plus.x[p] += h * direction.x[p];
            minus.x[p] -= h * direction.x[p];
            plus.v[p] += h * direction.v[p];
            minus.v[p] -= h * direction.v[p];
            plus.C[p] += h * direction.C[p];
            minus.C[p] -= h * direction.C[p];
        }
        const double differenced = (loss(plus) - loss(minus)) / (2.0 * h);
        EXPECT_NEAR(predicted, differenced, 1e-6 * std::abs(differenced)) << "input kind " << kind;
    }
}

TYPED_TEST(TransferAdjointTest, GridToParticlesAdjointIsTheTransposeOfItsDerivative) {
    constexpr int dim = TypeParam::value;
    const double dx = 1.0 / 16, dt = 2e-3;
    test::Random random(67);
    const Particles<dim> P = random_particles<dim>(random, dx, 12);
    Grid<dim> grid = small_grid<dim>(dx);
    const std::int64_t nodes = grid.storage_size();
    std::vector<Vec<dim>> grid_v(nodes);
    for (std::int64_t i = 0; i < nodes; ++i) grid_v[i] = random.template uniform_vec<dim>(-1.0, 1.0);
    std::vector<Vec<dim>> x_out_bar(P.size()), v_out_bar(P.size());
    std::vector<Mat<dim>> C_out_bar(P.size()), F_bar_out(P.size());
    for (std::size_t p = 0; p < P.size(); ++p) {
        x_out_bar[p] = random.template uniform_vec<dim>(-1.0, 1.0);
        v_out_bar[p] = random.template uniform_vec<dim>(-1.0, 1.0);
        C_out_bar[p] = random_matrix<dim>(random);
        F_bar_out[p] = random_matrix<dim>(random);
    }
    auto loss = [&](const Particles<dim>& Q, const std::vector<Vec<dim>>& v_nodes) {
        for (std::int64_t i = 0; i < nodes; ++i) grid.node(i).momentum = v_nodes[i];  // gather reads velocities here
        double L = 0.0;
        for (std::size_t p = 0; p < Q.size(); ++p) {
            Vec<dim> v;
            Mat<dim> C, grad_v;
            gather_velocity<dim>(grid, Q.x[p], v, C, grad_v);
            const Mat<dim> F_trial = (Mat<dim>::Identity() + dt * grad_v) * Q.F_elastic[p];
            L += x_out_bar[p].dot(Q.x[p] + dt * v) + v_out_bar[p].dot(v) + C_out_bar[p].cwiseProduct(C).sum() +
                 F_bar_out[p].cwiseProduct(F_trial).sum();
        }
        return L;
    };
    std::vector<Vec<dim>> grid_v_bar(nodes, Vec<dim>::Zero()), x_bar(P.size(), Vec<dim>::Zero());
    std::vector<Mat<dim>> F_bar(P.size(), Mat<dim>::Zero());
    grid_to_particles_adjoint<dim>(grid, P, grid_v, dt, x_out_bar, v_out_bar, C_out_bar, F_bar_out, grid_v_bar, x_bar,
                                   F_bar);

    for (int kind = 0; kind < 4; ++kind) {
        Particles<dim> dP = P;
        std::vector<Vec<dim>> dv(nodes, Vec<dim>::Zero());
        double predicted = 0.0;
        for (std::size_t p = 0; p < P.size(); ++p) {
            dP.x[p] = kind == 0 || kind == 3 ? random.template uniform_vec<dim>(-dx, dx) : Vec<dim>::Zero();
            dP.F_elastic[p] = kind == 1 || kind == 3 ? random_matrix<dim>(random) : Mat<dim>::Zero();
            predicted += x_bar[p].dot(dP.x[p]) + F_bar[p].cwiseProduct(dP.F_elastic[p]).sum();
        }
        if (kind == 2 || kind == 3)
            for (std::int64_t i = 0; i < nodes; ++i) {
                dv[i] = random.template uniform_vec<dim>(-1.0, 1.0);
                predicted += grid_v_bar[i].dot(dv[i]);
            }
        const double h = 1e-6;
        Particles<dim> plus = P, minus = P;
        std::vector<Vec<dim>> v_plus = grid_v, v_minus = grid_v;
        for (std::size_t p = 0; p < P.size(); ++p) {
            plus.x[p] += h * dP.x[p];
            minus.x[p] -= h * dP.x[p];
            plus.F_elastic[p] += h * dP.F_elastic[p];
            minus.F_elastic[p] -= h * dP.F_elastic[p];
        }
        for (std::int64_t i = 0; i < nodes; ++i) {
            v_plus[i] += h * dv[i];
            v_minus[i] -= h * dv[i];
        }
        const double differenced = (loss(plus, v_plus) - loss(minus, v_minus)) / (2.0 * h);
        EXPECT_NEAR(predicted, differenced, 1e-6 * std::abs(differenced)) << "input kind " << kind;
    }
}

}  // namespace
}  // namespace pnet
