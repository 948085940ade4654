// The PlasticityNet energy on the shipped models: grad Psi(F0) = E Ptilde(F0)
// by construction, derivatives against finite differences, the PSD
// projection, and the Python implementation (tests/data/energy_vectors_python.json,
// written by scripts/gen_energy_vectors.py) to 1e-10.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <fstream>
#include <iostream>
#include <optional>
#include <utility>
#include <nlohmann/json.hpp>

#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/math/psd.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/nn/model_file.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

const std::string kModels = PNET_MODELS_DIR;

template <int dim>
struct Batch {
    std::vector<Mat<dim>> F, F0;
    std::vector<double> h;
};

/// Particles near a reference: F0 = R1 diag(e^eps) R2 (|eps| <= 0.4), F = F0 + 0.03 G.
template <int dim>
Batch<dim> make_batch(const ModelMetadata& meta, std::size_t n, unsigned seed) {
    test::Random random(seed);
    Batch<dim> b;
    for (std::size_t p = 0; p < n; ++p) {
        b.F0.push_back(random.deformation<dim>(0.4));
        Mat<dim> G;
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) G(i, j) = random.uniform(-1.0, 1.0);
        b.F.push_back(b.F0.back() + 0.03 * G);
        const auto plasticity = meta.material.plasticity;
        b.h.push_back(plasticity == PlasticityModel::VonMises  ? random.uniform(0.02, 0.5)
                      : plasticity == PlasticityModel::CamClay ? random.uniform(-0.5, 0.0)
                                                               : 0.0);
    }
    return b;
}

template <int dim>
Eigen::Matrix<double, dim * dim, 1> as_vec(const Mat<dim>& A) {
    return flatten<dim>(A);
}

/// material: the object's (a parametric model's parameters); unset, the model's own.
template <int dim>
void check_model(const std::string& file, const std::optional<MaterialDescription>& material = std::nullopt) {
    SCOPED_TRACE(file);
    constexpr int m = dim * dim;
    const ModelFile model = load_model_file(kModels + "/" + file);
    const double E = 3.0e5;
    typename NeuralElastoplasticEnergy<dim>::Options options{E, 1.0};
    options.material = material;
    NeuralElastoplasticEnergy<dim> energy(model, options);
    const std::size_t n = 9;
    Batch<dim> b = make_batch<dim>(model.metadata, n, 17);
    energy.set_reference(b.F0.data(), b.h.data(), n);

    // grad Psi(F0) = E Ptilde(F0, h), exactly up to round-off (eq. 8; the rejected forms of the
    // ablation models do not have it: RejectedEnergyForms).
    std::vector<double> psi(n);
    std::vector<Mat<dim>> grad(n);
    energy.value_gradient(b.F0.data(), psi.data(), grad.data());
    for (std::size_t p = 0; p < n && model.metadata.energy_form == EnergyForm::Eq8; ++p) {
        const Mat<dim> P = energy.elastoplastic_stress(b.F0[p], b.h[p]);
        EXPECT_LE((grad[p] - P).cwiseAbs().maxCoeff(), 1e-10 * P.cwiseAbs().maxCoeff()) << "particle " << p;
    }

    // Value, gradient and Hessian of the three entry points agree.
    std::vector<Tensor4<dim>> hess(n), hess_psd(n);
    std::vector<double> psi1(n), psi2(n);
    std::vector<Mat<dim>> grad2(n);
    energy.value(b.F.data(), psi.data());
    energy.value_gradient(b.F.data(), psi1.data(), grad.data());
    energy.value_gradient_hessian(b.F.data(), psi2.data(), grad2.data(), hess.data(), false);
    EXPECT_EQ(psi, psi1);
    EXPECT_EQ(psi, psi2);
    EXPECT_EQ(grad, grad2);

    // Finite differences, particle by particle (the other particles fixed).
    test::FdStats stats;
    for (std::size_t p = 0; p < n; ++p) {
        auto at = [&](const Eigen::VectorXd& v) {
            std::vector<Mat<dim>> F = b.F;
            F[p] = unflatten<dim>(v);
            return F;
        };
        auto value = [&](const Eigen::VectorXd& v) {
            std::vector<double> out(n);
            energy.value(at(v).data(), out.data());
            return out[p];
        };
        auto gradient = [&](const Eigen::VectorXd& v) {
            std::vector<double> out(n);
            std::vector<Mat<dim>> g(n);
            energy.value_gradient(at(v).data(), out.data(), g.data());
            return Eigen::VectorXd(as_vec<dim>(g[p]));
        };
        const Eigen::VectorXd x = as_vec<dim>(b.F[p]);
        // Step 1e-5 for the value: Psi is a difference of O(E) terms (eq. 8), so at 1e-6 the
        // round-off of the quotient (eps |Psi| / h) reaches the 1e-6 tolerance on metal_3d.
        EXPECT_TRUE(test::check_gradient(value, as_vec<dim>(grad[p]), x, stats, 1e-5, 1e-6, 1e-3 * E));
        EXPECT_TRUE(test::check_jacobian(gradient, Eigen::MatrixXd(hess[p]), x, stats, 1e-6, 1e-6, 1e-3 * E));
    }
    EXPECT_EQ(stats.checks, static_cast<int>(n) * (m + m * m));

    // PSD projection: no negative eigenvalue; a PSD Hessian is left as it is.
    energy.value_gradient_hessian(b.F.data(), psi2.data(), grad2.data(), hess_psd.data(), true);
    for (std::size_t p = 0; p < n; ++p) {
        const double scale = hess[p].cwiseAbs().maxCoeff();
        Eigen::SelfAdjointEigenSolver<Tensor4<dim>> raw(hess[p]), projected(hess_psd[p]);
        EXPECT_GE(projected.eigenvalues().minCoeff(), -1e-12 * scale) << "particle " << p;
        if (raw.eigenvalues().minCoeff() >= 0.0) {
            EXPECT_LE((hess_psd[p] - hess[p]).cwiseAbs().maxCoeff(), 1e-12 * scale) << "particle " << p;
        }
        // Projecting again changes nothing.
        const Tensor4<dim> twice = project_psd<m>(hess_psd[p]);
        EXPECT_LE((twice - hess_psd[p]).cwiseAbs().maxCoeff(), 1e-12 * scale) << "particle " << p;
    }
}

