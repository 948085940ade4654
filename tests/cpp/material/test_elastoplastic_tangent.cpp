// The consistent tangent dPtilde/dF of the return-mapped stress (material/elastoplastic_tangent.hpp):
// for von Mises (associative, the Jacobian is symmetric) it is the finite-difference Jacobian of the
// material library's Ptilde(F, h), elastic and plastic branches, 2D and 3D; for the non-associative
// models it is symmetric and, projected, positive semi-definite, and with its skew part kept the
// finite-difference Jacobian again.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <string>

#include <Eigen/Eigenvalues>

#include "pnet/material/elastoplastic_tangent.hpp"
#include "pnet/material/material.hpp"
#include "support/dims.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

PNET_TYPED_TEST_SUITE_2D_3D(ElastoplasticTangentTest);

template <int dim>
Tensor4<dim> tangent_of(const Material<dim>& material, const Mat<dim>& F, double h, bool project,
                        bool keep_skew = false) {
    const PrincipalReturnMap<dim> Z = [&](const Vec<dim>& Sigma) { return material.return_map(Sigma, h).Sigma; };
    return elastoplastic_tangent<dim>(clamped_svd<dim>(F), material.elasticity(), Z, project, keep_skew);
}

TYPED_TEST(ElastoplasticTangentTest, VonMisesTangentIsTheJacobianOfTheStress) {
    constexpr int dim = TypeParam::value;
    const Material<dim> metal(material_preset("metal"));
    const double E = metal.description().elastic.E;
    test::Random random(29);
    test::FdStats fd;
    int plastic = 0, elastic = 0;
    for (int k = 0; k < 16; ++k) {
        const Mat<dim> F = random.template deformation<dim>(k % 2 ? 0.02 : 0.3);
        const double h = random.uniform(0.02, 0.1);
        const Vec<dim> e = clamped_svd<dim>(F).Sigma.array().log().matrix();
        ((e.array() - e.mean()).matrix().norm() > h ? plastic : elastic) += 1;
        const Tensor4<dim> K = tangent_of<dim>(metal, F, h, false);
        auto stress = [&](const Eigen::VectorXd& f) -> Eigen::VectorXd {
            return flatten<dim>(metal.elastoplastic_stress(unflatten<dim>(f), h));
        };
        EXPECT_TRUE(test::check_jacobian(stress, K, flatten<dim>(F), fd, 1e-6, 1e-4, 1e-3 * E)) << "sample " << k;
    }
    EXPECT_GT(plastic, 2);
    EXPECT_GT(elastic, 2);
    EXPECT_EQ(fd.checks, 16 * dim * dim * dim * dim);
}

TYPED_TEST(ElastoplasticTangentTest, NonAssociativeTangentIsSymmetricAndProjectsToPsd) {
    constexpr int dim = TypeParam::value;
    test::Random random(31);
    for (const char* preset : {"sand", "snow"}) {
        const Material<dim> material(material_preset(preset));
        const double h = material.description().initial_hardening;
        int checked = 0;
        for (int k = 0; k < 12; ++k) {
            const Mat<dim> F = random.template deformation<dim>(0.2);
            const Tensor4<dim> K = tangent_of<dim>(material, F, h, false);
            ASSERT_TRUE(K.allFinite()) << preset << " sample " << k;
            EXPECT_LE((K - K.transpose()).cwiseAbs().maxCoeff(), 1e-9 * K.cwiseAbs().maxCoeff()) << preset;
            const Tensor4<dim> P = tangent_of<dim>(material, F, h, true);
            const double smallest = Eigen::SelfAdjointEigenSolver<Tensor4<dim>>(P).eigenvalues().minCoeff();
            EXPECT_GE(smallest, -1e-9 * P.cwiseAbs().maxCoeff()) << preset << " sample " << k;
            ++checked;
        }
        EXPECT_EQ(checked, 12);
    }
}

