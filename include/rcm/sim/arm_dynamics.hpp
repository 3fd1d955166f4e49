#pragma once
// Rigid-body dynamics and friction of the first three PSM joints (yaw and pitch
// about the RCM, insertion along the shaft), for the simulated bench.
//
// Three lumped bodies carry the mass model (ArmParams): the yaw link (rotates
// with q1), the pitch parallelogram (rotates with q1, q2) and the insertion stage
// (rotates with q1, q2 and slides with q3). The equations of motion
//   M(q) qdd + h(q, qd) + tau_f = tau_actuator - J_D^T f_tissue
// are evaluated by Newton-Euler in the base frame; M and h come from the same
// recursion, so the model is energy consistent by construction (tested).

#include <Eigen/Core>
#include <array>

#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/sim_config.hpp"

namespace rcm::sim {

// DH frame 3's axes in the base frame and dz3/dq1 = yaw_axis x z3 (dz3/dq2 =
// x3): the kinematics' closed forms, which the tests hold against the DH chain
// of the robot file, so the simulator's truth and the estimators share them
// without sharing a mistake.
using ShaftFrame = ShaftDirections;
inline ShaftFrame compute_shaft_frame(const Eigen::Vector3d& q) { return compute_shaft_directions(q); }
// Yaw axis in the base frame (constant): dz3/dq1 = yaw_axis x z3.
Eigen::Vector3d get_yaw_axis_base();

// Immutable model built once from ArmParams.
struct ArmDynamics {
  ArmParams params;
  Eigen::Matrix3d inertia_yaw_body = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d inertia_pitch_body = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d inertia_insertion_body = Eigen::Matrix3d::Zero();

  explicit ArmDynamics(const ArmParams& p);
};

// tau = M(q) qdd + C(q, qd) qd + g(q) (+ counterbalance when with_gravity).
Eigen::Vector3d compute_inverse_dynamics(const ArmDynamics& model, const Eigen::Vector3d& q,
                                         const Eigen::Vector3d& qd, const Eigen::Vector3d& qdd,
                                         bool with_gravity = true);
Eigen::Matrix3d compute_mass_matrix(const ArmDynamics& model, const Eigen::Vector3d& q);
double compute_kinetic_energy(const ArmDynamics& model, const Eigen::Vector3d& q,
                              const Eigen::Vector3d& qd);
// Gravity plus the insertion counterbalance spring (zero at q = 0).
double compute_potential_energy(const ArmDynamics& model, const Eigen::Vector3d& q);

// The friction's memory on the three joints: the LuGre bristles' deflection
// and each Maxwell-slip element's (rad, rad, m; column i: element i of
// JointFrictionParams::slip_elements, unused columns stay 0).
struct FrictionState {
  Eigen::Vector3d bristles = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, kMaxSlipElements> slip = Eigen::Matrix<double, 3, kMaxSlipElements>::Zero();
};

struct FrictionOutput {
  Eigen::Vector3d tau = Eigen::Vector3d::Zero();   // resisting torque/force, same sign as motion
  Eigen::Vector3d zdot = Eigen::Vector3d::Zero();  // of the bristles
};
// Friction of the three joints (JointFrictionParams: LuGre + Maxwell-slip +
// viscous + offset) at joint velocity qd.
FrictionOutput compute_friction(const std::array<JointFrictionParams, 3>& params, const FrictionState& state,
                                const Eigen::Vector3d& qd);
// Advances the state over dt with qd held constant: the bristles by the exact
// exponential solution of their (stiff) equation, each slip element by its
// travel clamped at its breakaway displacement, also exact. Stable at any dt.
FrictionState advance_friction_state(const std::array<JointFrictionParams, 3>& params, const FrictionState& state,
                                     const Eigen::Vector3d& qd, double dt);
// One scalar LuGre element (shared with the shaft's axial friction in the incision).
double compute_lugre_force(double coulomb_pos, double coulomb_neg, double stiction_ratio,
                           double stribeck_velocity, double sigma0, double sigma1, double z,
                           double v, double* zdot);
double advance_lugre_state(double coulomb_pos, double coulomb_neg, double stiction_ratio,
                           double stribeck_velocity, double sigma0, double z, double v, double dt);

}  // namespace rcm::sim