// Relative to the reference (the integrators' form), eq. 8 at F = F0 exactly is psi = 0 and
// grad = E Ptilde(F0) without a network pass; away from it, the network's correction is computed
// when first needed, and the energy equals the absolute one less Psi(F0), with the same gradient.
template <int dim>
void check_relative_to_reference(const std::string& file) {
    SCOPED_TRACE(file);
    const ModelFile model = load_model_file(kModels + "/" + file);
    const double E = 3.0e5;
    using Options = typename NeuralElastoplasticEnergy<dim>::Options;
    NeuralElastoplasticEnergy<dim> relative(model, Options{E, 1.0, true});
    NeuralElastoplasticEnergy<dim> absolute(model, Options{E, 1.0, false});
    const std::size_t n = 9;
    const Batch<dim> b = make_batch<dim>(model.metadata, n, 23);
    relative.set_reference(b.F0.data(), b.h.data(), n);
    absolute.set_reference(b.F0.data(), b.h.data(), n);
    std::vector<double> psi(n), psi_abs(n), psi0_abs(n);
    std::vector<Mat<dim>> grad(n), grad_abs(n);
    auto at_reference_is_the_stress = [&](const char* when) {
        relative.value_gradient(b.F0.data(), psi.data(), grad.data());
        for (std::size_t p = 0; p < n; ++p) {
            EXPECT_EQ(psi[p], 0.0) << when << ", particle " << p;
            EXPECT_EQ(grad[p], relative.elastoplastic_stress(b.F0[p], b.h[p])) << when << ", particle " << p;
        }
    };
    at_reference_is_the_stress("first");
    relative.value_gradient(b.F.data(), psi.data(), grad.data());  // off the reference
    absolute.value_gradient(b.F.data(), psi_abs.data(), grad_abs.data());
    absolute.value(b.F0.data(), psi0_abs.data());
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_NEAR(psi[p], psi_abs[p] - psi0_abs[p], 1e-9 * E) << "particle " << p;
        EXPECT_LE((grad[p] - grad_abs[p]).cwiseAbs().maxCoeff(), 1e-9 * E) << "particle " << p;
        EXPECT_NE(psi[p], 0.0) << "particle " << p;
    }
    EXPECT_LE((relative.correction(0) - absolute.correction(0)).cwiseAbs().maxCoeff(), 1e-12 * E);
    at_reference_is_the_stress("after an evaluation away from it");
}

TEST(NeuralElastoplasticEnergy, RelativeToTheReferenceNeedsNoNetworkAtIt) {
    check_relative_to_reference<2>("metal_2d.pt");
    check_relative_to_reference<2>("metal_nh_2d.pt");  // the learned return mapping
    check_relative_to_reference<2>("sand_2d.pt");
    check_relative_to_reference<3>("snow_3d.pt");
}

// Each shipped model, one test a model.
TEST(NeuralElastoplasticEnergy, Sand2d) { check_model<2>("sand_2d.pt"); }
TEST(NeuralElastoplasticEnergy, Snow2d) { check_model<2>("snow_2d.pt"); }
TEST(NeuralElastoplasticEnergy, Metal2d) { check_model<2>("metal_2d.pt"); }
TEST(NeuralElastoplasticEnergy, MetalNeoHookeanLearnedReturnMap2d) { check_model<2>("metal_nh_2d.pt"); }
TEST(NeuralElastoplasticEnergy, Sand3d) { check_model<3>("sand_3d.pt"); }
TEST(NeuralElastoplasticEnergy, Snow3d) { check_model<3>("snow_3d.pt"); }
TEST(NeuralElastoplasticEnergy, Metal3d) { check_model<3>("metal_3d.pt"); }

// A parametric model at the ends of its ranges and inside: exact at F0 for that material, derivatives
// against finite differences.
TEST(NeuralElastoplasticEnergy, SandParametric2d) {
    for (const auto& [angle, nu] : {std::pair{20.0, 0.2}, std::pair{45.0, 0.45}, std::pair{33.0, 0.27}}) {
        SCOPED_TRACE(std::to_string(angle) + " deg, nu " + std::to_string(nu));
        MaterialDescription sand = material_preset("sand");
        sand.drucker_prager.friction_angle_deg = angle;
        sand.elastic.nu = nu;
        check_model<2>("sand_param_2d.pt", sand);
    }
}

// The models of the energy-representation ablation (models/ablation/, paper sec. 5.2, Fig. 11):
// derivatives against finite differences, and each form's defining property.
TEST(NeuralElastoplasticEnergy, AblationModelsDerivatives) {
    for (const char* form : {"eq8", "local_identity", "global_identity", "global"})
        check_model<2>(std::string("ablation/sand_2d_") + form + ".pt");
}

