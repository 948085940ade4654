#pragma once
// The IPC barrier as a form (docs/methods.md): B(x(v)), the contact potential (collisions/
// contact_potential.hpp: a mesh's pairs, the ground, stand-alone points) of the positions a step
// of unknowns v reaches, whatever moves the contact's vertices (ContactVertices): a mesh's nodes
// with their own velocities (MeshVertices, x = x^n + dt v), and in a coupled step MPM particles
// with their grid stencils too (coupling/coupled_vertices.hpp). Every vertex moves linearly,
//   x_j(v) = x_j^n + dt sum_k w_jk v_(u_jk),
// so a pair's gradient in v is dt J^T dB/dx and its Hessian dt^2 J^T (d2B/dx2) J, J the weights
// of the pair's vertices (PSD-projected per pair). The Hessian is kept per pair (its stacked
// matrix): its products, diagonals and triplets come from those. max_step() is the CCD filter on
// the motion x -> x + dt J d, so that no iterate intersects. The pairs change with x, so the
// Hessian is summed apart from the fixed-pattern forms (Form::changing_pattern()).
#include <vector>

#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/solver/form.hpp"

namespace pnet {

/// The CCD queries of a barrier form's max_step() since its step began, and how many of them
/// shortened the step.
struct CcdCount {
    int queries = 0, limited = 0;
    /// Counts one query that allowed the fraction t; returns t.
    double record(double t) {
        ++queries;
        limited += t < 1.0;
        return t;
    }
};

/// How a contact's vertices follow a step's unknowns v: x_j(v) = x_j^n + dt sum_k w_jk v_(u_jk),
/// vertex j moving with the unknown nodes u_jk (the index of their first component in v) and
/// weights w_jk.
template <int dim>
class ContactVertices {
public:
    /// The most unknown nodes one vertex moves with: an MPM particle's quadratic B-spline stencil.
    static constexpr int kMaxUnknowns = dim == 2 ? 9 : 27;

    virtual ~ContactVertices() = default;
    virtual double dt() const = 0;
    /// x(v), every vertex.
    virtual void positions(const VecX& v, std::vector<Vec<dim>>& x) const = 0;
    /// The motion of a direction d: dx_j = dt sum_k w_jk d_(u_jk).
    virtual void motion(const VecX& d, std::vector<Vec<dim>>& dx) const = 0;
    /// Vertex j's unknown nodes and weights (index, weight: at least kMaxUnknowns entries); returns
    /// how many. Nodes of weight 0 may be left out.
    virtual int unknowns(int vertex, Eigen::Index* index, double* weight) const = 0;

    /// Vertex j's velocity sum_k w_jk v_(u_jk).
    Vec<dim> velocity(int vertex, const VecX& v) const {
        Eigen::Index index[kMaxUnknowns];
        double weight[kMaxUnknowns];
        const int n = unknowns(vertex, index, weight);
        Vec<dim> u = Vec<dim>::Zero();
        for (int k = 0; k < n; ++k) u += weight[k] * v.template segment<dim>(index[k]);
        return u;
    }
};

/// A mesh's nodes, each moving with its own velocity: x = x^n + dt v (v: dim values per node).
template <int dim>
class MeshVertices final : public ContactVertices<dim> {
public:
    /// The step: positions x^n (referenced) and dt.
    void begin_step(const std::vector<Vec<dim>>& x_start, double dt) {
        x_start_ = &x_start;
        dt_ = dt;
    }
    double dt() const override { return dt_; }
    void positions(const VecX& v, std::vector<Vec<dim>>& x) const override;
    void motion(const VecX& d, std::vector<Vec<dim>>& dx) const override;
    int unknowns(int vertex, Eigen::Index* index, double* weight) const override {
        index[0] = dim * static_cast<Eigen::Index>(vertex);
        weight[0] = 1.0;
        return 1;
    }

private:
    const std::vector<Vec<dim>>* x_start_ = nullptr;
    double dt_ = 0.0;
};

/// A form whose terms are pairs of contact vertices (the barrier's; lagged friction's in a coupled
/// step): each pair's Hessian in its vertices' stacked positions, kept with those vertices, and
/// through ContactVertices the Hessian's products, diagonals and triplets in v.
template <int dim>
class VertexPairForm : public Form {
public:
    using Terms = ContactPairTerms<dim>;
    using Hessian = decltype(Terms::hessian);
    /// The most unknown nodes one pair reaches.
    static constexpr int kPairUnknowns = (dim + 1) * ContactVertices<dim>::kMaxUnknowns;

    /// vertices and free (the problem's 1 / 0 mask of free components) are referenced.
    VertexPairForm(const ContactVertices<dim>& vertices, const VecX& free) : vertices_(vertices), free_(free) {}

    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    void add_hessian_diagonal(VecX& diagonal) const override;
    void add_hessian_block_diagonal(VecX& blocks) const override;
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override;
    bool changing_pattern() const override { return true; }

    /// The pairs of the Hessian prepared last (their vertices and stacked Hessians), in order.
    const std::vector<Terms>& hessian_pairs() const { return hessians_; }

    /// f(H, scale, count, index, weight, slot) for every pair of the Hessian prepared last: its
    /// stacked Hessian H (scale H is its Hessian in the pair's motion per unit v), and the unknown
    /// nodes it reaches: index (first component in v), weight, slot (which of the pair's vertices
    /// the node moves).
    template <typename F>
    void for_each_pair_hessian(F&& f) const;

protected:
    /// f(node, a, b, value) for each entry of the unknown nodes' diagonal blocks (free components).
    template <typename F>
    void for_each_node_block_entry(F&& f) const;

    const ContactVertices<dim>& vertices_;
    const VecX& free_;
    std::vector<Terms> hessians_;  // node, count and hessian of each pair
    double hessian_scale_ = 0.0;
};

template <int dim>
class BarrierForm final : public VertexPairForm<dim> {
public:
    using Terms = ContactPairTerms<dim>;

    /// contact, vertices and free (the problem's 1 / 0 mask of free components) are referenced.
    BarrierForm(const ContactPotential<dim>& contact, const ContactVertices<dim>& vertices, const VecX& free)
        : VertexPairForm<dim>(vertices, free), contact_(contact) {}

    /// A new step: no pairs, no CCD queries.
    void begin_step();

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    /// The pairs' Hessians, scaled by kappa dt^2 in v.
    void prepare_hessian(const VecX& v) override;
    double max_step(const VecX& v, const VecX& d) override;

    /// Project the pairs' Hessians to PSD (default; false: exact, for derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }
    const CcdCount& ccd() const { return ccd_; }
    /// The pairs active at the last gradient.
    std::size_t pairs() const { return gradient_pairs_; }

private:
    const ContactPotential<dim>& contact_;
    std::vector<Vec<dim>> x_, dx_;
    std::vector<Terms> terms_;
    std::size_t gradient_pairs_ = 0;
    bool project_psd_ = true;
    CcdCount ccd_;
};

template <int dim>
template <typename F>
void VertexPairForm<dim>::for_each_pair_hessian(F&& f) const {
    Eigen::Index index[kPairUnknowns];
    double weight[kPairUnknowns];
    int slot[kPairUnknowns];
    for (const Terms& t : hessians_) {
        int count = 0;
        for (int k = 0; k < t.count; ++k) {
            const int n = vertices_.unknowns(t.node[k], index + count, weight + count);
            for (int i = 0; i < n; ++i) slot[count + i] = k;
            count += n;
        }
        f(t.hessian, hessian_scale_, count, index, weight, slot);
    }
}

}  // namespace pnet
