#include "pnet/solver/triplet_hessian.hpp"

#include <algorithm>

namespace pnet {

void TripletHessian::keep_free(const VecX& free) {
    triplets_.erase(std::remove_if(triplets_.begin(), triplets_.end(),
                                   [&](const Triplet& t) { return free[t.row()] == 0.0 || free[t.col()] == 0.0; }),
                    triplets_.end());
}

void TripletHessian::multiply(const VecX& d, VecX& out) const {
    for (const Triplet& t : triplets_) out[t.row()] += t.value() * d[t.col()];
}

void TripletHessian::diagonal(VecX& diagonal) const {
    for (const Triplet& t : triplets_)
        if (t.row() == t.col()) diagonal[t.row()] += t.value();
}

void TripletHessian::block_diagonal(VecX& blocks, int block) const {
    for (const Triplet& t : triplets_)
        if (t.row() / block == t.col() / block)
            blocks[(t.row() / block) * block * block + (t.row() % block) * block + t.col() % block] += t.value();
}

void TripletHessian::append_to(std::vector<Triplet>& triplets) const {
    triplets.insert(triplets.end(), triplets_.begin(), triplets_.end());
}

}  // namespace pnet