TEST(NeuralElastoplasticEnergy, RejectedEnergyForms) {
    const double E = 3.0e5;
    const std::size_t n = 7;
    for (const EnergyForm form :
         {EnergyForm::Eq8, EnergyForm::LocalIdentity, EnergyForm::GlobalIdentity, EnergyForm::Global}) {
        const std::string file = kModels + "/ablation/sand_2d_" + to_string(form) + ".pt";
        SCOPED_TRACE(file);
        const ModelFile model = load_model_file(file);
        ASSERT_EQ(model.metadata.energy_form, form);
        NeuralElastoplasticEnergy<2> energy(model, {E, 0.0});  // w = 0: the form alone
        Batch<2> b = make_batch<2>(model.metadata, n, 5);
        energy.set_reference(b.F0.data(), b.h.data(), n);
        std::vector<double> psi(n);
        std::vector<Mat<2>> at_F0(n), at_I(n), at_F(n), at_F_other(n);
        const std::vector<Mat<2>> identity(n, Mat<2>::Identity());
        energy.value_gradient(b.F0.data(), psi.data(), at_F0.data());
        energy.value_gradient(identity.data(), psi.data(), at_I.data());
        energy.value_gradient(b.F.data(), psi.data(), at_F.data());
        // The same F with other references (the batch's F0 in reverse order).
        std::vector<Mat<2>> F0_other(b.F0.rbegin(), b.F0.rend());
        energy.set_reference(F0_other.data(), b.h.data(), n);
        energy.value_gradient(b.F.data(), psi.data(), at_F_other.data());
        double F0_error = 0.0, I_stress = 0.0, F0_dependence = 0.0, scale = 0.0;
        for (std::size_t p = 0; p < n; ++p) {
            const Mat<2> P = energy.elastoplastic_stress(b.F0[p], b.h[p]);
            scale = std::max(scale, P.cwiseAbs().maxCoeff());
            F0_error = std::max(F0_error, (at_F0[p] - P).cwiseAbs().maxCoeff());
            I_stress = std::max(I_stress, at_I[p].cwiseAbs().maxCoeff());
            F0_dependence = std::max(F0_dependence, (at_F[p] - at_F_other[p]).cwiseAbs().maxCoeff());
        }
        // Eq. 8 alone reproduces Ptilde(F0) at F = F0 by construction.
        if (form == EnergyForm::Eq8)
            EXPECT_LE(F0_error, 1e-10 * scale);
        else
            EXPECT_GT(F0_error, 1e-4 * scale);
        // The *_identity forms have zero stress at F = I whatever F0.
        if (form == EnergyForm::LocalIdentity || form == EnergyForm::GlobalIdentity) {
            EXPECT_LE(I_stress, 1e-10 * E);
        }
        // The global forms do not depend on F0 (at w = 0); the local ones do.
        if (form == EnergyForm::GlobalIdentity || form == EnergyForm::Global)
            EXPECT_LE(F0_dependence, 1e-10 * scale);
        else
            EXPECT_GT(F0_dependence, 1e-4 * scale);
        if (form == EnergyForm::Global) {
            EXPECT_EQ(energy.correction(0), Mat<2>::Zero());
        }
    }
}

