#pragma once
// Galerkin geometric multigrid for the unknowns of a structured grid's nodes (the implicit MPM
// step's grid velocities; docs/solver.md, "Multigrid"), as a preconditioner of CG, GMRES and BiCGSTAB.
// After Wang et al. 2020 (HOT):
//
//   levels    the nodes of spacing dx, 2dx, 4dx, ...: P is the refinement relation of the quadratic
//             B-splines (a coarse spline is 1/4, 3/4, 3/4, 1/4 of four fine ones along each axis,
//             so the coarse spaces are nested), a tensor product over the axes, one copy per
//             velocity component;
//   operators A_{l+1} = P^T A_l P (Galerkin; R = P^T), from the symmetric part of the fine
//             operator (a Hessian with a skew part is preconditioned by its symmetric part);
//   smoother  block Gauss-Seidel on the nodes' d x d blocks, multi-coloured: the nodes coupled to a
//             node lie within two nodes of it along each axis on every level (a quadratic B-spline
//             stencil on the finest; the Galerkin product keeps the reach on the coarser ones), so
//             the 3^d colours of (c mod 3) are independent sets, updated in parallel and in the
//             same order whatever the thread count. Forward sweeps before the coarse correction,
//             backward after, so the V-cycle is a symmetric operator;
//   coarsest  a sparse Cholesky factorization (LDL^T).
//
// Components held fixed (Dirichlet; `free` 0) take no part in the interpolation: their rows of P
// are zero, and their own rows in A (the inertia's mass alone) are solved exactly by the smoother.
// A coarse component that no free fine component reaches gets a unit diagonal.
#include <memory>
#include <vector>

#include "pnet/solver/objective.hpp"

namespace pnet {

struct MultigridOptions {
    int smoothing_sweeps = 1;       // forward sweeps before and backward sweeps after each coarse correction
    int coarsest_nodes = 400;       // stop coarsening once a level has at most this many nodes
    int max_levels = 12;
};

class GridMultigrid {
public:
    explicit GridMultigrid(MultigridOptions options = {});
    ~GridMultigrid();
    GridMultigrid(GridMultigrid&&) noexcept;
    GridMultigrid& operator=(GridMultigrid&&) noexcept;

    /// The unknowns: dim components per node, node k's at dim k .. dim k + dim - 1, at the integer
    /// grid coordinates coordinates[dim k .. dim k + dim - 1] (>= 0); free[i] 0 on components held
    /// fixed. Builds the levels' nodes, prolongations and colours (once per step: the grid's active
    /// nodes change from step to step).
    void set_grid(int dim, const std::vector<int>& coordinates, const VecX& free);

    /// The fine operator (n x n, n = dim nodes; both triangles stored; `symmetric`: A is, else its
    /// symmetric part is taken): the coarse operators by Galerkin products, the smoothers' inverse
    /// blocks and the coarsest factorization. Throws std::invalid_argument on a size that is not
    /// the grid's, or when a level's operator couples two nodes of the same colour (a reach beyond
    /// two nodes).
    void set_operator(const SparseMatrix& A, bool symmetric = false);

    /// z = M^-1 r: one V-cycle from z = 0.
    void apply(const VecX& r, VecX& z) const;

    bool ready() const;
    int levels() const;
    /// Unknowns on level l (0: the finest).
    Eigen::Index unknowns(int level) const;

    struct Level;

private:
    void cycle(int level, const VecX& b, VecX& x) const;

    MultigridOptions options_;
    int dim_ = 0;
    std::vector<std::unique_ptr<Level>> levels_;
    struct Coarsest;
    std::unique_ptr<Coarsest> coarsest_;
    bool ready_ = false;
};

}  // namespace pnet
