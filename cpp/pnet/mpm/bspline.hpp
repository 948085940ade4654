#pragma once
// Quadratic B-spline interpolation weights of MPM (Jiang et al. 2016, the
// APIC/MLS-MPM course notes): a particle at x touches the 3^d grid nodes from
// base = floor(x/dx - 0.5); with f = x/dx - base in [0.5, 1.5),
//   w0 = (1.5 - f)^2 / 2,   w1 = 0.75 - (f - 1)^2,   w2 = (f - 0.5)^2 / 2,
// and dw/dx = (f - 1.5, -2 (f - 1), f - 0.5) / dx. Node k of the stencil sits
// at (base + k) dx, so x_i - x_p = (k - f) dx.
#include <cmath>

#include "pnet/math/types.hpp"

namespace pnet {

template <int dim>
struct BSplineStencil {
    int base[dim];
    double w[dim][3];    // weight per axis and stencil node
    double dw[dim][3];   // d w / d x per axis, 1/m
    double offset[dim];  // f = x/dx - base, so x_i - x_p = (k - offset) dx

    /// Position x relative to the grid origin, m.
    BSplineStencil(const Vec<dim>& x, double inv_dx) {
        for (int a = 0; a < dim; ++a) {
            const double s = x[a] * inv_dx;
            base[a] = static_cast<int>(std::floor(s - 0.5));
            const double f = s - base[a];
            offset[a] = f;
            w[a][0] = 0.5 * (1.5 - f) * (1.5 - f);
            w[a][1] = 0.75 - (f - 1.0) * (f - 1.0);
            w[a][2] = 0.5 * (f - 0.5) * (f - 0.5);
            dw[a][0] = (f - 1.5) * inv_dx;
            dw[a][1] = -2.0 * (f - 1.0) * inv_dx;
            dw[a][2] = (f - 0.5) * inv_dx;
        }
    }

    /// Weight and its gradient at stencil node k (k[a] in 0..2).
    double weight(const int* k) const {
        double value = 1.0;
        for (int a = 0; a < dim; ++a) value *= w[a][k[a]];
        return value;
    }
    Vec<dim> gradient(const int* k) const {
        Vec<dim> g;
        for (int a = 0; a < dim; ++a) {
            double value = dw[a][k[a]];
            for (int b = 0; b < dim; ++b)
                if (b != a) value *= w[b][k[b]];
            g[a] = value;
        }
        return g;
    }
};

}  // namespace pnet
