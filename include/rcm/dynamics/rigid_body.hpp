#pragma once
// Rigid-body structure of the free-space torque of a yaw (q1) / pitch (q2) /
// insertion (q3) arm whose pitch axis is perpendicular to its yaw axis (the dVRK
// PSM and any arm that pivots the same way), linear in its parameters.
//
// Inertia. Every link rotates with q1, or with q1 and q2 (the parallelogram's
// links by q2 plus a constant), and the insertion stage also translates by q3,
// so the kinetic energy of any set of rigid links is
//   T = sum_k theta_k g_k(q2, q3) s_k(qd),
// s_k a product qd_a qd_b (1/2 qd_a^2 on the diagonal) and g_k in
//   qd1^2:   {1, cos 2q2, sin 2q2} x {1, q3, q3^2}
//   qd1 qd2: {cos q2, sin q2} x {1, q3, q3^2}
//   qd2^2:   {1, q3, q3^2}
//   qd1 qd3: {cos q2, sin q2};  qd2 qd3: 1;  qd3^2: 1
// (q1 is cyclic). The torque is Lagrange's d/dt dT/dqd - dT/dq: inertia that
// changes with the configuration (the yaw inertia with the pitch and the
// insertion depth) and the velocity products (Coriolis, centripetal) in one set.
// The three constant diagonal terms are each joint's armature, kept apart in
// the linear model; the other 19 are the regressor below.
//
// Gravity. The potential of rigid links under a base tilted so that gravity
// points along the unit vector g (base frame) is
//   U = g . Rz(q1) [v0 + Rx(q2) (v1 + q3 v2)],
// the v's the mass moments of the links (mass times centre, times |g|) in the
// yaw and pitch frames. Any axis conventions reduce to this (a fixed rotation
// about z aligns the pitch axis with x and moves into g; joint offsets move into
// the v's). Of the 9 moments, 7 have a torque (v0's components along x and z
// merge with v1x or give a constant), and for a given g the potential is linear
// in them and lies in the span of the 17 generic terms of
// LinearTorqueModel::compute_gravity_regressor: compute_gravity_moment_map gives
// the 17 x 7 map. 7 moments and 2 angles instead of 17 free coefficients is what
// stops the potential from absorbing inertia on a short periodic path, where
// qddot is nearly a function of q.

// The bodies of a remote-centre arm. The 19 inertia coefficients above are
// those of any rigid links on such a chain; the links of an arm that pivots
// about a remote centre of motion (RCM) and slides its instrument through it
// tie them together. Every link that turns with yaw and pitch about the RCM
// has an inertia tensor I about the RCM; everything that slides with the
// insertion (carriage, instrument) is one body of mass m and first moment h
// (mass times centre, at q3 = 0, pitch frame) moving along the instrument
// axis e = (0, sin beta, cos beta) of the pitch frame, beta the angle between
// the instrument axis and the yaw axis at q2 = 0 (90 deg on the dVRK PSM). In
// the pitch frame, with w = (qd2, qd1 sin q2, qd1 cos q2),
//   T = 1/2 w.I.w + q3 [|w|^2 (e.h) - (w.e)(w.h)] + 1/2 m q3^2 [|w|^2 - (w.e)^2]
//       + qd3 w.(h x e) + 1/2 m qd3^2,
// so the 19 coefficients are linear in 8 parameters [m, h (3), and the four
// entries of I that are not constant, (I_zz - I_yy) / 2, I_yz, I_xz, I_xy]
// (the constant ones join the armatures, and m joins the insertion's). What a
// slow run cannot tell apart (the q3-dependence of the yaw and pitch inertia,
// the velocity products) is then fixed by what it can (the sliding mass).

#include <Eigen/Core>

namespace rcm::dynamics {

constexpr int kInertiaTerms = 19;
// beta of every robot rcm loads: the instrument axis is perpendicular to the
// yaw axis at q2 = 0 (the insertion axis z3(q), docs/formats.md).
constexpr double kInstrumentAxisAngle = 1.5707963267948966;
constexpr int kGravityMoments = 7;
constexpr int kRemoteCenterTerms = 8;

// dtau / dtheta of the 19 non-constant energy terms above at (q, qd, qdd),
// joints 1-3.
void compute_inertia_regressor(const double* q, const double* qd, const double* qdd,
                               Eigen::Matrix<double, 3, kInertiaTerms>& Y);

// T of the 19 terms with coefficients theta (what compute_inertia_regressor
// differentiates; for tests and documentation).
double compute_inertia_energy(const Eigen::Matrix<double, kInertiaTerms, 1>& theta, const double* q,
                              const double* qd);

// M such that the 19 inertia coefficients are M x for the remote-centre
// parameters x = [m, h_x, h_y, h_z, (I_zz - I_yy) / 2, I_yz, I_xz, I_xy] at
// instrument-axis angle beta (rad); the insertion's armature gains m.
void compute_remote_center_map(double beta, Eigen::Matrix<double, kInertiaTerms, kRemoteCenterTerms>& M);

// T above for the remote-centre parameters x, the armatures left out (for tests
// and documentation).
double compute_remote_center_energy(double beta, const Eigen::Matrix<double, kRemoteCenterTerms, 1>& x,
                                    const double* q, const double* qd);

// P such that the 17 generic potential coefficients are P v for the moments
// v = [v0y, v1x, v1y, v1z, v2x, v2y, v2z] under gravity direction g.
void compute_gravity_moment_map(const Eigen::Vector3d& g, Eigen::Matrix<double, 17, kGravityMoments>& P);

// U above for moments v (v0 = [0, v0y, 0]); its gradient is the torque that
// compute_gravity_moment_map's coefficients give.
double compute_rigid_body_potential(const Eigen::Vector3d& g, const Eigen::Matrix<double, kGravityMoments, 1>& v,
                                    const double* q);

}  // namespace rcm::dynamics