TEST(ModelMetadata, UnknownEnergyFormIsRefusedNamingTheField) {
    const ModelFile model = load_model_file(kModels + "/sand_2d.pt");
    nlohmann::json j = model.metadata.json;
    EXPECT_EQ(parse_model_metadata(j, "m.pt").energy_form, EnergyForm::Eq8);  // no field: eq. 8
    j["energy_form"] = "global";
    EXPECT_EQ(parse_model_metadata(j, "m.pt").energy_form, EnergyForm::Global);
    j["energy_form"] = "eq9";
    try {
        parse_model_metadata(j, "m.pt");
        FAIL() << "accepted energy_form eq9";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("m.pt"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("energy_form"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("\"eq9\""), std::string::npos) << e.what();
    }
}

// A parametric energy's "parameters" (issue 36): read in input order, and every malformed entry
// refused naming the file and the field.
TEST(ModelMetadata, ParametersAreReadAndCheckedNamingTheField) {
    const ModelFile model = load_model_file(kModels + "/sand_2d.pt");  // principal, 6 inputs, no hardening
    nlohmann::json j = model.metadata.json;
    j["widths"][0] = 8;
    j["input_width"] = 8;
    j["parameters"] = {{{"field", "plasticity.friction_angle_deg"}, {"min", 20.0}, {"max", 45.0}},
                       {{"field", "elasticity.nu"}, {"min", 0.2}, {"max", 0.45}}};
    const ModelMetadata meta = parse_model_metadata(j, "m.pt");
    ASSERT_EQ(meta.parameter_count(), 2);
    EXPECT_EQ(meta.parameters[0].field, "plasticity.friction_angle_deg");
    EXPECT_EQ(meta.parameters[1].max, 0.45);
    EXPECT_EQ(meta.forward_input_width(), 10);
    EXPECT_DOUBLE_EQ(meta.parameters[0].input(20.0), -1.0);
    EXPECT_DOUBLE_EQ(meta.parameters[0].input(45.0), 1.0);
    auto message = [&](const nlohmann::json& bad) {
        try {
            parse_model_metadata(bad, "m.pt");
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    nlohmann::json bad = j;
    bad["parameters"][1]["field"] = "plasticity.xi";  // a Cam-Clay field on a Drucker-Prager model
    EXPECT_EQ(message(bad), "m.pt: metadata.parameters[1].field: \"plasticity.xi\" is not a parameter of the "
                            "material's models (stvk_hencky, drucker_prager)");
    bad = j;
    bad["parameters"][0]["max"] = 10.0;
    EXPECT_EQ(message(bad), "m.pt: metadata.parameters[0]: the range [20.0, 10.0] must be finite with min < max");
    bad = j;
    bad["parameters"][1]["field"] = "plasticity.friction_angle_deg";
    EXPECT_EQ(message(bad), "m.pt: metadata.parameters[1].field: \"plasticity.friction_angle_deg\" is listed twice");
    bad = j;
    bad["parameters"][1].erase("min");
    EXPECT_NE(message(bad).find("m.pt: metadata.parameters[1]: expected {\"field\""), std::string::npos);
    bad = j;
    bad["parameters"].erase(1);  // 8 inputs do not fit [vec G, Sigma0] and one parameter
    EXPECT_NE(message(bad).find("m.pt: metadata.input_width: 8: a 2D principal energy without hardening takes "
                                "[vec G, Sigma0, 1 parameters], 7 inputs"),
              std::string::npos)
        << message(bad);
}

TEST(NeuralElastoplasticEnergy, ProjectionClampsNegativeEigenvalues) {
    // Strong compression makes the learned Hessian indefinite for some particles;
    // count them so that the clamp is known to have been exercised.
    const ModelFile model = load_model_file(kModels + "/sand_2d.pt");
    NeuralElastoplasticEnergy<2> energy(model, {1.0, 0.0});
    test::Random random(5);
    const std::size_t n = 200;
    std::vector<Mat<2>> F(n), F0(n);
    for (std::size_t p = 0; p < n; ++p) {
        F0[p] = random.deformation<2>(1.0);
        F[p] = random.deformation<2>(1.0);
    }
    std::vector<double> h(n, 0.0), psi(n);
    energy.set_reference(F0.data(), h.data(), n);
    std::vector<Mat<2>> grad(n);
    std::vector<Tensor4<2>> raw(n), psd(n);
    energy.value_gradient_hessian(F.data(), psi.data(), grad.data(), raw.data(), false);
    energy.value_gradient_hessian(F.data(), psi.data(), grad.data(), psd.data(), true);
    int indefinite = 0;
    for (std::size_t p = 0; p < n; ++p) {
        Eigen::SelfAdjointEigenSolver<Tensor4<2>> a(raw[p]), b(psd[p]);
        const double scale = raw[p].cwiseAbs().maxCoeff();
        if (a.eigenvalues().minCoeff() < -1e-8 * scale) {
            ++indefinite;
            // Eigenvalues: the negative ones become 0, the others stay.
            for (int k = 0; k < 4; ++k)
                EXPECT_NEAR(b.eigenvalues()[k], std::max(0.0, a.eigenvalues()[k]), 1e-10 * scale);
        }
        EXPECT_GE(b.eigenvalues().minCoeff(), -1e-12 * scale);
    }
    EXPECT_GT(indefinite, 0) << "no indefinite Hessian among " << n << " far-from-reference particles";
}

TEST(NeuralElastoplasticEnergy, RejectsBadConfiguration) {
    const ModelFile model = load_model_file(kModels + "/sand_2d.pt");
    EXPECT_THROW((NeuralElastoplasticEnergy<3>(model, {1.0, 1.0})), std::invalid_argument);
    EXPECT_THROW((NeuralElastoplasticEnergy<2>(model, {-1.0, 1.0})), std::invalid_argument);
    EXPECT_THROW((NeuralElastoplasticEnergy<2>(model, {1.0, -1.0})), std::invalid_argument);
    NeuralElastoplasticEnergy<2>::Options negative_reuse{1.0, 1.0};
    negative_reuse.network_reuse = -1e-3;
    EXPECT_THROW((NeuralElastoplasticEnergy<2>(model, negative_reuse)), std::invalid_argument);
    const ModelFile rm = load_model_file(kModels + "/metal_nh_rm_2d.pt");
    EXPECT_THROW((NeuralElastoplasticEnergy<2>(rm, {1.0, 1.0})), std::invalid_argument);
}

// The network's hardening input is h = min(a, 0) for Cam-Clay (paper A.2.2,
// docs/physics.md), clamped to the range the model was trained on (snow_2d:
// [-0.5, 0]); Ptilde(F0, a) in c keeps the state itself, so grad Psi(F0) stays
// exactly E Ptilde(F0, a). A raw state a > 0 (28-35% of a snowball's particles
// after impact) or a < -0.5 would be an input the network never saw.
TEST(NeuralElastoplasticEnergy, HardeningInputIsMinOfTheStateClampedToTheTrainedRange) {
    const ModelFile model = load_model_file(kModels + "/snow_2d.pt");
    EXPECT_EQ(model.metadata.hardening_min, -0.5);
    EXPECT_EQ(model.metadata.hardening_max, 0.0);
    const double E = 1.4e5;
    NeuralElastoplasticEnergy<2> energy(model, {E, 1.0});
    const Batch<2> b = make_batch<2>(model.metadata, 6, 31);
    const std::size_t n = b.F.size();
    // The same particles at four states: a > 0 against a = 0, a < -0.5 against a = -0.5.
    const std::vector<std::pair<double, double>> states = {{2.0, 0.0}, {6.45, 0.0}, {-1.29, -0.5}, {-3.0, -0.5}};
    for (const auto& [outside, inside] : states) {
        SCOPED_TRACE("a = " + std::to_string(outside));
        std::vector<double> h_out(n, outside), h_in(n, inside), psi_out(n), psi_in(n);
        std::vector<Mat<2>> g_out(n), g_in(n);
        energy.set_reference(b.F0.data(), h_out.data(), n);
        energy.value_gradient(b.F.data(), psi_out.data(), g_out.data());
        EXPECT_EQ(energy.hardening_clamped(), outside < -0.5 ? n : 0u) << "only a < -0.5 is outside [-0.5, 0]";
        energy.set_reference(b.F0.data(), h_in.data(), n);
        energy.value_gradient(b.F.data(), psi_in.data(), g_in.data());
        EXPECT_EQ(energy.hardening_clamped(), 0u);
        for (std::size_t p = 0; p < n; ++p) {
            // The network sees the same input, so grad Psi(F) - E Ptilde(F0, a) is the same.
            const Mat<2> d_out = g_out[p] - energy.elastoplastic_stress(b.F0[p], outside);
            const Mat<2> d_in = g_in[p] - energy.elastoplastic_stress(b.F0[p], inside);
            EXPECT_LE((d_out - d_in).cwiseAbs().maxCoeff(), 1e-9 * E) << "particle " << p;
        }
    }
    // Inside the range the input is the state itself: a = -0.2 differs from a = 0.
    std::vector<double> h0(n, 0.0), h1(n, -0.2), psi0(n), psi1(n);
    std::vector<Mat<2>> g0(n), g1(n);
    energy.set_reference(b.F0.data(), h0.data(), n);
    energy.value_gradient(b.F.data(), psi0.data(), g0.data());
    energy.set_reference(b.F0.data(), h1.data(), n);
    energy.value_gradient(b.F.data(), psi1.data(), g1.data());
    double differ = 0.0;
    for (std::size_t p = 0; p < n; ++p)
        differ = std::max(differ, ((g1[p] - energy.elastoplastic_stress(b.F0[p], -0.2)) -
                                   (g0[p] - energy.elastoplastic_stress(b.F0[p], 0.0)))
                                      .cwiseAbs()
                                      .maxCoeff());
    EXPECT_GT(differ, 1e-6 * E) << "the hardening input changes the network's output";
}

// Relative to the reference, Psi(F) - Psi(F0): the same gradient and Hessian,
// and 0 at F0 instead of a constant of the size of the energy density.
TEST(NeuralElastoplasticEnergy, RelativeToTheReferenceShiftsOnlyTheValue) {
    const ModelFile model = load_model_file(kModels + "/sand_2d.pt");
    NeuralElastoplasticEnergy<2> paper(model, {3.5e5, 1.0}), relative(model, {3.5e5, 1.0, true});
    const Batch<2> b = make_batch<2>(model.metadata, 8, 5);
    const std::size_t n = b.F.size();
    paper.set_reference(b.F0.data(), b.h.data(), n);
    relative.set_reference(b.F0.data(), b.h.data(), n);
    std::vector<double> a(n), r(n), a0(n), r0(n);
    std::vector<Mat<2>> ga(n), gr(n);
    paper.value(b.F0.data(), a0.data());
    relative.value(b.F0.data(), r0.data());
    paper.value_gradient(b.F.data(), a.data(), ga.data());
    relative.value_gradient(b.F.data(), r.data(), gr.data());
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_EQ(r0[p], 0.0);
        EXPECT_GT(std::abs(a0[p]), 1.0) << "the paper's Psi(F0) is a large constant (J/m^3)";
        EXPECT_NEAR(r[p], a[p] - a0[p], 1e-9 * std::abs(a0[p]));
        EXPECT_TRUE(gr[p] == ga[p]);
    }
}

// The first evaluation at F = F0 after set_reference reuses set_reference's own network pass (the fixed
// point's next solve starts there): value and gradient are bitwise those of a fresh pass, and an
// evaluation elsewhere in between, or a hardening change, is not mistaken for one at the reference.
TEST(NeuralElastoplasticEnergy, EvaluationAtTheReferenceEqualsAFreshPass) {
    const ModelFile model = load_model_file(kModels + "/snow_2d.pt");
    NeuralElastoplasticEnergy<2> cached(model, {1.4e5, 1.0}), fresh(model, {1.4e5, 1.0});
    const Batch<2> b = make_batch<2>(model.metadata, 8, 7);
    const std::size_t n = b.F.size();
    cached.set_reference(b.F0.data(), b.h.data(), n);
    fresh.set_reference(b.F0.data(), b.h.data(), n);
    std::vector<double> psi_cached(n), psi_fresh(n), psi_other(n);
    std::vector<Mat<2>> g_cached(n), g_fresh(n), g_other(n);
    fresh.value_gradient(b.F.data(), psi_other.data(), g_other.data());  // moves fresh's buffers off F0
    fresh.value_gradient(b.F0.data(), psi_fresh.data(), g_fresh.data());
    cached.value_gradient(b.F0.data(), psi_cached.data(), g_cached.data());
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_EQ(psi_cached[p], psi_fresh[p]);
        EXPECT_TRUE(g_cached[p] == g_fresh[p]);
    }
    // After an evaluation at F the buffers are F's: a later call at F0 must not see F's values.
    cached.value_gradient(b.F.data(), psi_other.data(), g_other.data());
    cached.value_gradient(b.F0.data(), psi_cached.data(), g_cached.data());
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_EQ(psi_cached[p], psi_fresh[p]);
        EXPECT_TRUE(g_cached[p] == g_fresh[p]);
    }
    // A new reference with other hardening at the same F0: its pass, not the old one.
    std::vector<double> h2 = b.h;
    for (double& h : h2) h += 0.05;
    cached.set_reference(b.F0.data(), h2.data(), n);
    fresh.set_reference(b.F0.data(), h2.data(), n);
    fresh.value_gradient(b.F.data(), psi_other.data(), g_other.data());
    fresh.value_gradient(b.F0.data(), psi_fresh.data(), g_fresh.data());
    cached.value(b.F0.data(), psi_cached.data());
    for (std::size_t p = 0; p < n; ++p) EXPECT_EQ(psi_cached[p], psi_fresh[p]);
}

