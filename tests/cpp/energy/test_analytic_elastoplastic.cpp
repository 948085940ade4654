// The ECI closed-form energy (StVK-Hencky + von Mises): its gradient is the
// elastoplastic stress of the return mapping, exactly; gradient and Hessian
// against finite differences in the elastic and the plastic branch, 2D and 3D.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include "pnet/energy/analytic_elastoplastic.hpp"
#include "support/dims.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

PNET_TYPED_TEST_SUITE_2D_3D(AnalyticEnergyTest);

TYPED_TEST(AnalyticEnergyTest, GradientIsTheElastoplasticStressAndDerivativesMatch) {
    constexpr int dim = TypeParam::value;
    constexpr int m = dim * dim;
    MaterialDescription metal = material_preset("metal");
    const std::vector<Material<dim>> materials = {Material<dim>(metal)};
    AnalyticElastoplasticEnergy<dim> energy(materials, {"metal"});
    test::Random random(17);
    std::vector<Mat<dim>> F;
    std::vector<double> h;
    int plastic = 0, elastic = 0;
    for (int k = 0; k < 16; ++k) {
        F.push_back(random.template deformation<dim>(k % 2 ? 0.02 : 0.3));
        h.push_back(random.uniform(0.02, 0.1));
    }
    const std::size_t n = F.size();
    energy.set_reference(F, h, std::vector<int>(n, 0));
    std::vector<double> psi(n);
    std::vector<Mat<dim>> P(n);
    std::vector<Tensor4<dim>> H(n);
    energy.evaluate(F, ParticleEnergy<dim>::Order::Hessian, psi.data(), P.data(), H.data(), false);
    const double E = metal.elastic.E;
    test::FdStats fd;
    for (std::size_t p = 0; p < n; ++p) {
        const Mat<dim> Ptilde = materials[0].elastoplastic_stress(F[p], h[p]);
        EXPECT_LE((P[p] - Ptilde).cwiseAbs().maxCoeff(), 1e-9 * E) << "particle " << p;
        const PolarSVD<dim> svd = clamped_svd<dim>(F[p]);
        const Vec<dim> e = svd.Sigma.array().log().matrix();
        ((e.array() - e.mean()).matrix().norm() > h[p] ? plastic : elastic) += 1;
        auto value = [&](const Eigen::VectorXd& f) {
            std::vector<Mat<dim>> G = {unflatten<dim>(f)};
            double v;
            energy.set_reference(G, {h[p]}, {0});
            energy.evaluate(G, ParticleEnergy<dim>::Order::Value, &v, nullptr, nullptr, false);
            return v;
        };
        auto gradient = [&](const Eigen::VectorXd& f) {
            std::vector<Mat<dim>> G = {unflatten<dim>(f)};
            double v;
            Mat<dim> g;
            energy.set_reference(G, {h[p]}, {0});
            energy.evaluate(G, ParticleEnergy<dim>::Order::Gradient, &v, &g, nullptr, false);
            return Eigen::VectorXd(flatten<dim>(g));
        };
        const Eigen::VectorXd f = flatten<dim>(F[p]);
        EXPECT_TRUE(test::check_gradient(value, flatten<dim>(P[p]), f, fd, 1e-6, 1e-5, 1e-4 * E));
        EXPECT_TRUE(test::check_jacobian(gradient, Eigen::MatrixXd(H[p]), f, fd, 1e-6, 1e-4, 1e-4 * E));
    }
    EXPECT_GT(plastic, 2);
    EXPECT_GT(elastic, 2);
    EXPECT_EQ(fd.checks, static_cast<int>(n * (m + m * m)));
    // Projected Hessians are PSD.
    energy.set_reference(F, h, std::vector<int>(n, 0));
    energy.evaluate(F, ParticleEnergy<dim>::Order::Hessian, psi.data(), P.data(), H.data(), true);
    for (const Tensor4<dim>& A : H)
        EXPECT_GE(Eigen::SelfAdjointEigenSolver<Tensor4<dim>>(A).eigenvalues().minCoeff(), -1e-9 * E);
}

TEST(AnalyticElastoplasticEnergy, RefusesOtherMaterials) {
    const std::vector<Material<2>> sand = {Material<2>(material_preset("sand"))};
    try {
        AnalyticElastoplasticEnergy<2> energy(sand, {"s.json: objects[0]"});
        FAIL() << "accepted sand";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("s.json: objects[0]: the analytic integrator needs StVK-Hencky"),
                  std::string::npos);
    }
}

}  // namespace
}  // namespace pnet
