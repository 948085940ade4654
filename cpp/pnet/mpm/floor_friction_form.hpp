#pragma once
// The Coulomb floor's friction inside an implicit MPM solve (BoundaryConditions::floor_friction,
// docs/methods.md): IPC's smoothed, lagged Coulomb friction (friction.hpp) on the grid nodes that
// press into the floor,
//
//   D(v) = sum_k mu J_k f0(|u_k|),   u_k the tangential components of v at node k,
//
// with J_k the normal impulse the floor gives node k over the step, lagged: found at v* from the
// start-of-step stress (IncrementalPotential::begin_step). -dD/du_k = -mu J_k f1(|u_k|) u_k / |u_k| is
// a Coulomb impulse of magnitude mu J_k once the node slides faster than eps_v, smoothed below it
// (static friction as a stiff drag); the Hessian is one PSD (dim-1) x (dim-1) block per node.
#include <vector>

#include "pnet/solver/triplet_hessian.hpp"

namespace pnet {

template <int dim>
class FloorFrictionForm final : public TripletHessianForm {
public:
    struct Contact {
        int dof;        // the node's unknown index (components dim dof + a)
        double weight;  // mu J_k, kg m/s
    };

    FloorFrictionForm() : TripletHessianForm(dim) {}

    /// This step's contacts, eps_v (m/s) and the problem's 1 / 0 mask of free components (referenced).
    void begin_step(std::vector<Contact> contacts, double eps_v, const VecX& free) {
        contacts_ = std::move(contacts);
        eps_v_ = eps_v;
        free_ = &free;
    }
    const std::vector<Contact>& contacts() const { return contacts_; }
    double eps_v() const { return eps_v_; }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;

private:
    std::vector<Contact> contacts_;
    double eps_v_ = 1.0;
    const VecX* free_ = nullptr;
};

}  // namespace pnet