// With its skew part kept (keep_skew) the non-associative tangent is the full Jacobian of the stress,
// unprojected; projected, its symmetric part is the PSD one above and its skew part is unchanged, so
// x . K x >= 0 (what keeps a Newton direction solved with it a descent direction).
TYPED_TEST(ElastoplasticTangentTest, NonAssociativeTangentWithItsSkewPartIsTheJacobianOfTheStress) {
    constexpr int dim = TypeParam::value;
    test::Random random(41);
    for (const char* preset : {"sand", "snow"}) {
        const Material<dim> material(material_preset(preset));
        const double E = material.description().elastic.E;
        const double h = material.description().initial_hardening;
        test::FdStats fd;
        std::map<ReturnBranch, int> branches;
        double skew = 0.0;
        int differenced = 0;
        for (int k = 0; k < 24; ++k) {
            const Mat<dim> F = random.template deformation<dim>(k % 2 ? 0.02 : 0.2);
            const ReturnBranch branch = material.return_map(clamped_svd<dim>(F).Sigma, h).branch;
            branches[branch] += 1;
            const Tensor4<dim> J = tangent_of<dim>(material, F, h, false, true);
            if (branch == ReturnBranch::Apex) {  // stress-free in a neighbourhood: nothing to difference
                EXPECT_EQ(J.cwiseAbs().maxCoeff(), 0.0) << preset << " sample " << k;
                continue;
            }
            auto stress = [&](const Eigen::VectorXd& f) -> Eigen::VectorXd {
                return flatten<dim>(material.elastoplastic_stress(unflatten<dim>(f), h));
            };
            // 3e-3: the tangent's own central difference in log-strain (1e-5) on Cam-Clay's curved
            // ellipse return differs from this one by up to 1.2e-3 (measured; von Mises: < 1e-4).
            EXPECT_TRUE(test::check_jacobian(stress, J, flatten<dim>(F), fd, 1e-6, 3e-3, 1e-3 * E))
                << preset << " sample " << k << " (" << to_string(branch) << ")";
            ++differenced;
            skew = std::max(skew, 0.5 * (J - J.transpose()).cwiseAbs().maxCoeff() / J.cwiseAbs().maxCoeff());
            const Tensor4<dim> P = tangent_of<dim>(material, F, h, true, true);
            const Tensor4<dim> symmetric = tangent_of<dim>(material, F, h, true);
            EXPECT_LE((0.5 * (P + P.transpose()) - symmetric).cwiseAbs().maxCoeff(), 1e-9 * P.cwiseAbs().maxCoeff());
            EXPECT_LE((0.5 * (P - P.transpose()) - 0.5 * (J - J.transpose())).cwiseAbs().maxCoeff(),
                      1e-9 * P.cwiseAbs().maxCoeff());
        }
        EXPECT_GT(skew, 1e-3) << preset << ": the plastic samples' Jacobian is not symmetric";
        EXPECT_GE(branches.size(), 2u) << preset << ": the samples must reach an elastic and a plastic branch";
        EXPECT_GE(differenced, 8) << preset;
        EXPECT_EQ(fd.checks, differenced * dim * dim * dim * dim) << preset;
    }
}

