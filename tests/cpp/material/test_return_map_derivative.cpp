// The derivatives of the return mapping's state update (material/return_map_derivative.hpp; the
// adjoint of an elastoplastic step, docs/adjoint.md) against central differences of
// Material::project: F^E and h' with respect to F_trial and h, elastic and yielding, in 2D and 3D, with
// two equal singular values (3D), one-sided at the yield onset; Drucker-Prager's cone, inside and apex with the
// friction angle's derivatives; Cam-Clay's four branches with its exact tangent and the derivatives in its
// parameters; refused for the materials not written.
#include <gtest/gtest.h>

#include <cmath>

#include "pnet/material/return_map_derivative.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

constexpr int kAngle = static_cast<int>(PlasticityParameter::FrictionAngle);

/// A random rotation (Cayley transform of a random skew matrix).
template <int dim>
Mat<dim> rotation(test::Random& rng) {
    Mat<dim> K = Mat<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = i + 1; j < dim; ++j) K(i, j) = -(K(j, i) = rng.uniform(-1.0, 1.0));
    return (Mat<dim>::Identity() - K).inverse() * (Mat<dim>::Identity() + K);
}

/// Checks return_map_derivative at F = R1 diag(stretch) R2 and h against central differences.
template <int dim>
void check(const Material<dim>& material, const Vec<dim>& stretch, double h, bool yielded, test::Random& rng) {
    const Mat<dim> F = rotation<dim>(rng) * stretch.asDiagonal() * rotation<dim>(rng);
    const ReturnMapDerivative<dim> d = return_map_derivative<dim>(material, clamped_svd<dim>(F), h);
    EXPECT_EQ(d.yielded, yielded) << "stretch " << stretch.transpose() << ", h " << h;
    const double step = 1e-6;
    double worst = 0.0, scale = d.dFE_dF.cwiseAbs().maxCoeff();
    for (int k = 0; k < dim * dim; ++k) {
        Mat<dim> dF = Mat<dim>::Zero();
        dF(k / dim, k % dim) = step;
        const auto plus = material.project(F + dF, h), minus = material.project(F - dF, h);
        const Eigen::Matrix<double, dim * dim, 1> fd =
            flatten<dim>(Mat<dim>((plus.F_elastic - minus.F_elastic) / (2 * step)));
        worst = std::max(worst, (d.dFE_dF.col(k) - fd).cwiseAbs().maxCoeff());
        EXPECT_NEAR(d.dh_dF(k / dim, k % dim), (plus.hardening - minus.hardening) / (2 * step), 1e-7)
            << "dh'/dF entry " << k;
    }
    EXPECT_LT(worst, 1e-7 * scale) << "dF^E/dF, stretch " << stretch.transpose();
    const auto plus = material.project(F, h + step), minus = material.project(F, h - step);
    EXPECT_LT((d.dFE_dh - (plus.F_elastic - minus.F_elastic) / (2 * step)).cwiseAbs().maxCoeff(), 1e-7);
    EXPECT_NEAR(d.dh_dh, (plus.hardening - minus.hardening) / (2 * step), 1e-7);
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    const Mat<dim> fd_P =
        (material.elastoplastic_stress(svd, h + step) - material.elastoplastic_stress(svd, h - step)) / (2 * step);
    EXPECT_LT((d.dP_dh - fd_P).cwiseAbs().maxCoeff(), 1e-6 * std::max(1.0, fd_P.cwiseAbs().maxCoeff()))
        << "dPtilde/dh";
    const ReturnMapDerivative<dim> stress_only = return_map_derivative<dim>(material, svd, h, false);
    EXPECT_EQ(stress_only.dP_dh, d.dP_dh);
    for (int q = 0; q < kPlasticityParameters; ++q) EXPECT_EQ(stress_only.dP_dparameter[q], d.dP_dparameter[q]);
    // The return-mapped stress's exact Jacobian (return_map_tangent), its skew part kept.
    const Tensor4<dim> T = return_map_tangent<dim>(material, svd, h);
    const double dF_step = 1e-7;
    double worst_T = 0.0;
    for (int k = 0; k < dim * dim; ++k) {
        Mat<dim> dF = Mat<dim>::Zero();
        dF(k / dim, k % dim) = dF_step;
        const Eigen::Matrix<double, dim * dim, 1> fd = flatten<dim>(Mat<dim>(
            (material.elastoplastic_stress(F + dF, h) - material.elastoplastic_stress(F - dF, h)) / (2 * dF_step)));
        worst_T = std::max(worst_T, (T.col(k) - fd).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(worst_T, 1e-6 * T.cwiseAbs().maxCoeff()) << "dPtilde/dF, stretch " << stretch.transpose();
}

TEST(ReturnMapDerivative, VonMisesMatchesCentralDifferencesElasticAndYielding) {
    test::Random rng(11);
    const Material<2> metal2(material_preset("metal"));
    const Material<3> metal3(material_preset("metal"));
    for (int trial = 0; trial < 5; ++trial) {
        const Vec<2> s2(rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.1));
        const double L2 = std::abs(std::log(s2[0]) - std::log(s2[1])) / std::sqrt(2.0);
        check<2>(metal2, s2, 0.5 * L2, true, rng);
        check<2>(metal2, s2, 2.0 * L2, false, rng);
        const Vec<3> s3(rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.1));
        const Vec<3> e3 = s3.array().log().matrix();
        const double L3 = (e3 - e3.mean() * Vec<3>::Ones()).norm();
        check<3>(metal3, s3, 0.5 * L3, true, rng);
        check<3>(metal3, s3, 2.0 * L3, false, rng);
    }
    // Two equal singular values (the pair's quotient at its limit), yielding.
    const Vec<3> equal(1.05, 1.05, 0.92);
    const Vec<3> e = equal.array().log().matrix();
    check<3>(metal3, equal, 0.3 * (e - e.mean() * Vec<3>::Ones()).norm(), true, rng);
}

