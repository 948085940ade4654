#include "pnet/solver/pcg.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <stdexcept>

namespace pnet {

namespace {

template <int b>
void invert_blocks(const VecX& blocks, VecX& inverse) {
    using Block = Eigen::Matrix<double, b, b, Eigen::RowMajor>;
    const Eigen::Index n = blocks.size() / (b * b);
    inverse.resize(blocks.size());
#pragma omp parallel for schedule(static)
    for (Eigen::Index k = 0; k < n; ++k) {
        const Eigen::Map<const Block> B(blocks.data() + k * b * b);
        Eigen::Map<Block> inv(inverse.data() + k * b * b);
        const Eigen::LLT<Block> llt(B);
        if (llt.info() == Eigen::Success) {
            inv = llt.solve(Block::Identity());
        } else {
            inv.setZero();
            for (int i = 0; i < b; ++i) inv(i, i) = B(i, i) > 0.0 ? 1.0 / B(i, i) : 1.0;
        }
    }
}

template <int b>
void apply_blocks(const VecX& inverse, const VecX& r, VecX& z) {
    using Block = Eigen::Matrix<double, b, b, Eigen::RowMajor>;
    const Eigen::Index n = r.size() / b;
    z.resize(r.size());
    for (Eigen::Index k = 0; k < n; ++k)
        z.template segment<b>(b * k).noalias() =
            Eigen::Map<const Block>(inverse.data() + k * b * b) * r.template segment<b>(b * k);
}

}  // namespace

Preconditioner Preconditioner::jacobi(const VecX& diagonal) {
    Preconditioner m;
    m.set_jacobi(diagonal);
    return m;
}

Preconditioner Preconditioner::block_jacobi(const VecX& blocks, int block) {
    Preconditioner m;
    m.set_block_jacobi(blocks, block);
    return m;
}

Preconditioner Preconditioner::of(const Objective& objective) {
    Preconditioner m;
    m.set_objective(objective);
    return m;
}

void Preconditioner::set_incomplete_cholesky(const SparseMatrix& H) {
    objective_ = nullptr;
    block_ = 1;
    if (!ichol_) ichol_ = std::make_shared<IncompleteCholesky>();
    ichol_->compute(H);
    if (ichol_->info() != Eigen::Success)
        throw std::runtime_error("Preconditioner: the incomplete Cholesky factorization failed");
    use_ichol_ = true;
}

void Preconditioner::set_jacobi(const VecX& diagonal) {
    objective_ = nullptr;
    use_ichol_ = false;
    block_ = 1;
    inverse_.resize(diagonal.size());
    inverse_ = diagonal.unaryExpr([](double h) { return h > 0.0 ? 1.0 / h : 1.0; });
}

void Preconditioner::set_block_jacobi(const VecX& blocks, int block) {
    objective_ = nullptr;
    use_ichol_ = false;
    if (block < 1 || blocks.size() % (block * block) != 0)
        throw std::invalid_argument("Preconditioner::block_jacobi: blocks do not hold whole " + std::to_string(block) +
                                    " x " + std::to_string(block) + " blocks");
    if (block == 1) {
        set_jacobi(blocks);
    } else if (block == 2) {
        block_ = 2;
        invert_blocks<2>(blocks, inverse_);
    } else if (block == 3) {
        block_ = 3;
        invert_blocks<3>(blocks, inverse_);
    } else {
        throw std::invalid_argument("Preconditioner::block_jacobi: blocks of 2 or 3 are supported, got " +
                                    std::to_string(block));
    }
}

void Preconditioner::apply(const VecX& r, VecX& z) const {
    if (objective_)
        objective_->apply_preconditioner(r, z);
    else if (use_ichol_)
        z = ichol_->solve(r);
    else if (block_ == 1)
        z = inverse_.cwiseProduct(r);
    else if (block_ == 2)
        apply_blocks<2>(inverse_, r, z);
    else
        apply_blocks<3>(inverse_, r, z);
}

namespace {

/// A Krylov solve's start: d = 0, and |b|; with b = 0 the solve is done (converged, d = 0).
bool nothing_to_solve(const VecX& b, VecX& d, PcgResult& result, double& b_norm) {
    d.setZero(b.size());
    b_norm = b.norm();
    result.converged = b_norm == 0.0;
    return result.converged;
}

}  // namespace

PcgResult solve_pcg(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                    double relative_tolerance, int max_iterations, PcgWorkspace& work) {
    PcgResult result;
    const Eigen::Index n = b.size();
    double b_norm = 0.0;
    if (nothing_to_solve(b, d, result, b_norm)) return result;
    VecX &r = work.r, &z = work.z, &p = work.p, &Hp = work.Hp;
    r = b;
    z.resize(n);
    Hp.resize(n);
    preconditioner.apply(r, z);
    p = z;
    double rz = r.dot(z);
    for (int k = 0; k < max_iterations; ++k) {
        objective.hessian_multiply(p, Hp);
        const double pHp = p.dot(Hp);
        if (!(pHp > 0.0)) {
            result.negative_curvature = true;
            if (k == 0) d = p * (rz / std::max(p.squaredNorm(), 1e-300));  // never return a zero step
            break;
        }
        const double alpha = rz / pHp;
        d += alpha * p;
        r -= alpha * Hp;
        result.iterations = k + 1;
        result.relative_residual = r.norm() / b_norm;
        if (result.relative_residual <= relative_tolerance) {
            result.converged = true;
            break;
        }
        preconditioner.apply(r, z);
        const double rz_next = r.dot(z);
        p = z + (rz_next / rz) * p;
        rz = rz_next;
    }
    return result;
}

PcgResult solve_pcg(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                    double relative_tolerance, int max_iterations) {
    PcgWorkspace work;
    return solve_pcg(objective, b, preconditioner, d, relative_tolerance, max_iterations, work);
}

PcgResult solve_bicgstab(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                         double relative_tolerance, int max_iterations, BicgstabWorkspace& work) {
    PcgResult result;
    const Eigen::Index n = b.size();
    double b_norm = 0.0;
    if (nothing_to_solve(b, d, result, b_norm)) return result;
    VecX &r = work.r, &r0 = work.r0, &p = work.p, &v = work.v, &s = work.s, &t = work.t, &y = work.y, &z = work.z;
    r = b;
    r0 = b;
    p.setZero(n);
    v.setZero(n);
    s.resize(n);
    t.resize(n);
    y.resize(n);
    z.resize(n);
    double rho = 1.0, alpha = 1.0, omega = 1.0;
    int products = 0;
    while (products + 2 <= std::max(max_iterations, 2)) {
        const double rho_next = r0.dot(r);
        if (rho_next == 0.0 || omega == 0.0) break;  // breakdown
        p = r + (rho_next / rho) * (alpha / omega) * (p - omega * v);
        rho = rho_next;
        preconditioner.apply(p, y);
        objective.hessian_multiply(y, v);
        const double r0v = r0.dot(v);
        if (r0v == 0.0) break;
        alpha = rho / r0v;
        s = r - alpha * v;
        preconditioner.apply(s, z);
        objective.hessian_multiply(z, t);
        products += 2;
        const double tt = t.squaredNorm();
        omega = tt > 0.0 ? t.dot(s) / tt : 0.0;
        d += alpha * y + omega * z;
        r = s - omega * t;
        result.iterations = products;
        result.relative_residual = r.norm() / b_norm;
        if (!std::isfinite(result.relative_residual)) {
            d.setZero(n);
            break;
        }
        if (result.relative_residual <= relative_tolerance) {
            result.converged = true;
            break;
        }
    }
    if (d.squaredNorm() == 0.0) {  // never return a zero step
        preconditioner.apply(b, z);
        d = z * (b.dot(z) / std::max(z.squaredNorm(), 1e-300));
    }
    return result;
}

PcgResult solve_gmres(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                      double relative_tolerance, int max_iterations, GmresWorkspace& work, int restart,
                      const VecX* weight) {
    PcgResult result;
    const Eigen::Index n = b.size();
    double b_norm = 0.0;
    if (nothing_to_solve(b, d, result, b_norm)) return result;
    // <u, v> = u . W v: Arnoldi orthonormalizes in it, and the iterate minimizes |b - H d|_W. A weight that
    // is not a norm on b (zero or non-finite where b is not zero) falls back to the Euclidean one.
    if (weight) {
        const double weighted = b.dot(weight->cwiseProduct(b));
        if (!(weighted > 0.0 && std::isfinite(weighted) && weight->minCoeff() >= 0.0)) weight = nullptr;
    }
    auto dot = [&](const VecX& u, const auto& v) { return weight ? u.dot(weight->cwiseProduct(v)) : u.dot(v); };
    const double b_size = std::sqrt(dot(b, b));
    max_iterations = std::max(max_iterations, 1);
    const int m = std::max(1, std::min(restart, max_iterations));
    work.basis.resize(n, m + 1);
    work.hessenberg.setZero(m + 1, m);
    work.cosines.resize(m);
    work.sines.resize(m);
    work.rhs.resize(m + 1);
    VecX &w = work.w, &z = work.z;
    w = b;  // the residual of d = 0
    int products = 0;
    double residual = b_size;
    while (products < max_iterations) {
        work.basis.col(0) = w / residual;
        work.rhs.setZero();
        work.rhs[0] = residual;
        int k = 0;  // the basis's size less one at the end of this cycle
        for (; k < m && products < max_iterations; ++k) {
            preconditioner.apply(work.basis.col(k), z);
            objective.hessian_multiply(z, w);
            ++products;
            for (int i = 0; i <= k; ++i) {  // modified Gram-Schmidt
                const double h = dot(w, work.basis.col(i));
                work.hessenberg(i, k) = h;
                w -= h * work.basis.col(i);
            }
            const double h_next = std::sqrt(dot(w, w));
            for (int i = 0; i < k; ++i) {  // the earlier rotations on the new column
                const double a = work.hessenberg(i, k), c = work.hessenberg(i + 1, k);
                work.hessenberg(i, k) = work.cosines[i] * a + work.sines[i] * c;
                work.hessenberg(i + 1, k) = -work.sines[i] * a + work.cosines[i] * c;
            }
            const double a = work.hessenberg(k, k), rr = std::hypot(a, h_next);
            work.cosines[k] = rr > 0.0 ? a / rr : 1.0;
            work.sines[k] = rr > 0.0 ? h_next / rr : 0.0;
            work.hessenberg(k, k) = rr;
            work.rhs[k + 1] = -work.sines[k] * work.rhs[k];
            work.rhs[k] *= work.cosines[k];
            residual = std::abs(work.rhs[k + 1]);
            if (!(h_next > 0.0) || residual <= relative_tolerance * b_size) {
                ++k;
                break;
            }
            work.basis.col(k + 1) = w / h_next;
        }
        // d += M^-1 V y with R y = the rotated right-hand side.
        const Eigen::VectorXd y =
            work.hessenberg.topLeftCorner(k, k).triangularView<Eigen::Upper>().solve(work.rhs.head(k));
        w = work.basis.leftCols(k) * y;
        preconditioner.apply(w, z);
        d += z;
        if (!std::isfinite(residual) || !d.allFinite()) {
            d.setZero(n);
            break;
        }
        if (residual <= relative_tolerance * b_size || products >= max_iterations) break;
        // Restart from the true residual.
        objective.hessian_multiply(d, w);
        ++products;
        w = b - w;
        residual = std::sqrt(dot(w, w));
        if (residual <= relative_tolerance * b_size) break;
    }
    result.iterations = products;
    result.relative_residual = residual / b_size;
    result.converged = result.relative_residual <= relative_tolerance;
    if (d.squaredNorm() == 0.0) {  // never return a zero step
        preconditioner.apply(b, z);
        d = z * (b.dot(z) / std::max(z.squaredNorm(), 1e-300));
    }
    return result;
}

}  // namespace pnet