// Ptilde is isotropic, so its change under a rotation of F is exact: Ptilde(e^{tW} F) = e^{tW} Ptilde(F) and
// Ptilde(F e^{tW}) = Ptilde(F) e^{tW} (W skew), and the tangent must give T : (W F) = W Ptilde and
// T : (F W) = Ptilde W. That tests its rotational part, (tau_i - tau_j) / (Sigma_i - Sigma_j) and
// (tau_i + tau_j) / (Sigma_i + Sigma_j), without differencing the return: here at principal strains closer
// than the tangent's kCloseLog (1e-4), strains of 1e-5 as at a sand pile's free surface.
TYPED_TEST(ElastoplasticTangentTest, TheTangentIsExactUnderRotationsAtNearlyEqualSingularValues) {
    constexpr int dim = TypeParam::value;
    test::Random random(43);
    for (const char* preset : {"sand", "snow", "metal"}) {
        const Material<dim> material(material_preset(preset));
        const double h = material.description().initial_hardening;
        std::map<ReturnBranch, int> branches;
        for (int k = 0; k < 24; ++k) {
            // Principal strains 1e-6..6e-5 apart about a mean strain from -5e-5 (compression) to 2e-5.
            const double mean = random.uniform(-5e-5, 2e-5), spread = random.uniform(1e-6, 3e-5);
            Vec<dim> eps;
            for (int i = 0; i < dim; ++i) eps[i] = mean + spread * (i == 0 ? 1.0 : i == 1 ? -1.0 : 0.3);
            const Mat<dim> F = random.template rotation<dim>() * Mat<dim>(eps.array().exp().matrix().asDiagonal()) *
                               random.template rotation<dim>();
            const PolarSVD<dim> svd = clamped_svd<dim>(F);
            const ReturnBranch branch = material.return_map(svd.Sigma, h).branch;
            branches[branch] += 1;
            const Tensor4<dim> T = material.elastoplastic_tangent(svd, h, false, true);
            const Mat<dim> P = material.elastoplastic_stress(svd, h);
            Mat<dim> W = random.template deformation<dim>(1.0);
            W = (W - W.transpose()).eval();
            const double scale = std::max(T.cwiseAbs().maxCoeff() * F.norm() * W.norm(), 1e-300);
            EXPECT_LE((unflatten<dim>(T * flatten<dim>(Mat<dim>(W * F))) - W * P).cwiseAbs().maxCoeff(), 1e-8 * scale)
                << preset << " sample " << k << " (" << to_string(branch) << "), strains " << eps.transpose();
            EXPECT_LE((unflatten<dim>(T * flatten<dim>(Mat<dim>(F * W))) - P * W).cwiseAbs().maxCoeff(), 1e-8 * scale)
                << preset << " sample " << k << " (" << to_string(branch) << "), strains " << eps.transpose();
        }
        // Sand on its three branches; snow and metal yield only beyond these strains.
        EXPECT_EQ(branches.size(), std::string(preset) == "sand" ? 3u : 1u) << preset;
    }
}

// Material::elastoplastic_tangent runs the return mapping in Hencky strain (no log/exp per stencil
// point); it must be the same tangent as the generic one through singular values, on every branch.
TYPED_TEST(ElastoplasticTangentTest, MaterialTangentInStrainMatchesTheGenericOne) {
    constexpr int dim = TypeParam::value;
    test::Random random(37);
    for (const char* preset : {"sand", "snow", "metal", "metal_nh"}) {
        const Material<dim> material(material_preset(preset));
        std::map<ReturnBranch, int> branches;
        for (int k = 0; k < 40; ++k) {
            const Mat<dim> F = random.template deformation<dim>(k % 4 == 0 ? 0.02 : 0.3);
            const double h = material.description().plasticity == PlasticityModel::VonMises
                                 ? random.uniform(0.02, 0.1)
                                 : material.description().initial_hardening;
            const PolarSVD<dim> svd = clamped_svd<dim>(F);
            branches[material.return_map(svd.Sigma, h).branch] += 1;
            for (bool project : {false, true}) {
                const Tensor4<dim> expected = tangent_of<dim>(material, F, h, project);
                const Tensor4<dim> K = material.elastoplastic_tangent(svd, h, project);
                EXPECT_LE((K - expected).cwiseAbs().maxCoeff(), 1e-6 * expected.cwiseAbs().maxCoeff())
                    << preset << " sample " << k << " project " << project;
            }
        }
        EXPECT_GE(branches.size(), 2u) << preset << ": the samples must reach an elastic and a plastic branch";
    }
}