/// Snow (Cam-Clay, its exact variant) at F = R1 diag(stretch) R2 and hardening a on the expected branch:
/// check()'s derivatives, the return-mapped stress's exact Jacobian (return_map_tangent), and F^E, a' and
/// Ptilde in the friction angle, xi and beta, against central differences.
template <int dim>
void check_snow(const Vec<dim>& stretch, double a, ReturnBranch expected, test::Random& rng) {
    const MaterialDescription snow = material_preset("snow");
    const Material<dim> material(snow);
    const Mat<dim> F = rotation<dim>(rng) * stretch.asDiagonal() * rotation<dim>(rng);
    ASSERT_EQ(material.project(F, a).branch, expected) << stretch.transpose();
    check<dim>(material, stretch, a, expected != ReturnBranch::Elastic, rng);
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    const ReturnMapDerivative<dim> d = return_map_derivative<dim>(material, svd, a);
    const char* names[] = {"plasticity.friction_angle_deg", "plasticity.xi", "plasticity.beta"};
    for (int q = 0; q < kPlasticityParameters; ++q) {
        MaterialDescription up = snow, down = snow;
        const double value = *material_parameter(snow, names[q]), h = 1e-6 * std::max(1.0, value);
        *material_parameter(up, names[q]) = value + h;
        *material_parameter(down, names[q]) = value - h;
        const Material<dim> plus(up), minus(down);
        const auto p = plus.project(F, a), m = minus.project(F, a);
        const Mat<dim> fd_FE = (p.F_elastic - m.F_elastic) / (2 * h);
        const Mat<dim> fd_P = (plus.elastoplastic_stress(svd, a) - minus.elastoplastic_stress(svd, a)) / (2 * h);
        EXPECT_LT((d.dFE_dparameter[q] - fd_FE).cwiseAbs().maxCoeff(), 1e-7 * std::max(1.0, fd_FE.cwiseAbs().maxCoeff()))
            << "dF^E/d" << names[q] << ", " << to_string(expected);
        EXPECT_NEAR(d.dh_dparameter[q], (p.hardening - m.hardening) / (2 * h), 1e-7 * std::max(1.0, std::abs(d.dh_dparameter[q])))
            << "da'/d" << names[q] << ", " << to_string(expected);
        EXPECT_LT((d.dP_dparameter[q] - fd_P).cwiseAbs().maxCoeff(), 1e-6 * std::max(1.0, fd_P.cwiseAbs().maxCoeff()))
            << "dPtilde/d" << names[q] << ", " << to_string(expected);
    }
    if (expected == ReturnBranch::Ellipse) {
        EXPECT_GT(d.dP_dparameter[static_cast<int>(PlasticityParameter::Xi)].cwiseAbs().maxCoeff(), 0.0);
        EXPECT_GT(std::abs(d.dh_dparameter[static_cast<int>(PlasticityParameter::Beta)]), 0.0);
    }
}