// The rebased Newton's pass at its iterate (F = F0, relative to the reference) in single precision:
// Newton's Hessian within float's rounding of the double one, in one float pass (the double energy's
// pass is double); value and gradient at F0 exactly 0 and E Ptilde(F0) (to double's rounding) as
// before. The line search's trial points from there are float passes of the change N(F) - N(F0):
// within 1e-6 E t of the double energy's values down to changes of 1e-7, where a float N(F) - N(F0)
// would be all rounding; one pass each. A Newton iterate off the reference (the paper's fixed point)
// makes the next values double again, with N(F0) then taken in double once.
template <int dim>
void check_single_precision_hessian(const std::string& file) {
    SCOPED_TRACE(file);
    constexpr int m = dim * dim;
    const ModelFile model = load_model_file(kModels + "/" + file);
    const double E = 3.0e5;
    using Options = typename NeuralElastoplasticEnergy<dim>::Options;
    Options exact_options{E, 0.1, true};
    Options single_options = exact_options;
    single_options.hessian_precision = FusedMlp::Precision::Single;
    NeuralElastoplasticEnergy<dim> exact(model, exact_options), single(model, single_options);
    const std::size_t n = 21;
    const Batch<dim> b = make_batch<dim>(model.metadata, n, 31);
    exact.set_reference(b.F0.data(), b.h.data(), n);
    single.set_reference(b.F0.data(), b.h.data(), n);
    std::vector<double> psi(n), psi_single(n);
    std::vector<Mat<dim>> grad(n), grad_single(n);
    std::vector<Tensor4<dim>> H(n), H_single(n);
    exact.value_gradient_hessian(b.F0.data(), psi.data(), grad.data(), H.data(), false);
    single.value_gradient_hessian(b.F0.data(), psi_single.data(), grad_single.data(), H_single.data(), false);
    EXPECT_EQ(exact.network_passes(), 1);
    EXPECT_EQ(single.network_passes(), 1);
    double hessian_difference = 0.0;
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_EQ(psi_single[p], 0.0);
        // grad N(F0) - c = Ptilde(F0) up to double's rounding, whichever precision grad N(F0) had.
        const Mat<dim> P = single.elastoplastic_stress(b.F0[p], b.h[p]);
        EXPECT_LE((grad_single[p] - P).cwiseAbs().maxCoeff(), 1e-12 * E) << "particle " << p;
        EXPECT_LE((grad[p] - P).cwiseAbs().maxCoeff(), 1e-12 * E) << "particle " << p;
        hessian_difference = std::max(hessian_difference, (H_single[p] - H[p]).cwiseAbs().maxCoeff() /
                                                              H[p].cwiseAbs().maxCoeff());
        EXPECT_FALSE(H_single[p].isApprox(H[p], 1e-12)) << "particle " << p << ": not float arithmetic";
    }
    EXPECT_LT(hessian_difference, 1e-4);
    EXPECT_EQ(static_cast<int>(H[0].rows()), m);
    // Values along the line search's segment F0 + t (F - F0): the same energy but for the slope.
    long passes = single.network_passes();
    for (double t : {1.0, 0.1, 1e-3, 1e-5, 1e-7}) {
        std::vector<Mat<dim>> Ft(n);
        for (std::size_t p = 0; p < n; ++p) Ft[p] = b.F0[p] + t * (b.F[p] - b.F0[p]);
        exact.value(Ft.data(), psi.data());
        single.value(Ft.data(), psi_single.data());
        EXPECT_EQ(single.network_passes(), ++passes) << "t " << t << ": one pass of the change";
        // c's float gradient shifts the slope: |psi_single - psi| <= |delta c| |F - F0| E, with
        // |F - F0| <= 0.06 t here and |delta c| of float's rounding of grad N; the change's own
        // error is of the same order.
        for (std::size_t p = 0; p < n; ++p)
            EXPECT_NEAR(psi_single[p], psi[p], 1e-6 * E * t) << "t " << t << ", particle " << p;
    }
    // An iterate off the reference: its values, and the trial values after it, are double passes
    // with a double N(F0) (one extra pass, once), as the double energy's.
    std::vector<Mat<dim>> Fh(n);
    for (std::size_t p = 0; p < n; ++p) Fh[p] = b.F0[p] + 0.5 * (b.F[p] - b.F0[p]);
    exact.value_gradient(Fh.data(), psi.data(), grad.data());
    single.value_gradient(Fh.data(), psi_single.data(), grad_single.data());
    EXPECT_EQ(single.network_passes(), passes + 2);
    for (std::size_t p = 0; p < n; ++p) EXPECT_NEAR(psi_single[p], psi[p], 1e-6 * E) << "particle " << p;
    exact.value(b.F.data(), psi.data());
    single.value(b.F.data(), psi_single.data());
    EXPECT_EQ(single.network_passes(), passes + 3);
    for (std::size_t p = 0; p < n; ++p) EXPECT_NEAR(psi_single[p], psi[p], 1e-6 * E) << "particle " << p;
}