// Drucker-Prager's tangent (Material::elastoplastic_tangent): where every point of the strain stencil lies
// on the center's branch it is the branch's derivative in closed form, the stencil's tangent to the
// stencil's truncation error but not bit for bit (so the closed form is what ran); within twice its step of
// the cone's surface or the apex it is the stencil's, bit for bit (the average of the two sides there).
TYPED_TEST(ElastoplasticTangentTest, DruckerPragerTangentIsInClosedFormAwayFromItsBranchesBoundaries) {
    constexpr int dim = TypeParam::value;
    const Material<dim> sand(material_preset("sand"));
    const DruckerPrager<dim>& model = *sand.template plasticity_model<DruckerPrager<dim>>();
    const double mu = sand.elasticity().mu(), lambda = sand.elasticity().lambda();
    const double c = DruckerPragerParams{sand.description().drucker_prager.friction_angle_deg}.alpha() *
                     (dim * lambda + 2.0 * mu) / (2.0 * mu);
    auto stencil = [&](const PolarSVD<dim>& svd, bool project) {  // the strain stencil, as before the closed form
        constexpr int k = kTangentStencil<dim>;
        Vec<dim> strain[k], tau[k];
        tangent_strain_stencil<dim>(svd.Sigma.array().log().matrix(), strain);
        for (int j = 0; j < k; ++j) tau[j] = sand.elasticity().tau_of_strain(model.project_strain(strain[j]));
        const Mat<dim> quotient =
            deviatoric_scale_quotients<dim>(sand.elasticity(), svd.Sigma, model.deviatoric_scale(strain[0]));
        return elastoplastic_tangent_of_stress<dim>(svd, tau, project, true, &quotient);
    };
    test::Random random(53);
    int far = 0, near = 0, differ = 0;
    for (int k = 0; k < 48; ++k) {
        // A strain at a chosen distance s from the cone's surface (dgamma = ||dev eps|| + c tr eps = s), or
        // from the apex (tr eps = s).
        const double s = (k % 2 ? 1.0 : -1.0) * (k % 4 < 2 ? 1e-6 : 1e-2);
        const double tr = k % 8 < 4 ? -random.uniform(0.005, 0.05) : s;
        Vec<dim> n = random.uniform_vector(dim, -1.0, 1.0);
        n -= n.sum() / dim * Vec<dim>::Ones();
        n.normalize();
        const double L = k % 8 < 4 ? std::max(s - c * tr, 1e-3) : random.uniform(0.001, 0.02);
        const Vec<dim> eps = tr / dim * Vec<dim>::Ones() + L * n;
        const Mat<dim> F =
            random.template rotation<dim>() * eps.array().exp().matrix().asDiagonal() * random.template rotation<dim>();
        const PolarSVD<dim> svd = clamped_svd<dim>(F);
        Mat<dim> jacobian;
        double scale = 0.0, margin = 0.0;
        model.project_strain(svd.Sigma.array().log().matrix(), jacobian, scale, margin);
        for (bool project : {false, true}) {
            const Tensor4<dim> K = sand.elastoplastic_tangent(svd, 0.0, project, true),
                               expected = stencil(svd, project);
            if (margin > 2.0 * kTangentStencilStep) {
                // The stencil's truncation error, delta^2 / ||dev eps||^2 relative on the cone (up to 1e-7 here).
                EXPECT_LE((K - expected).cwiseAbs().maxCoeff(), 1e-6 * expected.cwiseAbs().maxCoeff())
                    << "sample " << k << " margin " << margin;
                differ += K != expected;
                far += 1;
            } else {
                EXPECT_EQ(K, expected) << "sample " << k << " margin " << margin;
                near += 1;
            }
        }
    }
    EXPECT_GE(near, 10);
    EXPECT_GE(far, 10);
    EXPECT_GE(differ, far / 2) << "away from the boundaries the closed form, not the stencil, ran";
}

// Cam-Clay's tangent inside the yield surface is the snow elasticity's, in closed form (not the
// 2d + 1 projections of the stencil): exactly Elasticity::dPdF there, and the stencil's elsewhere.
TYPED_TEST(ElastoplasticTangentTest, CamClayTangentInsideTheYieldSurfaceIsTheElasticOne) {
    constexpr int dim = TypeParam::value;
    const Material<dim> snow(material_preset("snow"));
    const double h = snow.description().initial_hardening;
    test::Random random(47);
    int elastic = 0, plastic = 0;
    for (int k = 0; k < 40; ++k) {
        const Mat<dim> F = random.template deformation<dim>(k % 2 ? 0.002 : 0.05);
        const PolarSVD<dim> svd = clamped_svd<dim>(F);
        const bool inside = snow.return_map(svd.Sigma, h).branch == ReturnBranch::Elastic;
        (inside ? elastic : plastic) += 1;
        for (bool project : {false, true}) {
            const Tensor4<dim> K = snow.elastoplastic_tangent(svd, h, project);
            if (inside) {
                EXPECT_EQ(K, snow.elasticity().dPdF(svd, project)) << "sample " << k;
            } else {
                EXPECT_LE((K - tangent_of<dim>(snow, F, h, project)).cwiseAbs().maxCoeff(),
                          1e-6 * K.cwiseAbs().maxCoeff())
                    << "sample " << k;
            }
        }
    }
    EXPECT_GE(elastic, 5);
    EXPECT_GE(plastic, 5);
}