TEST(ReturnMapDerivative, CamClayMatchesCentralDifferencesOnItsBranches) {
    // a = -0.1 (the snow preset's): p0 = K sinh(0.05), the compression tip below J = 0.949, the tension tip
    // above J = 1.015; shear of 5% in log strain puts J = 0.98 on the ellipse, 0.5% inside.
    test::Random rng(31);
    const double a = -0.1;
    for (int trial = 0; trial < 3; ++trial) {
        const double shear = rng.uniform(0.04, 0.06), mean = std::log(0.98) / 2;
        check_snow<2>(Vec<2>(std::exp(mean + shear), std::exp(mean - shear)), a, ReturnBranch::Ellipse, rng);
        check_snow<2>(Vec<2>(std::exp(mean + 0.1 * shear), std::exp(mean - 0.1 * shear)), a, ReturnBranch::Elastic, rng);
        check_snow<2>(Vec<2>(0.95 * std::exp(shear), 0.95 * std::exp(-0.5 * shear)), a, ReturnBranch::CompressionTip,
                      rng);
        check_snow<2>(Vec<2>(1.02 * std::exp(0.3 * shear), 1.01), a, ReturnBranch::TensionTip, rng);
        const double mean3 = std::log(0.98) / 3;
        check_snow<3>(Vec<3>(std::exp(mean3 + shear), std::exp(mean3 - 0.3 * shear), std::exp(mean3 - 0.7 * shear)), a,
                      ReturnBranch::Ellipse, rng);
        check_snow<3>(Vec<3>(std::exp(mean3 + 0.05 * shear), std::exp(mean3), std::exp(mean3 - 0.05 * shear)), a,
                      ReturnBranch::Elastic, rng);
        check_snow<3>(Vec<3>(0.97 * std::exp(shear), 0.97, 0.97 * std::exp(-0.5 * shear)), a,
                      ReturnBranch::CompressionTip, rng);
    }
    // Two equal singular values on the ellipse (the pairs' quotients at their limit).
    const double shear = 0.06, mean3 = std::log(0.98) / 3;
    check_snow<3>(Vec<3>(std::exp(mean3 + shear), std::exp(mean3 + shear), std::exp(mean3 - 2 * shear)), a,
                  ReturnBranch::Ellipse, rng);
}

TEST(ReturnMapDerivative, IsOneSidedAtTheYieldOnsetAndRefusesWhatIsNotWritten) {
    // At L = h the mapping takes the elastic branch, and so does its derivative; just past it, the
    // plastic one.
    const Material<2> metal(material_preset("metal"));
    const Vec<2> s(1.04, 0.98);
    const double L = std::abs(std::log(s[0]) - std::log(s[1])) / std::sqrt(2.0);
    const PolarSVD<2> svd = clamped_svd<2>(Mat<2>(s.asDiagonal()));
    EXPECT_FALSE(return_map_derivative<2>(metal, svd, L).yielded);
    EXPECT_EQ(return_map_derivative<2>(metal, svd, L).dFE_dF, Tensor4<2>::Identity());
    EXPECT_TRUE(return_map_derivative<2>(metal, svd, L * (1.0 - 1e-9)).yielded);
    MaterialDescription paper_snow = material_preset("snow");
    paper_snow.cam_clay.variant = CamClayVariant::Paper;
    try {
        return_map_derivative<2>(Material<2>(paper_snow), svd, -0.1);
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("plasticity.variant 'paper'"), std::string::npos) << e.what();
    }
    EXPECT_THROW(return_map_derivative<2>(Material<2>(material_preset("metal_nh")), svd, 0.1), std::invalid_argument);
}

