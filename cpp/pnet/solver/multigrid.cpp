#include "pnet/solver/multigrid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>

namespace pnet {

namespace {

using RowMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor>;

constexpr int kCoordinateBits = 21;  // coordinates below 2^21 per axis (a 2-million-node axis)

std::int64_t key_of(const int* c, int dim) {
    std::int64_t key = 0;
    for (int a = 0; a < dim; ++a) key = (key << kCoordinateBits) | c[a];
    return key;
}

int colour_of(const int* c, int dim) {
    int colour = 0;
    for (int a = dim - 1; a >= 0; --a) colour = 3 * colour + c[a] % 3;
    return colour;
}

/// y = A x, rows in parallel (each row summed in storage order: the same for any thread count).
void multiply(const RowMatrix& A, const VecX& x, VecX& y) {
    const Eigen::Index n = A.rows();
    y.resize(n);
    const auto* outer = A.outerIndexPtr();
    const auto* inner = A.innerIndexPtr();
    const double* value = A.valuePtr();
#pragma omp parallel for schedule(static) if (n > 4096)
    for (Eigen::Index i = 0; i < n; ++i) {
        double s = 0.0;
        for (auto k = outer[i]; k < outer[i + 1]; ++k) s += value[k] * x[inner[k]];
        y[i] = s;
    }
}

}  // namespace

struct GridMultigrid::Level {
    std::vector<int> coordinates;               // dim per node
    std::vector<std::vector<int>> colour_nodes;  // the nodes of each colour, increasing
    VecX free;                                   // 1 / 0 per component
    RowMatrix A;                                 // the operator (symmetric)
    VecX inverse_blocks;                         // dim x dim inverse diagonal blocks, row-major
    std::vector<int> own_begin, own_end;         // per row: the entries of its own node's block (sorted rows)
    // To the next coarser level: P (this level's unknowns x the coarser one's) by rows, and P^T by rows.
    RowMatrix P, Pt;
    mutable VecX x, b, r;                        // the cycle's work vectors (levels > 0: x and b)

