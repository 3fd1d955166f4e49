#pragma once
// The arm as its motors drive it: the rigid links of arm_dynamics.hpp, each
// joint driven by a motor through a cable transmission (ArmParams::transmission),
// the joint's LuGre friction split between the motor side and the link side.
//
// On a compliant joint (stiffness > 0) motor and link are two bodies:
//   J_m qmdd = tau - tau_c - f_motor(z_m, qmd)
//   M(q) qdd + h(q, qd) + f_link(z_l, qd) + tau_ext = tau_c
//   tau_c = k (qm - q) + c (qmd - qd)
// On a rigid joint (stiffness 0) the motor is the link: qm = q, J_m joins M's
// diagonal, and tau and f_motor act on the link equation. tau is the motor
// torque (what the current gives, the logged effort); tau_ext = J_D^T f the
// tissue's. The encoders read qm, so the controller and the recording see the
// motor, and the tissue sees the link.

#include <Eigen/Core>
#include <array>

#include "rcm/sim/arm_dynamics.hpp"
#include "rcm/sim/sim_config.hpp"

namespace rcm::sim {

// Immutable, built once from the arm and its friction.
struct Plant {
  ArmDynamics arm;
  std::array<JointTransmissionParams, 3> transmission;
  std::array<JointFrictionParams, 3> friction;
  Eigen::Vector3d rotor_inertia = Eigen::Vector3d::Zero();
  Eigen::Vector3d link_share = Eigen::Vector3d::Zero();  // of each joint's friction
  std::array<bool, 3> compliant{};

  Plant(const ArmParams& arm_params, const std::array<JointFrictionParams, 3>& friction_params);
};

struct PlantState {
  Eigen::Vector3d q = Eigen::Vector3d::Zero(), qd = Eigen::Vector3d::Zero();    // link
  Eigen::Vector3d qm = Eigen::Vector3d::Zero(), qmd = Eigen::Vector3d::Zero();  // motor (= link when rigid)
  FrictionState friction_link, friction_motor;  // the friction's memory on each side of the cable
};

// At rest at link position q with the cables carrying gravity (and the
// counterbalance), friction relaxed: the state a long hold at q settles to
// without friction.
PlantState make_plant_state_at_rest(const Plant& plant, const Eigen::Vector3d& q);

struct PlantAcceleration {
  Eigen::Vector3d qdd = Eigen::Vector3d::Zero();   // link
  Eigen::Vector3d qmdd = Eigen::Vector3d::Zero();  // motor (= qdd on a rigid joint)
  Eigen::Vector3d cable = Eigen::Vector3d::Zero(); // tau_c (0 on a rigid joint)
  Eigen::Vector3d friction_link = Eigen::Vector3d::Zero(), friction_motor = Eigen::Vector3d::Zero();
  // tau - tau_ext = J_m qmdd + f_motor + M qdd + h + f_link: what a perfect
  // free-space model predicts, friction state included.
  Eigen::Vector3d tau_fs = Eigen::Vector3d::Zero();
};

PlantAcceleration compute_plant_acceleration(const Plant& plant, const PlantState& state,
                                             const Eigen::Vector3d& tau, const Eigen::Vector3d& tau_ext);

// One step of semi-implicit Euler (velocities first, positions with the new
// velocities; a rigid joint's motor follows its link) and the friction states by
// their exact exponential update.
void advance_plant_state(const Plant& plant, PlantState& state, const PlantAcceleration& acc, double dt);

// Kinetic energy of links and rotors, gravity and counterbalance, and the
// cables' elastic energy. Without friction, d/dt energy = tau . qmd - cable
// damping losses - tau_ext . qd (tested).
double compute_plant_energy(const Plant& plant, const PlantState& state);

// The first natural frequency (Hz) of one compliant joint's link against its
// motor held still: sqrt(k / m) / 2 pi, m the joint's own diagonal of M(q).
double compute_cable_mode_hz(const Plant& plant, const Eigen::Vector3d& q, int joint);

}  // namespace rcm::sim