TEST(NeuralElastoplasticEnergy, SinglePrecisionHessianAtTheReference) {
    check_single_precision_hessian<2>("sand_2d.pt");
    check_single_precision_hessian<2>("metal_2d.pt");
    check_single_precision_hessian<3>("snow_3d.pt");
}

// Options::network_reuse (the rebased Newton's passes at the reference, in float): a particle whose
// reference moved less than the tolerance keeps the Hessian of its last network pass and is not
// evaluated again, its gradient at the reference still E Ptilde(F0) exactly; a particle that moved
// farther is evaluated as without reuse. A line search's trial point within the tolerance of the
// reference is valued by the energy's second-order expansion, one farther by the network.
// A kept Hessian's particle valued by the network takes its c from a gradient pass first (the kept
// Hessian cannot extrapolate grad N(F0): it does not see the change of the network's F0 input).
template <int dim>
void check_network_reuse(const std::string& file) {
    const double shift = 4e-4;
    SCOPED_TRACE(file);
    const ModelFile model = load_model_file(kModels + "/" + file);
    const double E = 3.0e5, tolerance = 1e-3;
    using Options = typename NeuralElastoplasticEnergy<dim>::Options;
    Options every_options{E, 0.1, true};
    every_options.hessian_precision = FusedMlp::Precision::Single;
    Options reuse_options = every_options;
    reuse_options.network_reuse = tolerance;
    NeuralElastoplasticEnergy<dim> every(model, every_options), reuse(model, reuse_options);
    const std::size_t n = 20, half = n / 2;
    const Batch<dim> b = make_batch<dim>(model.metadata, n, 41);
    std::vector<double> psi(n), psi_reuse(n);
    std::vector<Mat<dim>> grad(n), grad_reuse(n);
    std::vector<Tensor4<dim>> H(n), H_reuse(n), H_first(n);
    every.set_reference(b.F0.data(), b.h.data(), n);
    reuse.set_reference(b.F0.data(), b.h.data(), n);
    every.value_gradient_hessian(b.F0.data(), psi.data(), grad.data(), H.data(), false);
    reuse.value_gradient_hessian(b.F0.data(), psi_reuse.data(), grad_reuse.data(), H_first.data(), false);
    EXPECT_EQ(reuse.network_rows(), static_cast<long>(n)) << "nothing cached yet: every particle";
    for (std::size_t p = 0; p < n; ++p)
        EXPECT_LE((H_first[p] - H[p]).cwiseAbs().maxCoeff(), 1e-12 * H[p].cwiseAbs().maxCoeff()) << p;

    // The next reference: the first half moved `shift` (within the tolerance), the second half 4e-3.
    std::vector<Mat<dim>> F0(n);
    for (std::size_t p = 0; p < n; ++p) F0[p] = b.F0[p] + Mat<dim>::Constant(p < half ? shift : 4e-3);
    every.set_reference(F0.data(), b.h.data(), n);
    reuse.set_reference(F0.data(), b.h.data(), n);
    every.value_gradient_hessian(F0.data(), psi.data(), grad.data(), H.data(), false);
    reuse.value_gradient_hessian(F0.data(), psi_reuse.data(), grad_reuse.data(), H_reuse.data(), false);
    EXPECT_EQ(reuse.network_rows(), static_cast<long>(n + half)) << "only the particles that moved farther";
    EXPECT_EQ(reuse.network_rows_without_reuse(), static_cast<long>(2 * n));
    for (std::size_t p = 0; p < n; ++p) {
        const Mat<dim> P = reuse.elastoplastic_stress(F0[p], b.h[p]);
        EXPECT_EQ(psi_reuse[p], 0.0);
        EXPECT_LE((grad_reuse[p] - P).cwiseAbs().maxCoeff(), 1e-12 * E) << "particle " << p;
        const Tensor4<dim>& expected = p < half ? H_first[p] : H[p];  // kept, or taken again
        EXPECT_LE((H_reuse[p] - expected).cwiseAbs().maxCoeff(), 1e-12 * expected.cwiseAbs().maxCoeff()) << p;
    }

    // Trial points within the tolerance: every particle valued by the expansion, no pass; its error is
    // the cubic term and the kept Hessian's change over the shift, a fraction of the quadratic term.
    // Beyond it: every particle valued by the network, the same value as without reuse (to float's
    // rounding of c), after one gradient pass over the kept particles for their c.
    for (double t : {1e-2, 1.0}) {
        std::vector<Mat<dim>> Ft(n);
        double largest_step = 0.0;
        for (std::size_t p = 0; p < n; ++p) {
            Ft[p] = F0[p] + t * (b.F[p] - b.F0[p]);
            largest_step = std::max(largest_step, (Ft[p] - F0[p]).cwiseAbs().maxCoeff());
        }
        const long rows = reuse.network_rows();
        every.value(Ft.data(), psi.data());
        reuse.value(Ft.data(), psi_reuse.data());
        const bool near = largest_step <= tolerance;
        EXPECT_EQ(near, t == 1e-2);
        EXPECT_EQ(reuse.network_rows(), rows + (near ? 0L : static_cast<long>(n + half))) << "t " << t;
        for (std::size_t p = 0; p < n; ++p) {
            const auto dF = flatten<dim>(Ft[p] - F0[p]);
            const double quadratic = 0.5 * std::abs(dF.dot(H[p] * dF));
            EXPECT_NEAR(psi_reuse[p], psi[p], (near ? 0.05 * quadratic : 0.0) + 1e-6 * E * t)
                << "t " << t << ", particle " << p;
        }
    }
}