    Eigen::Index nodes(int dim) const { return static_cast<Eigen::Index>(coordinates.size()) / dim; }
};

struct GridMultigrid::Coarsest {
    // The operator scaled to a unit diagonal, D^-1/2 S D^-1/2, and D^-1/2.
    Eigen::SimplicialLDLT<SparseMatrix, Eigen::Lower> ldlt;
    VecX scale;
};

GridMultigrid::GridMultigrid(MultigridOptions options) : options_(options) {}
GridMultigrid::~GridMultigrid() = default;
GridMultigrid::GridMultigrid(GridMultigrid&&) noexcept = default;
GridMultigrid& GridMultigrid::operator=(GridMultigrid&&) noexcept = default;

bool GridMultigrid::ready() const { return ready_; }
int GridMultigrid::levels() const { return static_cast<int>(levels_.size()); }
Eigen::Index GridMultigrid::unknowns(int level) const { return levels_.at(level)->nodes(dim_) * dim_; }

void GridMultigrid::set_grid(int dim, const std::vector<int>& coordinates, const VecX& free) {
    if (dim != 2 && dim != 3) throw std::invalid_argument("GridMultigrid::set_grid: dim must be 2 or 3");
    if (coordinates.size() % dim != 0 || static_cast<Eigen::Index>(coordinates.size()) != free.size())
        throw std::invalid_argument("GridMultigrid::set_grid: " + std::to_string(coordinates.size()) +
                                    " coordinates for " + std::to_string(free.size()) + " components in " +
                                    std::to_string(dim) + "D");
    for (const int c : coordinates)
        if (c < 0 || c >= (1 << kCoordinateBits))
            throw std::invalid_argument("GridMultigrid::set_grid: node coordinate " + std::to_string(c) +
                                        " outside [0, 2^21)");
    dim_ = dim;
    ready_ = false;
    levels_.clear();
    auto fine = std::make_unique<Level>();
    fine->coordinates = coordinates;
    fine->free = free;
    levels_.push_back(std::move(fine));
    while (true) {
        Level& level = *levels_.back();
        const Eigen::Index nodes = level.nodes(dim);
        level.colour_nodes.assign(dim == 2 ? 9 : 27, {});
        for (Eigen::Index k = 0; k < nodes; ++k)
            level.colour_nodes[colour_of(&level.coordinates[dim * k], dim)].push_back(static_cast<int>(k));
        if (nodes <= options_.coarsest_nodes || levels() >= options_.max_levels) break;

        // The coarser level: each node's 2^d parents (below), numbered in the order the fine nodes
        // first reach them.
        auto coarse = std::make_unique<Level>();
        std::unordered_map<std::int64_t, int> index;
        index.reserve(static_cast<std::size_t>(nodes));
        std::vector<Eigen::Triplet<double>> entries;
        entries.reserve(static_cast<std::size_t>(nodes) * dim * (dim == 2 ? 4 : 8));
        for (Eigen::Index k = 0; k < nodes; ++k) {
            const int* c = &level.coordinates[dim * k];
            // Per axis the two parents and their weights, by the quadratic B-splines' refinement: a
            // coarse spline is 1/4, 3/4, 3/4, 1/4 of the fine ones at 2J .. 2J + 3 (coarse index J
            // stored as J + 1, so that it stays >= 0).
            int parent_c[3][2];
            const double parent_w[2] = {0.75, 0.25};
            for (int a = 0; a < dim; ++a) {
                const int J = c[a] % 2 == 0 ? c[a] / 2 - 1 : (c[a] - 1) / 2;
                parent_c[a][0] = J + 1;
                parent_c[a][1] = c[a] % 2 == 0 ? J + 2 : J;
            }
            int corner[3] = {0, 0, 0};
            while (true) {
                int parent[3];
                double w = 1.0;
                for (int a = 0; a < dim; ++a) {
                    parent[a] = parent_c[a][corner[a]];
                    w *= parent_w[corner[a]];
                }
                const auto [it, inserted] = index.emplace(key_of(parent, dim), static_cast<int>(index.size()));
                if (inserted) coarse->coordinates.insert(coarse->coordinates.end(), parent, parent + dim);
                for (int a = 0; a < dim; ++a)
                    if (level.free[dim * k + a] > 0.0) entries.emplace_back(dim * k + a, dim * it->second + a, w);
                int a = 0;  // next corner
                while (a < dim && ++corner[a] == 2) corner[a++] = 0;
                if (a == dim) break;
            }
        }
        const Eigen::Index coarse_unknowns = static_cast<Eigen::Index>(coarse->coordinates.size());
        if (coarse_unknowns >= nodes * dim) break;  // no coarsening left (a line of nodes)
        level.P.resize(nodes * dim, coarse_unknowns);
        level.P.setFromTriplets(entries.begin(), entries.end());
        level.Pt = level.P.transpose();
        // A coarse component is free where some free fine component reaches it.
        coarse->free = VecX::Zero(coarse_unknowns);
        for (Eigen::Index i = 0; i < level.Pt.rows(); ++i)
            if (level.Pt.outerIndexPtr()[i + 1] > level.Pt.outerIndexPtr()[i]) coarse->free[i] = 1.0;
        levels_.push_back(std::move(coarse));
    }
    // The last level has no coarser one.
    levels_.back()->P.resize(0, 0);
    levels_.back()->Pt.resize(0, 0);
}

void GridMultigrid::set_operator(const SparseMatrix& A, bool symmetric) {
    if (levels_.empty()) throw std::logic_error("GridMultigrid::set_operator: set_grid first");
    const int dim = dim_;
    if (A.rows() != unknowns(0) || A.cols() != unknowns(0))
        throw std::invalid_argument("GridMultigrid::set_operator: a " + std::to_string(A.rows()) + " x " +
                                    std::to_string(A.cols()) + " operator for " + std::to_string(unknowns(0)) +
                                    " unknowns");
    ready_ = false;
    // The symmetric part (exact when A is symmetric: (A + A^T) / 2 rounds to A).
    SparseMatrix S = symmetric ? A : SparseMatrix(0.5 * (A + SparseMatrix(A.transpose())));
    for (std::size_t l = 0; l < levels_.size(); ++l) {
        Level& level = *levels_[l];
        if (l > 0) {
            const Level& fine = *levels_[l - 1];
            const SparseMatrix P = fine.P;  // col-major for the products
            S = SparseMatrix(P.transpose()) * (S * P);
            // Components no free fine component reaches: a unit diagonal (their residual is 0).
            std::vector<Eigen::Triplet<double>> unit;
            for (Eigen::Index i = 0; i < S.rows(); ++i)
                if (level.free[i] == 0.0) unit.emplace_back(i, i, 1.0);
            if (!unit.empty()) {
                SparseMatrix D(S.rows(), S.cols());
                D.setFromTriplets(unit.begin(), unit.end());
                S += D;
            }
        }
        S.makeCompressed();
        level.A = S;
        const Eigen::Index nodes = level.nodes(dim);
        // The colouring must separate coupled nodes; and the inverse diagonal blocks.
        std::vector<int> colour(static_cast<std::size_t>(nodes));
        for (Eigen::Index k = 0; k < nodes; ++k) colour[k] = colour_of(&level.coordinates[dim * k], dim);
        level.inverse_blocks.setZero(nodes * dim * dim);
        const auto* outer = level.A.outerIndexPtr();
        const auto* inner = level.A.innerIndexPtr();
        const double* value = level.A.valuePtr();
        level.own_begin.assign(level.A.rows(), 0);
        level.own_end.assign(level.A.rows(), 0);
        for (Eigen::Index i = 0; i < level.A.rows(); ++i) {
            const Eigen::Index k = i / dim;
            level.own_begin[i] = level.own_end[i] = outer[i];
            for (auto e = outer[i]; e < outer[i + 1]; ++e) {
                const Eigen::Index j = inner[e], m = j / dim;
                if (m < k) level.own_begin[i] = level.own_end[i] = e + 1;
                if (m == k) {
                    level.inverse_blocks[k * dim * dim + (i % dim) * dim + j % dim] = value[e];
                    level.own_end[i] = e + 1;
                }
                else if (colour[m] == colour[k] && value[e] != 0.0)
                    throw std::invalid_argument("GridMultigrid::set_operator: level " + std::to_string(l) +
                                                " couples nodes " + std::to_string(k) + " and " + std::to_string(m) +
                                                " of the same colour (more than two nodes apart)");
            }
        }
        for (Eigen::Index k = 0; k < nodes; ++k) {
            double* block = level.inverse_blocks.data() + k * dim * dim;
            if (dim == 2) {
                Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> B(block);
                const Eigen::Matrix2d inverse = Eigen::LLT<Eigen::Matrix2d>(B).solve(Eigen::Matrix2d::Identity());
                B = inverse.allFinite() ? inverse : Eigen::Matrix2d(B.diagonal().cwiseInverse().asDiagonal());
            } else {
                Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> B(block);
                const Eigen::Matrix3d inverse = Eigen::LLT<Eigen::Matrix3d>(B).solve(Eigen::Matrix3d::Identity());
                B = inverse.allFinite() ? inverse : Eigen::Matrix3d(B.diagonal().cwiseInverse().asDiagonal());
            }
        }
        const Eigen::Index n = level.A.rows();
        level.x.resize(n);
        level.b.resize(n);
        level.r.resize(n);
    }
    if (!coarsest_) coarsest_ = std::make_unique<Coarsest>();
    // The coarsest operator is factorized scaled to a unit diagonal: an MPM grid's rows span many
    // orders of magnitude (an edge node reached by a particle's far stencil weight has a mass 1e-9 of
    // the others'), and pivots judged against the largest would call a positive definite operator
    // indefinite (the sand column's coarsest pivots ran from 3e-13 to 33).
    coarsest_->scale.resize(S.rows());
    for (Eigen::Index i = 0; i < S.rows(); ++i) {
        const double d = S.coeff(i, i);
        coarsest_->scale[i] = d > 0.0 ? 1.0 / std::sqrt(d) : 1.0;
    }
    S = coarsest_->scale.asDiagonal() * S * coarsest_->scale.asDiagonal();
    // A positive semi-definite operator can make the coarsest one singular to round-off (a free
    // component that nothing but round-off holds); its LDL^T then has zero or negative pivots, and the
    // V-cycle would not be positive definite. Shifted by a relative 1e-10 of its diagonal (x100 until
    // every pivot is positive), the coarsest solve stays a positive definite approximation.
    auto pivots_positive = [&] {
        if (coarsest_->ldlt.info() != Eigen::Success) return false;
        const VecX& D = coarsest_->ldlt.vectorD();
        return D.size() == 0 || D.minCoeff() > 1e-14 * D.cwiseAbs().maxCoeff();
    };
    coarsest_->ldlt.compute(S);
    for (double shift = 1e-10; !pivots_positive() && shift <= 1e-4; shift *= 100.0) {
        SparseMatrix shifted = S;
        for (Eigen::Index i = 0; i < shifted.rows(); ++i) shifted.coeffRef(i, i) *= 1.0 + shift;
        coarsest_->ldlt.compute(shifted);
    }
    if (!pivots_positive())
        throw std::invalid_argument("GridMultigrid::set_operator: the coarsest operator (" +
                                    std::to_string(S.rows()) + " unknowns) is not positive definite");
    ready_ = true;
}

namespace {

/// One multi-coloured block Gauss-Seidel sweep on A x = b (colours forward or backward).
template <int dim>
void gauss_seidel(const GridMultigrid::Level& level, const VecX& b, VecX& x, bool forward);

}  // namespace

void GridMultigrid::apply(const VecX& r, VecX& z) const {
    if (!ready_) throw std::logic_error("GridMultigrid::apply: set_operator first");
    cycle(0, r, z);
}

void GridMultigrid::cycle(int l, const VecX& b, VecX& x) const {
    const Level& level = *levels_[l];
    if (l + 1 == levels()) {
        x = coarsest_->scale.cwiseProduct(coarsest_->ldlt.solve(coarsest_->scale.cwiseProduct(b)));
        return;
    }
    x.setZero(b.size());
    for (int s = 0; s < options_.smoothing_sweeps; ++s)
        dim_ == 2 ? gauss_seidel<2>(level, b, x, true) : gauss_seidel<3>(level, b, x, true);
    // The coarse correction of the residual.
    multiply(level.A, x, level.r);
    level.r = b - level.r;
    const Level& coarse = *levels_[l + 1];
    multiply(level.Pt, level.r, coarse.b);
    cycle(l + 1, coarse.b, coarse.x);
    multiply(level.P, coarse.x, level.r);
    x += level.r;
    for (int s = 0; s < options_.smoothing_sweeps; ++s)
        dim_ == 2 ? gauss_seidel<2>(level, b, x, false) : gauss_seidel<3>(level, b, x, false);
}

namespace {

template <int dim>
void gauss_seidel(const GridMultigrid::Level& level, const VecX& b, VecX& x, bool forward) {
    const auto* outer = level.A.outerIndexPtr();
    const auto* inner = level.A.innerIndexPtr();
    const double* value = level.A.valuePtr();
    const int colours = static_cast<int>(level.colour_nodes.size());
    const Eigen::Index total = level.A.rows();
#pragma omp parallel if (total > 4096)
    for (int c = 0; c < colours; ++c) {
        const std::vector<int>& nodes = level.colour_nodes[forward ? c : colours - 1 - c];
        const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(nodes.size());
#pragma omp for schedule(static)
        for (std::ptrdiff_t q = 0; q < count; ++q) {
            const int k = nodes[q];
            Eigen::Matrix<double, dim, 1> s;
            for (int a = 0; a < dim; ++a) {
                const Eigen::Index i = dim * k + a;
                double sum = b[i];
                for (auto e = outer[i]; e < level.own_begin[i]; ++e) sum -= value[e] * x[inner[e]];
                for (auto e = level.own_end[i]; e < outer[i + 1]; ++e) sum -= value[e] * x[inner[e]];
                s[a] = sum;
            }
            const Eigen::Map<const Eigen::Matrix<double, dim, dim, Eigen::RowMajor>> inverse(
                level.inverse_blocks.data() + static_cast<Eigen::Index>(k) * dim * dim);
            x.template segment<dim>(dim * k) = inverse * s;
        }
    }
}

}  // namespace

}  // namespace pnet
