// The FEM incremental potential (docs/methods.md): its gradient and assembled
// Hessian against finite differences (elements with a plastic part F^P),
// Newton with the CHOLMOD direct solve against PCG, and a physical check: a bar
// hanging under its own weight settles at the analytic elongation.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "pnet/contact/collisions/contact.hpp"
#include "pnet/contact/friction.hpp"
#include "pnet/fem/fem_potential.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "pnet/solver/newton.hpp"
#include "support/form_checks.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

Mesh<2> box_mesh(double w, double h, double size) {
    Shape2d box;
    box.kind = Shape2d::Kind::Box;
    box.min = Vec<2>(0.0, 0.0);
    box.max = Vec<2>(w, h);
    box.element_size = size;
    return mesh_shape(box, "box");
}

MaterialDescription jelly(double E, double nu) {
    MaterialDescription m;
    m.name = "jelly";
    m.density = 1000.0;
    m.elasticity = ElasticityModel::StvkHencky;
    m.elastic.E = E;
    m.elastic.nu = nu;
    m.plasticity = PlasticityModel::None;
    return m;
}

struct Fixture {
    Mesh<2> mesh;
    ElementRest<2> rest;
    std::vector<Material<2>> materials;
    ElasticParticleEnergy<2> energy;
    FemPotential<2> potential;
    std::vector<int> object;
    std::vector<double> hardening;

    Fixture(Mesh<2> m, const MaterialDescription& material)
        : mesh(std::move(m)),
          rest(mesh, std::vector<double>(mesh.elements.size(), material.density)),
          materials{Material<2>(material)},
          energy(materials),
          potential(mesh, rest, energy),
          object(mesh.elements.size(), 0),
          hardening(mesh.elements.size(), 0.0) {}
};

/// The free components of a velocity vector v: restrict() picks them, expand() writes them back
/// into a copy of v (the fixed ones keep v's values), for derivative checks along them only.
struct FreeComponents {
    VecX v;
    std::vector<Eigen::Index> free;
    FreeComponents(const VecX& at, const std::vector<char>& fixed) : v(at) {
        for (Eigen::Index k = 0; k < v.size(); ++k)
            if (!fixed[k]) free.push_back(k);
    }
    VecX expand(const VecX& y) const {
        VecX full = v;
        for (std::size_t k = 0; k < free.size(); ++k) full[free[k]] = y[k];
        return full;
    }
    VecX restrict(const VecX& full) const {
        VecX y(free.size());
        for (std::size_t k = 0; k < free.size(); ++k) y[k] = full[free[k]];
        return y;
    }
    /// H's rows and columns of the free components.
    Eigen::MatrixXd restrict_hessian(const Eigen::MatrixXd& H) const {
        Eigen::MatrixXd H_free(free.size(), free.size());
        for (std::size_t a = 0; a < free.size(); ++a)
            for (std::size_t b = 0; b < free.size(); ++b) H_free(a, b) = H(free[a], free[b]);
        return H_free;
    }
    /// The potential's gradient at expand(y), restricted to the free components.
    VecX gradient(FemPotential<2>& potential, const VecX& y) const {
        VecX g;
        potential.value_gradient(expand(y), g);
        return restrict(g);
    }
};

