#pragma once
// Continuous collision detection of IPC's 3D contact primitives for the line
// search (docs/methods.md): the largest fraction t of a linear motion
// x0 -> x0 + dx that a pair can take without touching.
//
// Point-triangle and edge-edge: additive CCD (Li, Kaufman, Jiang 2021), as the 2D
// point_edge_time_of_impact (ccd.hpp). The pair's mean displacement is removed (a
// common translation changes no distance); then
//   l_p = |u_p| + max(|u_a|, |u_b|, |u_c|)            (point-triangle)
//   l_p = max(|u_a0|, |u_a1|) + max(|u_b0|, |u_b1|)    (edge-edge)
// bounds how fast the distance d can shrink per unit t, so a step of
// t_l = eta (d - xi) / l_p cannot reach the gap xi. The steps are repeated until
// the distance has fallen below (1 - eta) of its start (or t passes t_max). The
// result never exceeds the true time of impact and the pair moved to it keeps a
// distance of at least xi + (1 - eta)(d0 - xi) > xi. A slow grazing approach
// (over 100000 steps) stops at the safe time reached so far.
// Point-plane: point_plane_time_of_impact (ccd.hpp), for both dimensions.
#include "pnet/contact/ccd/point_edge.hpp"  // kNoImpact, point_plane_time_of_impact
#include "pnet/math/types.hpp"

namespace pnet {

/// Time of impact in [0, t_max] of point p and triangle abc moving by dp, da, db, dc,
/// or kNoImpact if none before t_max; 0 if they are already within min_distance
/// xi >= 0 (the gap kept). eta: the conservative rescaling in (0, 1).
double point_triangle_time_of_impact(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                     const Vec<3>& dp, const Vec<3>& da, const Vec<3>& db, const Vec<3>& dc,
                                     double min_distance = 0.0, double t_max = 1.0, double eta = 0.9);

/// Time of impact in [0, t_max] of edges a0a1 and b0b1 moving by da0, da1, db0, db1
/// (as point_triangle_time_of_impact()).
double edge_edge_time_of_impact(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1,
                                const Vec<3>& da0, const Vec<3>& da1, const Vec<3>& db0, const Vec<3>& db1,
                                double min_distance = 0.0, double t_max = 1.0, double eta = 0.9);

}  // namespace pnet
