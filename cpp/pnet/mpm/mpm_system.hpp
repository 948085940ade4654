#pragma once
// What stays fixed during an MPM run: the grid geometry, gravity, boundary
// conditions and one material per scene object. Every integrator (explicit,
// plasticitynet, lagged) works on the same system and particles, so results
// differ only by the time integration (docs/methods.md).
#include <array>
#include <vector>

#include "pnet/material/material.hpp"
#include "pnet/math/types.hpp"
#include "pnet/mpm/grid.hpp"

namespace pnet {

template <int dim>
struct MpmSystem {
    Vec<dim> origin = Vec<dim>::Zero();   // domain minimum, m
    double dx = 1.0 / 64;                 // m
    std::array<int, dim> cells{};         // per axis
    Vec<dim> gravity = Vec<dim>::Zero();  // m/s^2
    BoundaryConditions boundary;
    // Transfers: 0, APIC (G2P replaces v_p by the grid's velocity every step). > 0: AFLIP, the part of
    // v_p the grid does not carry decays as exp(-t / flip_relaxation_time) instead (transfer.hpp).
    double flip_relaxation_time = 0.0;    // s
    std::vector<Material<dim>> materials; // indexed by Particles::object
    std::vector<double> density;          // kg/m^3, per object

    /// Largest P-wave speed sqrt((lambda + 2 mu) / rho) over the materials, m/s.
    double max_wave_speed() const;
};

}  // namespace pnet
