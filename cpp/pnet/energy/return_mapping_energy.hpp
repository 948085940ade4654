#pragma once
// The classical implicit solver's energy face (`return_map`, docs/solver.md): no network, the material
// library's return mappings. About a reference F0 (the outer iteration moves it to F(v) at every Newton
// iterate and trial point), per point
//
//   P(F)   = Ptilde(F, h)                              (the return-mapped stress at F, h = h^n)
//   H(F)   = dPtilde/dF(F, h) + w mu I                 (the consistent tangent, material/elastoplastic_tangent.hpp)
//   psi(F) = 1/2 (Ptilde(F0, h) + Ptilde(F, h)) : (F - F0)
//
// psi is the work of the stress along the segment F0 -> F by the trapezoid rule: 0 at the reference,
// which is where the rebased Newton with the work line search evaluates every point (it only reports
// it). There is no potential behind P for non-associative flow (Drucker-Prager, Cam-Clay); the tangent
// then keeps its skew part (H = S + K, S projected to PSD plus w mu I with w = tangent_damping, K
// unprojected) and Newton solves it by GMRES. For von Mises (associative) w = 0 and H is symmetric.
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/material/material.hpp"
#include "pnet/math/svd.hpp"

namespace pnet {

template <int dim>
class ReturnMappingEnergy final : public ParticleEnergy<dim> {
public:
    /// materials[k]: object k's material (kept by reference). tangent_damping: w of the
    /// non-associative materials' tangent, in units of their shear modulus.
    ReturnMappingEnergy(const std::vector<Material<dim>>& materials, double tangent_damping);

    void set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                       const std::vector<int>& object) override;
    void evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order, double* psi, Mat<dim>* P,
                  Tensor4<dim>* H, bool project_psd = true) override;
    bool set_damping(double lambda) override {
        damping_ = lambda;
        return true;
    }
    bool tangent_hessian() const override { return true; }
    void begin_step() override { svd0_.clear(); }
    bool symmetric_hessian() const override { return symmetric_; }

private:
    const std::vector<Material<dim>>& materials_;
    double tangent_damping_;       // w of the non-associative tangent (0 for associative flow)
    std::vector<bool> keep_skew_;  // per object: non-associative flow, the tangent's skew part kept and damped
    bool symmetric_ = true;
    double damping_ = 0.0;   // Objective::set_damping, added to w
    std::vector<int> object_;
    std::vector<double> hardening_;
    std::vector<Mat<dim>> F0_, stress0_;  // the reference and Ptilde there
    std::vector<PolarSVD<dim>> svd0_;     // clamped SVDs of F0, for evaluations at the reference
};

}  // namespace pnet