// CamClay::project_tau, the stencil's stress without Z: tau(Z(Sigma)) of the snow elasticity on every
// branch (inside, the ellipse, both tips), and refused for the paper's variant.
TYPED_TEST(ElastoplasticTangentTest, CamClayStressWithoutZIsTheStressOfZ) {
    constexpr int dim = TypeParam::value;
    const Material<dim> snow(material_preset("snow"));
    const CamClay<dim> cam_clay(snow.description().cam_clay, snow.elasticity());
    test::Random random(53);
    std::map<ReturnBranch, int> branches;
    for (int k = 0; k < 300; ++k) {
        // Down to strains of 1e-9, where the stress is 1e-9 of E: as accurate relative to itself as eq. 17
        // through the Hencky strain (expm1).
        const double magnitude = k % 3 == 0 ? 0.2 : k % 3 == 1 ? 0.01 : std::pow(10.0, -3.0 - k % 7);
        const Vec<dim> Sigma = clamped_svd<dim>(random.template deformation<dim>(magnitude)).Sigma;
        const double a = random.uniform(-0.2, 0.0);
        const ReturnResult<dim> Z = cam_clay.project(Sigma, a);
        branches[Z.branch] += 1;
        const Vec<dim> expected = snow.elasticity().tau_of_strain(Z.Sigma.array().log().matrix());
        const Vec<dim> tau = cam_clay.project_tau(Sigma, cam_clay.p0(a));
        EXPECT_LE((tau - expected).cwiseAbs().maxCoeff(), 1e-9 * expected.cwiseAbs().maxCoeff())
            << k << " (" << to_string(Z.branch) << "), magnitude " << magnitude;
        // Material::elastoplastic_stress takes it (the exact variant), at these singular values exactly.
        PolarSVD<dim> svd;
        svd.U = svd.V = Mat<dim>::Identity();
        svd.Sigma = Sigma;
        EXPECT_LE((snow.elastoplastic_stress(svd, a) - Mat<dim>((expected.array() / Sigma.array()).matrix().asDiagonal()))
                      .cwiseAbs()
                      .maxCoeff(),
                  1e-9 * expected.cwiseAbs().maxCoeff())
            << k;
    }
    for (const ReturnBranch b : {ReturnBranch::Elastic, ReturnBranch::Ellipse, ReturnBranch::CompressionTip,
                                 ReturnBranch::TensionTip})
        EXPECT_GE(branches[b], 3) << to_string(b);
    CamClayParams paper = snow.description().cam_clay;
    paper.variant = CamClayVariant::Paper;
    EXPECT_THROW(CamClay<dim>(paper, snow.elasticity()).project_tau(Vec<dim>::Ones(), 1.0), std::logic_error);
}


TYPED_TEST(ElastoplasticTangentTest, StrainProjectionIsTheLogOfTheProjection) {
    constexpr int dim = TypeParam::value;
    test::Random random(41);
    const Material<dim> sand_material(material_preset("sand"));
    const DruckerPrager<dim> sand(sand_material.description().drucker_prager, sand_material.elasticity());
    for (const char* preset : {"metal", "metal_nh"}) {
        const Material<dim> metal_material(material_preset(preset));
        const VonMises<dim> metal(metal_material.description().von_mises, metal_material.elasticity());
        for (int k = 0; k < 30; ++k) {
            const Vec<dim> Sigma = clamped_svd<dim>(random.template deformation<dim>(0.3)).Sigma;
            const Vec<dim> eps = Sigma.array().log().matrix();
            const double h = random.uniform(0.02, 0.1);
            const Vec<dim> expected = metal.project(Sigma, h).Sigma.array().log().matrix();
            EXPECT_LE((metal.project_strain(eps, h) - expected).cwiseAbs().maxCoeff(), 1e-12) << preset << " " << k;
            if (preset == std::string("metal")) {
                ReturnBranch branch;
                const Vec<dim> sand_expected = sand.project(Sigma, 0.0).Sigma.array().log().matrix();
                EXPECT_LE((sand.project_strain(eps, &branch) - sand_expected).cwiseAbs().maxCoeff(), 1e-12) << k;
                EXPECT_EQ(branch, sand.project(Sigma, 0.0).branch) << k;
            }
        }
    }
}

}  // namespace
}  // namespace pnet
