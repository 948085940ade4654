#pragma once
// Bit-for-bit comparisons of two runs' states (a resumed checkpoint, another thread count) and a
// scene's integrator settings with another integrator and step, for the simulation tests.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "pnet/fem/fem_integrator.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/sim/run_stats.hpp"
#include "support/temp_dir.hpp"

namespace pnet::test {

/// The scene's integrator settings with `integrator` and the step dt (s).
inline IntegratorSettings settings_for(const Scene& scene, const std::string& integrator, double dt) {
    IntegratorSettings s = IntegratorSettings::from_scene(scene);
    s.name = integrator;
    s.dt = dt;
    return s;
}

template <typename T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

/// Each of `fields` (pointers to vector members) is the same in a and b, bit for bit; a failure
/// names the field by its place in the list.
template <typename State, typename... Field>
void expect_same_fields(const State& a, const State& b, Field... fields) {
    int k = 0;
    for (const bool same : {same_bytes(a.*fields, b.*fields)...}) EXPECT_TRUE(same) << "field " << k++ << " differs";
}

/// The particles' positions, velocities, C, elastic F and hardening are identical.
template <int dim>
bool identical(const Particles<dim>& a, const Particles<dim>& b) {
    return same_bytes(a.x, b.x) && same_bytes(a.v, b.v) && same_bytes(a.C, b.C) &&
           same_bytes(a.F_elastic, b.F_elastic) && same_bytes(a.hardening, b.hardening);
}

/// identical(a, b), field by field.
template <int dim>
void expect_identical(const Particles<dim>& a, const Particles<dim>& b) {
    using P = Particles<dim>;
    expect_same_fields(a, b, &P::x, &P::v, &P::C, &P::F_elastic, &P::hardening);
}

/// The nodes' positions and velocities, the elements' plastic state and BDF2's history are identical.
template <int dim>
void expect_identical(const FemState<dim>& a, const FemState<dim>& b) {
    using S = FemState<dim>;
    expect_same_fields(a, b, &S::x, &S::v, &S::plastic_inverse, &S::hardening, &S::x_previous, &S::v_previous);
}

/// Runs `uninterrupted` `frames` frames, and `first` `split` frames, checkpoints it and resumes
/// `resumed` from that file for the rest: the frame and step counts carry over, and the folder
/// holds the checkpoint alone (no temporary file left). The caller compares the states.
template <typename Simulation>
void resume_from_checkpoint(Simulation& uninterrupted, Simulation& first, Simulation& resumed, int split, int frames) {
    TempDir dir;
    for (int f = 0; f < frames; ++f) uninterrupted.advance_frame();
    for (int f = 0; f < split; ++f) first.advance_frame();
    first.save_checkpoint(dir.file("state.bin"));
    resumed.load_checkpoint(dir.file("state.bin"));
    EXPECT_EQ(resumed.frame(), split);
    EXPECT_EQ(resumed.total_steps(), first.total_steps());
    for (int f = split; f < frames; ++f) resumed.advance_frame();
    EXPECT_EQ(resumed.total_steps(), uninterrupted.total_steps());
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"state.bin"});
}

}  // namespace pnet::test