/// Sand (Drucker-Prager) at F = R1 diag(stretch) R2: dF^E/dF, and dF^E and Ptilde in the friction angle,
/// against central differences.
template <int dim>
void check_sand(const Vec<dim>& stretch, ReturnBranch expected, test::Random& rng, double step = 1e-7) {
    MaterialDescription sand = material_preset("sand");
    const Material<dim> material(sand);
    const Mat<dim> F = rotation<dim>(rng) * stretch.asDiagonal() * rotation<dim>(rng);
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    ASSERT_EQ(material.project(F, 0.0).branch, expected) << stretch.transpose();
    const ReturnMapDerivative<dim> d = return_map_derivative<dim>(material, svd, 0.0);
    EXPECT_EQ(d.yielded, expected != ReturnBranch::Elastic);
    double worst = 0.0;
    for (int k = 0; k < dim * dim; ++k) {
        Mat<dim> dF = Mat<dim>::Zero();
        dF(k / dim, k % dim) = step;
        const Eigen::Matrix<double, dim * dim, 1> fd = flatten<dim>(
            Mat<dim>((material.project(F + dF, 0.0).F_elastic - material.project(F - dF, 0.0).F_elastic) / (2 * step)));
        worst = std::max(worst, (d.dFE_dF.col(k) - fd).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(worst, 1e-6) << "dF^E/dF, " << to_string(expected) << ", stretch " << stretch.transpose();
    // The return-mapped stress's exact Jacobian (drucker_prager_tangent), its skew part kept.
    const Tensor4<dim> T = drucker_prager_tangent<dim>(material, svd);
    double worst_T = 0.0;
    for (int k = 0; k < dim * dim; ++k) {
        Mat<dim> dF = Mat<dim>::Zero();
        dF(k / dim, k % dim) = step;
        const Eigen::Matrix<double, dim * dim, 1> fd = flatten<dim>(
            Mat<dim>((material.elastoplastic_stress(F + dF, 0.0) - material.elastoplastic_stress(F - dF, 0.0)) /
                     (2 * step)));
        worst_T = std::max(worst_T, (T.col(k) - fd).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(worst_T, 1e-6 * std::max(1.0, T.cwiseAbs().maxCoeff())) << "dPtilde/dF, " << to_string(expected);
    const double angle = sand.drucker_prager.friction_angle_deg, h = 1e-4;
    MaterialDescription up = sand, down = sand;
    up.drucker_prager.friction_angle_deg = angle + h;
    down.drucker_prager.friction_angle_deg = angle - h;
    const Material<dim> plus(up), minus(down);
    const Mat<dim> fd_FE = (plus.project(F, 0.0).F_elastic - minus.project(F, 0.0).F_elastic) / (2 * h);
    const Mat<dim> fd_P = (plus.elastoplastic_stress(svd, 0.0) - minus.elastoplastic_stress(svd, 0.0)) / (2 * h);
    EXPECT_LT((d.dFE_dparameter[kAngle] - fd_FE).cwiseAbs().maxCoeff(), 1e-8 + 1e-6 * fd_FE.cwiseAbs().maxCoeff()) << "dF^E/dphi";
    EXPECT_EQ(return_map_derivative<dim>(material, svd, 0.0, false).dP_dparameter[kAngle], d.dP_dparameter[kAngle]);
    EXPECT_LT((d.dP_dparameter[kAngle] - fd_P).cwiseAbs().maxCoeff(), 1e-6 * std::max(1.0, fd_P.cwiseAbs().maxCoeff()))
        << "dPtilde/dphi";
    if (expected == ReturnBranch::Cone) {
        EXPECT_GT(d.dP_dparameter[kAngle].cwiseAbs().maxCoeff(), 0.0);
    }
}

TEST(ReturnMapDerivative, DruckerPragerMatchesCentralDifferencesOnItsBranches) {
    test::Random rng(13);
    for (int trial = 0; trial < 4; ++trial) {
        // Compression with shear beyond the cone, compression within it, and tension (the apex).
        const double shear = rng.uniform(0.03, 0.06), squeeze = rng.uniform(0.005, 0.01);
        check_sand<2>(Vec<2>(std::exp(shear - squeeze), std::exp(-shear - squeeze)), ReturnBranch::Cone, rng);
        check_sand<2>(Vec<2>(std::exp(0.001 - 0.02), std::exp(-0.001 - 0.02)), ReturnBranch::Elastic, rng);
        check_sand<2>(Vec<2>(std::exp(0.01 + shear), std::exp(0.01 - 0.5 * shear)), ReturnBranch::Apex, rng);
        check_sand<3>(Vec<3>(std::exp(shear - squeeze), std::exp(-0.3 * shear - squeeze), std::exp(-0.7 * shear - squeeze)),
                      ReturnBranch::Cone, rng);
        check_sand<3>(Vec<3>(std::exp(0.02), std::exp(0.01), std::exp(-0.005)), ReturnBranch::Apex, rng);
    }
}

TEST(ReturnMapDerivative, DruckerPragerTangentIsExactOnTheConeAtNearlyEqualSingularValues) {
    // Strains of 1e-5, as at a sand pile's free surface: principal strains under 1e-4 apart (within the
    // tangent's kCloseLog), beyond the cone. The limit of (tau_i - tau_j) / (Sigma_i - Sigma_j) from dtau/deps
    // is negative there (the cone's derivative taken across its edge at equal strains); the quotient is 2 mu k.
    // Differences of 1e-8, a thousandth of the distance to the branches' boundaries.
    test::Random rng(29);
    for (int trial = 0; trial < 4; ++trial) {
        const double shear = rng.uniform(3e-5, 4.5e-5), squeeze = rng.uniform(5e-6, 1e-5);
        check_sand<2>(Vec<2>(std::exp(shear - squeeze), std::exp(-shear - squeeze)), ReturnBranch::Cone, rng, 1e-8);
        check_sand<3>(Vec<3>(std::exp(shear - squeeze), std::exp(-0.2 * shear - squeeze),
                             std::exp(-0.8 * shear - squeeze)),
                      ReturnBranch::Cone, rng, 1e-8);
    }
}

}  // namespace
}  // namespace pnet
