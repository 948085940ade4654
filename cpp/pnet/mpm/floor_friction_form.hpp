#pragma once
// The Coulomb floor's friction inside an implicit MPM solve (BoundaryConditions::floor_friction,
// docs/methods.md): IPC's smoothed Coulomb friction on the grid nodes that press into the floor,
//
//   D(v) = sum_k mu J_k f0(|u_k|),   u_k the tangential components of v at node k,
//
// J_k the normal impulse the floor gives node k over the step and f0 (friction.hpp) |u| smoothed below
// eps_v, minimized by majorize-minimize: each solve sees the quadratic that touches D at the last slip
// s_k = |u_k|,
//
//   D_s(v) = sum_k mu J_k f1(s_k) / (2 s_k) |u_k|^2   (+ a constant),
//
// which lies above D (f0(sqrt(q)) is concave in q) and has its gradient there, so every pass lowers
// D plus the rest of the potential, and Newton sees a smooth quadratic instead of friction's kink (with
// D itself Newton stalled on stick-slip switches: most steps of a granular collapse ran out of
// iterations). The passes, each with the J_k and s_k of the last solution, are MpmOptions::
// floor_friction_solve "passes" (IncrementalPotential::floor_friction_contacts, MpmOptions::floor_friction_passes).
//
// floor_friction_solve "newton" (begin_newton; "auto" in 2D under the work line search, MpmOptions)
// puts the friction itself in the one solve's residual,
//
//   r_k += mu J_k(v) f1(|u_k|) u_k / |u_k|,   J_k(v) = the floor's reaction on node k at v,
//
// so the solve stops on Coulomb's law at its tolerance, and its Jacobian gets the majorizer's curvature
// in the slip and the force's derivative through J_k, mu f1 u_k / |u_k| dJ_k/dv: the normal impulse
// follows the material's stress, and without that term Newton converged linearly on the sliding nodes.
// That term lives in the matrix-free product only: an assembled Hessian (CHOLMOD, incomplete Cholesky,
// the multigrid's operator) carries the slip's curvature alone.
#include <vector>

#include <Eigen/Core>

#include "pnet/solver/triplet_hessian.hpp"

namespace pnet {

template <int dim>
class FloorFrictionForm final : public TripletHessianForm {
public:
    struct Contact {
        int dof;           // the node's unknown index (components dim dof + a)
        double stiffness;  // mu J_k f1(s_k) / s_k, kg/s: the quadratic's curvature
    };

    FloorFrictionForm() : TripletHessianForm(dim) {}

    /// This pass's contacts and the problem's 1 / 0 mask of free components (referenced).
    void begin_step(std::vector<Contact> contacts, const VecX& free) {
        contacts_ = std::move(contacts);
        free_ = &free;
        newton_ = false;
    }

    /// The friction itself instead of a pass's quadratic (the semi-smooth Newton on the floor): the
    /// force mu J_k(v) f1(|u_k|) u_k / |u_k| at every v, with J_k(v) = g_k,y - m_k vn_k read from the
    /// gradient the forms before this one summed (the impulse the floor gives node k at v: the
    /// material's stress and the node's inertia against it), and its Jacobian with J's own
    /// derivative, mu f1 u_k / |u_k| (H_psi d)_k,y, from `held_product` (the product the particles'
    /// form leaves out of the held rows, ParticleEnergyForm::held_product). Not a potential: its
    /// Hessian is not symmetric. Its value (for an energy line search) is the IPC dissipation
    /// mu J_k f0(|u_k|) with J_k held at the last Hessian's iterate, so that an iterate's energy and its
    /// trial points' compare the same function; with J taken at each trial point instead, the
    /// learned energy's line search failed near the tolerance (29 of 738 steps of the sand column).
    void begin_newton(const std::vector<int>& dofs, const std::vector<double>& normal_velocity, const VecX& mass,
                      double mu, double eps_v, const VecX& free, const VecX& held_product);
    bool newton() const { return newton_; }

    /// A contact node of begin_newton(), as the last gradient left it.
    struct NewtonContact {
        int dof;
        double normal_momentum;  // m_k vn_k: what the floor stops of node k's momentum
        double impulse = 0.0;    // J_k at the last gradient's v (<= 0: the floor pulls, no friction)
        double held_impulse = 0.0;  // J_k at the last Hessian's v: the value's (below)
        Eigen::Matrix<double, dim - 1, 1> slip;      // u_k there
        Eigen::Matrix<double, dim - 1, 1> coupling;  // mu f1 u / |u| (0 where J <= 0): d force / d J
    };
    const std::vector<NewtonContact>& newton_contacts() const { return newton_contacts_; }
    /// begin_newton()'s Coulomb coefficient and the slip velocity below which the friction is smoothed (m/s).
    double mu() const { return mu_; }
    double eps_v() const { return eps_v_; }
    const std::vector<Contact>& contacts() const { return contacts_; }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;
    double add_gradient_hessian(const VecX& v, VecX& g) override;
    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    bool symmetric_hessian() const override { return !newton_; }

private:
    std::vector<Contact> contacts_;
    const VecX* free_ = nullptr;
    // The semi-smooth Newton (begin_newton): per contact node, its dof, m_k vn_k, and at the last
    // gradient's v the impulse J_k and the force's coefficient mu f1(|u|) / |u| (times J in the force).
    bool newton_ = false;
    double mu_ = 0.0, eps_v_ = 1.0;
    const VecX* held_product_ = nullptr;
    std::vector<NewtonContact> newton_contacts_;
    VecX gradient_at_;  // the v of the last gradient
};

}  // namespace pnet
