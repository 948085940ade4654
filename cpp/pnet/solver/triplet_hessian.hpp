#pragma once
// A form's Hessian kept as a list of triplets (the contact pairs' terms, whose pattern changes
// from one Newton iterate to the next): its products, diagonals and triplets for the problem.
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

}  // namespace pnet
