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
// iterations). The passes, each with the J_k and s_k of the last solution, are the implicit
// integrators' (IncrementalPotential::floor_friction_contacts, kFloorFrictionSolves).
#include <vector>

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
    }
    const std::vector<Contact>& contacts() const { return contacts_; }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;

private:
    std::vector<Contact> contacts_;
    const VecX* free_ = nullptr;
};

}  // namespace pnet
