#pragma once
// A form's Hessian kept as a list of triplets (the contact pairs' terms, whose pattern changes
// from one Newton iterate to the next): its products, diagonals and triplets for the problem;
// TripletHessianForm, the base of the forms that keep theirs so.
#include <vector>

#include "pnet/solver/form.hpp"

namespace pnet {

/// The Hessian of a changing-pattern form kept as triplets between free components: its
/// matrix-free products, diagonals and triplets.
class TripletHessian {
public:
    /// Keeps only the triplets whose row and column are free (free[i] > 0).
    void keep_free(const VecX& free);
    void multiply(const VecX& d, VecX& out) const;
    void diagonal(VecX& diagonal) const;
    void block_diagonal(VecX& blocks, int block) const;
    void append_to(std::vector<Triplet>& triplets) const;
    std::vector<Triplet>& triplets() { return triplets_; }

private:
    std::vector<Triplet> triplets_;
};

/// A form whose prepare_hessian() fills hessian_ (triplets between free components, summed
/// apart from the fixed-pattern forms): the Hessian views come from it.
class TripletHessianForm : public Form {
public:
    /// block: the unknowns per node (the dimension).
    explicit TripletHessianForm(int block) : block_(block) {}
    void add_hessian_multiply(const VecX& d, VecX& out) const override { hessian_.multiply(d, out); }
    void add_hessian_diagonal(VecX& diagonal) const override { hessian_.diagonal(diagonal); }
    void add_hessian_block_diagonal(VecX& blocks) const override { hessian_.block_diagonal(blocks, block_); }
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override { hessian_.append_to(triplets); }
    bool changing_pattern() const override { return true; }

protected:
    TripletHessian hessian_;

private:
    int block_;
};

}  // namespace pnet
