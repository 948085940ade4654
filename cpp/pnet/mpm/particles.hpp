#pragma once
// MPM particle state (docs/methods.md), one array per field so that each
// transfer streams only the fields it needs.
#include <cstddef>
#include <vector>

#include "pnet/math/types.hpp"

namespace pnet {

template <int dim>
struct Particles {
    std::vector<Vec<dim>> x;          // position, m
    std::vector<Vec<dim>> v;          // velocity, m/s
    std::vector<Mat<dim>> C;          // APIC affine velocity matrix, 1/s
    std::vector<Mat<dim>> F_elastic;  // elastic deformation gradient F^E
    std::vector<double> hardening;    // Cam-Clay a, von Mises h = tau_Y / (2 mu); 0 for sand
    std::vector<double> mass;         // kg
    std::vector<double> rest_volume;  // V0, m^d
    std::vector<int> object;          // index of the scene object (and so of its material)

    std::size_t size() const { return x.size(); }

    void resize(std::size_t n) {
        x.resize(n);
        v.resize(n);
        C.resize(n, Mat<dim>::Zero());
        F_elastic.resize(n, Mat<dim>::Identity());
        hardening.resize(n);
        mass.resize(n);
        rest_volume.resize(n);
        object.resize(n);
    }
};

}  // namespace pnet