TEST(FemPotential, GradientAndHessianMatchFiniteDifferences) {
    Fixture f(box_mesh(0.1, 0.05, 0.025), jelly(1e5, 0.3));
    const std::size_t n = f.mesh.nodes(), ne = f.mesh.elements.size();
    test::Random random(3);
    std::vector<Vec<2>> x(n);
    for (std::size_t i = 0; i < n; ++i) x[i] = f.mesh.x[i] + 0.002 * random.uniform_vec<2>(-1.0, 1.0);
    std::vector<Mat<2>> plastic_inverse(ne);
    for (auto& Pi : plastic_inverse) Pi = (Mat<2>::Identity() + 0.05 * Mat<2>::NullaryExpr([&] { return random.uniform(-1, 1); })).inverse();
    VecX v_star(2 * n);
    for (Eigen::Index k = 0; k < v_star.size(); ++k) v_star[k] = random.uniform(-0.5, 0.5);
    std::vector<char> fixed(2 * n, 0);
    fixed[0] = fixed[1] = 1;  // node 0 is fixed
    const double dt = 1e-2;
    f.potential.begin_step(x, v_star, dt, plastic_inverse, fixed);
    f.potential.set_material_state(f.object, f.hardening);
    f.potential.set_reference({});
    f.potential.set_project_psd(false);
    VecX v = v_star;
    for (Eigen::Index k = 2; k < v.size(); ++k) v[k] += random.uniform(-0.2, 0.2);

    // Derivatives along the free components (node 0's are fixed: its gradient is 0 and its
    // Hessian rows and columns hold only the mass).
    const FreeComponents components(v, fixed);
    const std::size_t n_free = components.free.size();
    VecX g;
    f.potential.value_gradient(v, g);
    EXPECT_EQ(g[0], 0.0);
    EXPECT_EQ(g[1], 0.0);
    test::FdStats fd;
    const VecX v_free = components.restrict(v);
    EXPECT_TRUE(test::check_gradient([&](const VecX& y) { return f.potential.value(components.expand(y)); },
                                     components.restrict(g), v_free, fd, 1e-6, 1e-5, 1e-6 * g.cwiseAbs().maxCoeff()));
    f.potential.prepare_hessian(v);
    const Eigen::MatrixXd H = Eigen::MatrixXd(*f.potential.hessian_matrix());
    auto grad_of = [&](const VecX& y) { return components.gradient(f.potential, y); };
    EXPECT_TRUE(test::check_jacobian(grad_of, components.restrict_hessian(H), v_free, fd, 1e-6, 1e-5,
                                     1e-6 * H.cwiseAbs().maxCoeff()));
    for (Eigen::Index k = 2; k < H.cols(); ++k) EXPECT_EQ(H(0, k), 0.0);
    EXPECT_EQ(H(0, 0), f.rest.node_mass[0]);
    EXPECT_EQ(fd.checks, static_cast<int>(n_free + n_free * n_free)) << "every entry was compared";
    EXPECT_LT((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-12 * H.cwiseAbs().maxCoeff()) << "symmetric";
    VecX d = VecX::Random(2 * n), Hd;
    f.potential.hessian_multiply(d, Hd);
    EXPECT_LT((Hd - H * d).cwiseAbs().maxCoeff(), 1e-12 * (H * d).cwiseAbs().maxCoeff());
}

// The assembled Hessian with contact and friction (a second matrix added to the mesh's
// fixed pattern) against finite differences of the gradient, after the kinematic stages'
// soften/harden cycle refilled the pattern: a block resting within dhat of the ground,
// sliding, with one fixed node.
TEST(FemPotential, AssembledHessianWithContactAndFrictionMatchesFiniteDifferences) {
    Fixture f(box_mesh(0.1, 0.05, 0.025), jelly(1e5, 0.3));
    const std::size_t n = f.mesh.nodes(), ne = f.mesh.elements.size();
    std::vector<Vec<2>> x(n);
    for (std::size_t i = 0; i < n; ++i) x[i] = f.mesh.x[i] + Vec<2>(0.0, 5e-4);  // the bottom within dhat
    const double dhat = 1e-3;
    Contact2d contact(f.mesh.boundary, dhat, 1e8);
    contact.add_half_space({Vec<2>(0.0, 0.0), Vec<2>(0.0, 1.0)});
    ASSERT_GT(contact.active_pairs(x), 2u);
    Friction2d friction(0.3, 1e-3);
    friction.lag(contact, x);
    ASSERT_GT(friction.pairs(), 2u);
    f.potential.set_contact(&contact);
    f.potential.set_friction(&friction);
    test::Random random(5);
    VecX v_star(2 * n);
    for (std::size_t i = 0; i < n; ++i) v_star.segment<2>(2 * i) = Vec<2>(0.02, -0.01);
    std::vector<char> fixed(2 * n, 0);
    Eigen::Index node = 0;  // the bottom-left corner is fixed
    for (std::size_t i = 0; i < n; ++i)
        if (x[i][0] + x[i][1] < x[node][0] + x[node][1]) node = static_cast<Eigen::Index>(i);
    ASSERT_LT(x[node][1], dhat);
    fixed[2 * node] = fixed[2 * node + 1] = 1;
    const double dt = 1e-2;
    f.potential.begin_step(x, v_star, dt, std::vector<Mat<2>>(ne, Mat<2>::Identity()), fixed);
    f.potential.set_material_state(f.object, f.hardening);
    f.potential.set_reference({});
    f.potential.set_project_psd(false);
    VecX v = v_star;
    for (Eigen::Index k = 0; k < v.size(); ++k)
        if (!fixed[k]) v[k] += random.uniform(-0.005, 0.005);
    ASSERT_GE(f.potential.max_step(VecX::Zero(v.size()), v), 1.0) << "an intersection-free test point";
    f.potential.soften_fixed(1e3);
    f.potential.prepare_hessian(v);
    const Eigen::MatrixXd soft(*f.potential.hessian_matrix());
    f.potential.harden_fixed();

    const FreeComponents components(v, fixed);
    const std::size_t n_free = components.free.size();
    f.potential.prepare_hessian(v);
    const Eigen::MatrixXd H(*f.potential.hessian_matrix());
    auto grad_of = [&](const VecX& y) { return components.gradient(f.potential, y); };
    test::FdStats fd;
    EXPECT_TRUE(test::check_jacobian(grad_of, components.restrict_hessian(H), components.restrict(v), fd, 1e-7, 1e-4,
                                     1e-6 * H.cwiseAbs().maxCoeff()));
    EXPECT_EQ(fd.checks, static_cast<int>(n_free * n_free)) << "every entry was compared";
    // The fixed node keeps only its mass, although its contact and element entries are in the pattern.
    for (Eigen::Index k = 0; k < H.cols(); ++k)
        for (const Eigen::Index c : {2 * node, 2 * node + 1}) {
            EXPECT_EQ(H(c, k), c == k ? f.rest.node_mass[node] : 0.0) << c << ", " << k;
            EXPECT_EQ(H(k, c), c == k ? f.rest.node_mass[node] : 0.0) << k << ", " << c;
        }
    // Softened, the fixed node's row holds its elasticity and contact, and its weighted mass. (The
    // neighbour is taken from an element: node + 1 was read before, out of range when the corner is the
    // mesh's last node -- a read past the matrix that valgrind found and that made this test flaky.)
    Eigen::Index neighbour = -1;
    for (const auto& element : f.mesh.elements)
        for (int a = 0; a < 3 && neighbour < 0; ++a)
            if (element[a] == node) neighbour = element[(a + 1) % 3];
    ASSERT_GE(neighbour, 0);
    EXPECT_NE(soft(2 * node + 1, 2 * neighbour + 1), 0.0);
    EXPECT_GT(soft(2 * node + 1, 2 * node + 1), 1e3 * f.rest.node_mass[node]);
    EXPECT_LT((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-12 * H.cwiseAbs().maxCoeff()) << "symmetric";
    // Each form (inertia, elements, contact = barrier + friction) on its own.
    ASSERT_EQ(f.potential.forms().size(), 3u);
    for (Form* form : f.potential.forms()) EXPECT_GT(test::expect_consistent_form(*form, v, 2, "FEM form"), 0u);
}

// CHOLMOD's direct solve and PCG find the same minimizer; the direct solve
// keeps its symbolic analysis for the whole solve.
TEST(FemPotential, CholeskyAndPcgReachTheSameMinimizer) {
    Fixture f(box_mesh(0.2, 0.04, 0.01), jelly(1e6, 0.3));
    const std::size_t n = f.mesh.nodes();
    std::vector<char> fixed(2 * n, 0);
    for (std::size_t i = 0; i < n; ++i)
        if (f.mesh.x[i][0] < 1e-9) fixed[2 * i] = fixed[2 * i + 1] = 1;  // clamped left end: a cantilever
    VecX v_star = VecX::Zero(2 * n);
    for (std::size_t i = 0; i < n; ++i)
        if (!fixed[2 * i]) v_star[2 * i + 1] = -9.8 * 0.01 - 0.5;  // gravity and a downward push
    f.potential.begin_step(f.mesh.x, v_star, 0.01, std::vector<Mat<2>>(f.mesh.elements.size(), Mat<2>::Identity()),
                           fixed);
    f.potential.set_material_state(f.object, f.hardening);
    f.potential.set_reference({});
    NewtonOptions options;
    options.tolerance = 1e-10;
    options.residual_mass = f.potential.residual_mass();
    VecX v_pcg = v_star, v_direct = v_star;
    options.max_cg_iterations = 5000;
    const NewtonStats pcg = minimize(f.potential, v_pcg, options, "pcg");
    options.linear_solver = NewtonOptions::LinearSolver::Cholesky;
    const NewtonStats direct = minimize(f.potential, v_direct, options, "cholmod");
    EXPECT_TRUE(pcg.converged && direct.converged);
    EXPECT_LT((v_pcg - v_direct).cwiseAbs().maxCoeff(), 1e-8);
    EXPECT_GT((v_direct - v_star).cwiseAbs().maxCoeff(), 0.1) << "the bar resists the push";
    EXPECT_EQ(direct.factorizations, direct.iterations);
    EXPECT_EQ(direct.analyses, 1) << "the pattern does not change within a solve";
    EXPECT_EQ(direct.cg_iterations, 0);
}

// A bar (nu = 0, so 1D theory is exact for small strain: at most 0.2% here)
// hanging from its top under gravity settles, by implicit Euler steps, at the
// elongation rho g L^2 / (2 E) of its bottom.
TEST(FemPotential, HangingBarSettlesAtTheAnalyticElongation) {
    const double L = 0.2, E = 1e6, rho = 1000.0, g = 9.8, dt = 1e-2;
    Fixture f(box_mesh(0.02, L, 0.005), jelly(E, 0.0));
    const std::size_t n = f.mesh.nodes();
    std::vector<char> fixed(2 * n, 0);
    for (std::size_t i = 0; i < n; ++i)
        if (f.mesh.x[i][1] > L - 1e-9) fixed[2 * i] = fixed[2 * i + 1] = 1;
    std::vector<Vec<2>> x = f.mesh.x;
    VecX v = VecX::Zero(2 * n);
    const std::vector<Mat<2>> identity(f.mesh.elements.size(), Mat<2>::Identity());
    NewtonOptions options;
    options.tolerance = 1e-9;
    options.linear_solver = NewtonOptions::LinearSolver::Cholesky;
    for (int step = 0; step < 200; ++step) {
        VecX v_star = v;
        for (std::size_t i = 0; i < n; ++i) {
            if (fixed[2 * i]) v_star.segment<2>(2 * i).setZero();
            else v_star[2 * i + 1] -= g * dt;
        }
        f.potential.begin_step(x, v_star, dt, identity, fixed);
        f.potential.set_material_state(f.object, f.hardening);
        f.potential.set_reference({});
        options.residual_mass = f.potential.residual_mass();
        v = v_star;
        const NewtonStats s = minimize(f.potential, v, options, "step " + std::to_string(step));
        ASSERT_TRUE(s.converged) << "step " << step;
        for (std::size_t i = 0; i < n; ++i) x[i] += dt * v.segment<2>(2 * i);
    }
    double bottom = 0.0;
    int count = 0;
    for (std::size_t i = 0; i < n; ++i)
        if (f.mesh.x[i][1] < 1e-9) {
            bottom += f.mesh.x[i][1] - x[i][1];
            ++count;
        }
    bottom /= count;
    const double analytic = rho * g * L * L / (2.0 * E);
    EXPECT_NEAR(bottom, analytic, 0.01 * analytic) << "bottom displacement (m)";
    EXPECT_LT(v.cwiseAbs().maxCoeff(), 1e-3) << "at rest";
}

}  // namespace
}  // namespace pnet
