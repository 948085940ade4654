#pragma once
// A uniform grid over axis-aligned boxes: the broad phase of 3D contact
// (docs/methods.md). Boxes (a primitive's, swept over its motion for CCD,
// grown by a margin) are binned into every cell of side `cell` they overlap,
// stored cell by cell (compressed rows: one counting pass, one fill pass, no
// hashing, no sorting); a query box visits the cells it overlaps and returns
// the boxes that overlap it in ascending order without repeats, so that every
// sum over pairs keeps a fixed order (thread counts and runs give the same
// bits). The cell grows (x1.5 at a time) until the grid has at most 2^23 cells.
#include <vector>

#include "pnet/math/types.hpp"

namespace pnet {

template <int dim>
class HashGrid {
public:
    /// Bins boxes [lo[k], hi[k]]. cell > 0: the cell side; about the typical box size (a box
    /// spanning many cells costs as many entries; tiny cells cost as many lookups per query).
    void build(const std::vector<Vec<dim>>& lo, const std::vector<Vec<dim>>& hi, double cell);

    /// The boxes overlapping [lo, hi], ascending, in `out` (cleared first).
    void query(const Vec<dim>& lo, const Vec<dim>& hi, std::vector<int>& out) const;

    /// A cell side for boxes [lo[k], hi[k]]: their mean largest extent (at least `floor`).
    static double suggested_cell(const std::vector<Vec<dim>>& lo, const std::vector<Vec<dim>>& hi, double floor);

    double cell() const { return cell_; }

private:
    using Index = Eigen::Matrix<long, dim, 1>;
    /// The cell holding p, clamped to the grid.
    Index cell_of(const Vec<dim>& p) const;
    long linear(const Index& c) const;

    double cell_ = 1.0;
    Vec<dim> origin_ = Vec<dim>::Zero();
    Index size_ = Index::Ones();      // cells per axis
    std::vector<int> start_;          // per cell: first entry; one past the end last
    std::vector<int> entries_;        // box indices, cell by cell, ascending within a cell
    std::vector<Vec<dim>> lo_, hi_;
};

}  // namespace pnet
