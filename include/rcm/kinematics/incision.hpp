#pragma once
// Geometry of the misaligned incision (paper III-A, Eq. 2-9).
//
// The incision frame I has the orientation of DH frame 3 at the docking
// configuration q0 and its origin at the RCM. The pad (body wall) plane lies at
// the coaxial offset D along z_I. When the shaft pivots by theta away from z_I,
// it crosses that plane at distance s = D sec(theta) from the RCM; J_D is the
// Jacobian of the shaft's material point there.

#include <Eigen/Core>

#include "rcm/common/options_fwd.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm {

// Immutable: built once per docking configuration.
struct IncisionFrame {
  Eigen::Vector3d q0 = Eigen::Vector3d::Zero();
  Eigen::Matrix3d R_base_inc = Eigen::Matrix3d::Identity();  // columns x3(q0), y3(q0), z3(q0)
  Eigen::Vector3d z_inc_base() const { return R_base_inc.col(2); }
};

IncisionFrame make_incision_frame(const Eigen::Vector3d& q0);

// theta(q0, q): angle between z3(q0) and z3(q), in [0, pi] (Eq. 9). Computed with
// atan2(|z0 x z|, z0 . z), which keeps full precision near 0 where acos does not.
double compute_pivot_angle(const IncisionFrame& incision, const Eigen::Vector3d& q);

// Distance along the shaft from the RCM to the pad plane at offset D:
// D sec(theta) = D / (z_inc . z3(q)). Infinite when the shaft is parallel to the pad.
double compute_shaft_distance(const IncisionFrame& incision, const Eigen::Vector3d& q,
                              double D);

// J_D in the base frame, closed form: columns s dz3/dq1, s dz3/dq2, z3 with
// s = D sec(theta). This is the geometry; Eq. 8 as printed in the paper flips the
// sign of the first two columns (see tests/test_kinematics.cpp).
Eigen::Matrix3d compute_incision_jacobian(const Eigen::Vector3d& q, double shaft_distance);

// The same Jacobian built from the DH chain: the model's joints 1-2 followed by
// the 'inc' row of paper Table I (ref 2, a = 0, alpha = -pi/2, d = -s, theta = 0),
// with the geometric Jacobian z_i x (p_inc - o_i) for the revolute joints and the
// prismatic joint's axis z3 for joint 3.
Eigen::Matrix3d compute_incision_jacobian_dh(const PsmModel& model, KinematicsData& data,
                                             const Eigen::Vector3d& q, double shaft_distance);

enum class JacobianStatus { ok, ill_conditioned, singular };
const char* to_string(JacobianStatus status);

struct JacobianCheckOptions {
  // Above this 2-norm condition number a force estimate is flagged: at the
  // dVRK's torque noise (~0.02 N m) and D ~ 5 mm it already amplifies noise to
  // several newtons.
  double max_condition = 200.0;
  // Above this (or when not finite) the Jacobian is treated as singular.
  double singular_condition = 1e8;
};
const OptionTable<JacobianCheckOptions>& get_option_table(OptionTag<JacobianCheckOptions>);

struct JacobianCondition {
  double condition = 0.0;  // sigma_max / sigma_min, +inf when singular
  JacobianStatus status = JacobianStatus::ok;
};

// Condition of J_D at (q, s). Its columns are mutually orthogonal with norms
// |s| cos(q2), |s| and 1, so the singular values are exact.
JacobianCondition compute_incision_jacobian_condition(const Eigen::Vector3d& q,
                                                      double shaft_distance,
                                                      const JacobianCheckOptions& options = {});

}  // namespace rcm