TEST(NeuralElastoplasticEnergy, NetworkReuseWithinItsTolerance) {
    check_network_reuse<2>("sand_2d.pt");
    check_network_reuse<2>("metal_2d.pt");
    check_network_reuse<3>("snow_3d.pt");
}

// --- Python cross-check ----------------------------------------------------------

template <int dim>
Mat<dim> mat_from(const nlohmann::json& j) {
    Mat<dim> A;
    for (int i = 0; i < dim; ++i)
        for (int k = 0; k < dim; ++k) A(i, k) = j[i][k].get<double>();
    return A;
}

template <int dim>
int check_python_energy_case(const nlohmann::json& c) {
    constexpr int m = dim * dim;
    const std::string file = c["file"];
    SCOPED_TRACE(file);
    const ModelFile model = load_model_file(kModels + "/" + file);
    NeuralElastoplasticEnergy<dim> energy(model, {c["E"].get<double>(), c["w"].get<double>()});
    const std::size_t n = c["F"].size();
    std::vector<Mat<dim>> F(n), F0(n), grad(n);
    std::vector<double> h = c["hardening"].get<std::vector<double>>(), psi(n);
    for (std::size_t p = 0; p < n; ++p) {
        F[p] = mat_from<dim>(c["F"][p]);
        F0[p] = mat_from<dim>(c["F0"][p]);
    }
    energy.set_reference(F0.data(), h.data(), n);
    std::vector<Tensor4<dim>> hess(n);
    energy.value_gradient_hessian(F.data(), psi.data(), grad.data(), hess.data(), false);
    int checks = 0;
    const nlohmann::json& expect = c["expect"];
    for (std::size_t p = 0; p < n; ++p) {
        const double psi_ref = expect["psi"][p];
        EXPECT_NEAR(psi[p], psi_ref, 1e-10 * std::abs(psi_ref)) << "psi " << p;
        const Mat<dim> g_ref = mat_from<dim>(expect["gradient"][p]);
        EXPECT_LE((grad[p] - g_ref).cwiseAbs().maxCoeff(), 1e-10 * g_ref.cwiseAbs().maxCoeff()) << "grad " << p;
        Tensor4<dim> H_ref;
        for (int a = 0; a < m; ++a)
            for (int b = 0; b < m; ++b)
                H_ref(a, b) = expect["hessian"][p][a][b].get<double>();  // row-major vec(F) basis
        EXPECT_LE((hess[p] - H_ref).cwiseAbs().maxCoeff(), 1e-10 * H_ref.cwiseAbs().maxCoeff()) << "hess " << p;
        const Mat<dim> P_ref = mat_from<dim>(expect["Ptilde_F0"][p]);
        const Mat<dim> P = energy.elastoplastic_stress(F0[p], h[p]);
        EXPECT_LE((P - P_ref).cwiseAbs().maxCoeff(), 1e-10 * P_ref.cwiseAbs().maxCoeff()) << "Ptilde " << p;
        checks += 4;
    }
    return checks;
}

