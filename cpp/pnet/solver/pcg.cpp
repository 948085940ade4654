#include "pnet/solver/pcg.hpp"

#include <cmath>

namespace pnet {

PcgResult solve_pcg(const Objective& objective, const VecX& b, const VecX& inverse_diagonal, VecX& d,
                    double relative_tolerance, int max_iterations) {
    PcgResult result;
    const Eigen::Index n = b.size();
    d.setZero(n);
    const double b_norm = b.norm();
    if (b_norm == 0.0) {
        result.converged = true;
        return result;
    }
    VecX r = b, z = inverse_diagonal.cwiseProduct(r), p = z, Hp(n);
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
        z = inverse_diagonal.cwiseProduct(r);
        const double rz_next = r.dot(z);
        p = z + (rz_next / rz) * p;
        rz = rz_next;
    }
    return result;
}

}  // namespace pnet
