#pragma once
// The sum of forms (form.hpp) that Newton minimizes (docs/architecture.md, "Forms"):
//
//   E(x) = sum_f E_f(x),   g = mask(sum_f dE_f/dx),   H = sum_f H_f,
//
// in the order the forms were given, so every sum has a fixed order (results do not depend on
// the thread count). The mask zeroes the gradient of the components held fixed (free_ = 0).
// The Hessian is used matrix-free (the forms' products, for PCG) or assembled (set_assemble(),
// for a direct solve): the forms whose pattern is fixed over a step are summed into a pattern
// built from their triplets once (again after invalidate_pattern()) and refilled through a map
// from their entries to value slots (Form::add_hessian_values()), and the forms whose pattern
// changes (contact pairs) are summed apart and added.
//
// The MPM, FEM and coupled potentials are problems: each sets up its forms for the step and
// adds what is particular to it (the reference deformation of the learned energy, a
// preconditioner). ProblemForm lets one problem be a form of a larger one (the coupled step
// sums the MPM problem, the FEM problem and the particle-mesh forms).
#include <vector>

#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/form.hpp"

namespace pnet {

template <int dim>
class Problem : public ReferencedObjective<dim> {
public:
    Eigen::Index size() const override { return free_.size(); }
    double value(const VecX& x) override;
    double value_gradient(const VecX& x, VecX& gradient) override;
    void prepare_hessian(const VecX& x) override;
    double value_gradient_hessian(const VecX& x, VecX& gradient) override;
    void hessian_multiply(const VecX& d, VecX& out) const override;
    void hessian_diagonal(VecX& diagonal) const override;
    int hessian_block_size() const override { return dim; }
    void hessian_block_diagonal(VecX& blocks) const override;
    const SparseMatrix* hessian_matrix() const override { return assemble_ ? hessian_ : nullptr; }
    bool hessian_symmetric() const override;
    double max_step(const VecX& x, const VecX& d) override;

    /// The Hessian prepared last as triplets, rows and columns shifted by `offset` (this problem
    /// inside a larger one): the assembled matrix's entries when assembled, else the forms'.
    void add_hessian_triplets(std::vector<Triplet>& triplets, Eigen::Index offset) const;

    /// Assemble H at every Hessian pass, so that hessian_matrix() gives it (a direct solve);
    /// off: matrix-free.
    void set_assemble(bool assemble) { assemble_ = assemble; }
    /// 1 on the free components, 0 on the fixed ones.
    const VecX& free_components() const { return free_; }
    /// The forms, in their summation order.
    const std::vector<Form*>& forms() const { return forms_; }

protected:
    /// The forms, summed in this order (not owned).
    void set_forms(std::vector<Form*> forms) {
        forms_ = std::move(forms);
        pattern_valid_ = false;
    }
    /// Called after every form prepared its Hessian at x (and after the assembly, if any).
    virtual void hessian_prepared(const VecX& /*x*/) {}
    /// The fixed-pattern forms' triplet patterns changed (a new step's grid): the next assembly
    /// builds the pattern anew.
    void invalidate_pattern() { pattern_valid_ = false; }

    VecX free_;

private:
    void assemble();

    std::vector<Form*> forms_;
    bool assemble_ = false;
    // The assembly: fixed_hessian_'s pattern, the value slot of each fixed-pattern form's
    // entries (slot_start_[f] .. for form f), and the changing-pattern forms' matrix.
    bool pattern_valid_ = false;
    std::vector<int> slots_;
    std::vector<std::size_t> slot_start_;
    std::vector<Triplet> changing_triplets_;
    SparseMatrix fixed_hessian_, changing_hessian_, sum_hessian_;
    const SparseMatrix* hessian_ = nullptr;
};

/// A problem as one form of a larger problem, on the unknowns [offset, offset + size()).
template <int dim>
class ProblemForm final : public Form {
public:
    explicit ProblemForm(Problem<dim>& problem) : problem_(problem) {}
    void set_offset(Eigen::Index offset) { offset_ = offset; }

    double value(const VecX& x) override;
    double add_gradient(const VecX& x, VecX& g) override;
    void prepare_hessian(const VecX& x) override;
    double add_gradient_hessian(const VecX& x, VecX& g) override;
    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    void add_hessian_diagonal(VecX& diagonal) const override;
    void add_hessian_block_diagonal(VecX& blocks) const override;
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override;
    bool symmetric_hessian() const override { return problem_.hessian_symmetric(); }
    double max_step(const VecX& x, const VecX& d) override;

private:
    /// x's part on the unknowns of the problem; whole's part += part.
    const VecX& slice(const VecX& x) const;
    void add_slice(const VecX& part, VecX& whole) const;

    Problem<dim>& problem_;
    Eigen::Index offset_ = 0;
    mutable VecX in_, out_, step_;
};

}  // namespace pnet