template <int dim>
int check_python_return_map_case(const nlohmann::json& c) {
    const std::string file = c["file"];
    SCOPED_TRACE(file);
    const LearnedReturnMap<dim> rm(load_model_file(kModels + "/" + file));
    int checks = 0;
    for (std::size_t p = 0; p < c["Sigma"].size(); ++p) {
        Vec<dim> Sigma, Z_ref;
        for (int i = 0; i < dim; ++i) {
            Sigma[i] = c["Sigma"][p][i];
            Z_ref[i] = c["expect"]["Z"][p][i];
        }
        const double h = c["hardening"][p];
        const ReturnResult<dim> r = rm.return_map(Sigma, h);
        EXPECT_LE((r.Sigma - Z_ref).cwiseAbs().maxCoeff(), 1e-10) << "Z " << p;
        EXPECT_NEAR(r.hardening, c["expect"]["hardening_new"][p].get<double>(), 1e-10) << "h " << p;
        EXPECT_EQ(r.branch == ReturnBranch::Yield, c["expect"]["yielding"][p].get<bool>()) << "branch " << p;
        checks += 3;
    }
    // All states at once (the network runs on the yielding ones only) give the same as one by one,
    // and so do the stresses of deformation gradients with these singular values.
    const std::size_t n = c["Sigma"].size();
    std::vector<Vec<dim>> Sigma(n);
    std::vector<double> h(n);
    std::vector<Mat<dim>> F(n), P(n);
    test::Random random(11);
    for (std::size_t p = 0; p < n; ++p) {
        for (int i = 0; i < dim; ++i) Sigma[p][i] = c["Sigma"][p][i];
        h[p] = c["hardening"][p];
        const Mat<dim> U = Eigen::AngleAxis<double>(random.uniform(-3, 3), Vec<3>::UnitZ()).matrix().template topLeftCorner<dim, dim>();
        F[p] = U * Sigma[p].asDiagonal();
    }
    std::vector<ReturnResult<dim>> batch(n);
    rm.return_map(Sigma.data(), h.data(), n, batch.data());
    rm.elastoplastic_stress(F.data(), h.data(), n, P.data());
    for (std::size_t p = 0; p < n; ++p) {
        const ReturnResult<dim> one = rm.return_map(Sigma[p], h[p]);
        EXPECT_LE((batch[p].Sigma - one.Sigma).cwiseAbs().maxCoeff(), 1e-14) << "batched Z " << p;
        EXPECT_EQ(batch[p].hardening, one.hardening) << "batched h " << p;
        EXPECT_EQ(batch[p].branch, one.branch) << "batched branch " << p;
        const Mat<dim> P_one = rm.elastoplastic_stress(F[p], h[p]);
        EXPECT_LE((P[p] - P_one).cwiseAbs().maxCoeff(), 1e-13 * std::max(1.0, P_one.cwiseAbs().maxCoeff())) << p;
        checks += 4;
    }
    return checks;
}

TEST(NeuralElastoplasticEnergy, MatchesPythonVectors) {
    std::ifstream in(std::string(PNET_TEST_DATA_DIR) + "/energy_vectors_python.json");
    ASSERT_TRUE(in) << "tests/data/energy_vectors_python.json (scripts/gen_energy_vectors.py)";
    const nlohmann::json j = nlohmann::json::parse(in);
    ASSERT_EQ(j["format"], "plasticitynet-energy-vectors");
    int checks = 0, models = 0, yielding = 0;
    for (const nlohmann::json& c : j["cases"]) {
        const int dim = c["dim"];
        ++models;
        if (c["kind"] == "energy")
            checks += dim == 2 ? check_python_energy_case<2>(c) : check_python_energy_case<3>(c);
        else {
            checks += dim == 2 ? check_python_return_map_case<2>(c) : check_python_return_map_case<3>(c);
            for (const auto& y : c["expect"]["yielding"]) yielding += y.get<bool>();
        }
    }
    // Every model the MANIFESTs pin (the shipped ones and the ablation's, models/ablation/) has its cases.
    int pinned = 0;
    for (const char* manifest : {"/MANIFEST", "/ablation/MANIFEST"}) {
        std::ifstream m(kModels + manifest);
        ASSERT_TRUE(m) << kModels << manifest;
        pinned += static_cast<int>(nlohmann::json::parse(m)["models"].size());
    }
    EXPECT_EQ(models, pinned) << "tests/data/energy_vectors_python.json is stale: run scripts/gen_energy_vectors.py";
    EXPECT_GT(yielding, 0) << "no yielding return-map case: the learned projection was not exercised";
    EXPECT_GT(checks, 100);
}

}  // namespace
}  // namespace pnet
