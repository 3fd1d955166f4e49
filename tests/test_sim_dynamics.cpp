// Physics of the simulated bench: rigid-body energy balance, derivatives of the
// reference motions, LuGre memory, tissue geometry against the contract's J_D.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "rcm/common/error.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/arm_dynamics.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/tissue.hpp"
#include "rcm/sim/trajectory.hpp"

using namespace rcm::sim;

namespace {

// A smooth joint trajectory with analytic derivatives.
struct Wave {
  Eigen::Vector3d c, a, w, p;
  void eval(double t, Eigen::Vector3d& q, Eigen::Vector3d& qd, Eigen::Vector3d& qdd) const {
    for (int j = 0; j < 3; ++j) {
      q[j] = c[j] + a[j] * std::sin(w[j] * t + p[j]);
      qd[j] = a[j] * w[j] * std::cos(w[j] * t + p[j]);
      qdd[j] = -a[j] * w[j] * w[j] * std::sin(w[j] * t + p[j]);
    }
  }
};

}  // namespace

TEST(SimDynamics, JointPowerEqualsRateOfEnergy) {
  const SimConfig config = make_default_config();
  const ArmDynamics arm(config.arm);
  const Wave wave{{0.1, -0.05, 0.12}, {0.5, 0.4, 0.03}, {2.1, 3.3, 4.7}, {0.3, 1.1, -0.7}};
  const double h = 1e-5;
  double max_power = 0.0;
  for (double t = 0.0; t < 3.0; t += 0.137) {
    Eigen::Vector3d q, qd, qdd;
    wave.eval(t, q, qd, qdd);
    const Eigen::Vector3d tau = compute_inverse_dynamics(arm, q, qd, qdd, true);
    const double power = tau.dot(qd);
    auto energy = [&](double time) {
      Eigen::Vector3d a, b, c;
      wave.eval(time, a, b, c);
      return compute_kinetic_energy(arm, a, b) + compute_potential_energy(arm, a);
    };
    const double dE = (energy(t + h) - energy(t - h)) / (2.0 * h);
    // Central difference: truncation ~h^2 E''' (< 1e-8 here), rounding ~1e-16 E / h.
    EXPECT_NEAR(power, dE, 1e-7) << "t = " << t;
    max_power = std::max(max_power, std::abs(power));
  }
  EXPECT_GT(max_power, 0.5);  // the check covered real motion, not a resting arm
}

TEST(SimDynamics, MassMatrixMatchesKineticEnergyAndDefaults) {
  const SimConfig config = make_default_config();
  const ArmDynamics arm(config.arm);
  const Eigen::Vector3d q(0.3, -0.2, 0.1), qd(0.7, -0.4, 0.05);
  const Eigen::Matrix3d M = compute_mass_matrix(arm, q);
  EXPECT_NEAR(0.5 * qd.dot(M * qd), compute_kinetic_energy(arm, q, qd), 1e-12);
  EXPECT_GT(M.llt().matrixL().toDenseMatrix().diagonal().minCoeff(), 0.0);
  // Effective inertias of the simulated arm at q0: 0.16 / 0.20 kg m^2, 0.85 kg.
  const Eigen::Matrix3d M0 = compute_mass_matrix(arm, config.protocol.q0);
  EXPECT_NEAR(M0(0, 0), 0.16, 0.005);
  EXPECT_NEAR(M0(1, 1), 0.20, 0.005);
  EXPECT_NEAR(M0(2, 2), 0.85, 1e-12);
}

TEST(SimDynamics, GravityIsGradientOfPotential) {
  const SimConfig config = make_default_config();
  const ArmDynamics arm(config.arm);
  const Eigen::Vector3d q(0.4, 0.3, 0.09), zero = Eigen::Vector3d::Zero();
  const Eigen::Vector3d g = compute_inverse_dynamics(arm, q, zero, zero, true);
  const double h = 1e-6;
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(j);
    const double fd = (compute_potential_energy(arm, q + e) - compute_potential_energy(arm, q - e)) / (2 * h);
    EXPECT_NEAR(g[j], fd, 1e-7) << "joint " << j + 1;
  }
}

TEST(SimTrajectory, TeleopDerivativesMatchFiniteDifferences) {
  const SimConfig config = make_default_config();
  // 200 s: several segments, so the cross-fades between draws are checked too.
  const TeleopPath path(config.trajectory, config.protocol.q0, 42, 200.0);
  const double h = 1e-5;
  int moving = 0;
  // Off t = 0: the pause ramps are C2, so the jerk jumps at their ends.
  for (double t = 0.05; t < 200.0; t += 0.231) {
    const ReferenceSample r = path.evaluate(t), a = path.evaluate(t + h), b = path.evaluate(t - h);
    const Eigen::Vector3d qd_fd = (a.q - b.q) / (2 * h);
    const Eigen::Vector3d qdd_fd = (a.qd - b.qd) / (2 * h);
    // Truncation ~h^2 q''' / 6 (q''' < 50), rounding ~1e-16 / h.
    EXPECT_LT((r.qd - qd_fd).norm(), 1e-7) << "t = " << t;
    EXPECT_LT((r.qdd - qdd_fd).norm(), 1e-6) << "t = " << t;
    for (int j = 0; j < 3; ++j) {
      EXPECT_LE(std::abs(r.q[j] - config.protocol.q0[j]), config.trajectory.amplitude[j] + 1e-12);
    }
    if (r.qd.head<2>().norm() > 0.05) ++moving;
  }
  EXPECT_GT(moving, 400);
  // Starts at q0, at rest.
  const ReferenceSample s = path.evaluate(0.0);
  EXPECT_LT((s.q - config.protocol.q0).norm(), 1e-12);
  EXPECT_LT(s.qd.norm(), 1e-12);
}

// The identification-style excitation: derivatives (across the ramp's end too),
// the amplitude bound, rest at q0 at the start, and exact periodicity after the
// ramp.
TEST(SimTrajectory, ExcitationDerivativesBoundsStartAndPeriod) {
  SimConfig config = make_default_config();
  config.trajectory.free_space_path = "excitation";
  const ExcitationPath path(config.trajectory, config.protocol.q0, 42);
  const double h = 1e-5, period = config.trajectory.excitation_period_s;
  for (double t = 0.013; t < 3.0 * period; t += 0.0371) {
    const ReferenceSample r = path.evaluate(t), a = path.evaluate(t + h), b = path.evaluate(t - h);
    EXPECT_LT((r.qd - (a.q - b.q) / (2 * h)).norm(), 1e-7) << "t = " << t;
    EXPECT_LT((r.qdd - (a.qd - b.qd) / (2 * h)).norm(), 1e-6) << "t = " << t;
    for (int j = 0; j < 3; ++j)
      EXPECT_LE(std::abs(r.q[j] - config.protocol.q0[j]), config.trajectory.amplitude[j] + 1e-12);
    if (t > config.trajectory.excitation_ramp_s) {
      const ReferenceSample later = path.evaluate(t + period);
      EXPECT_LT((later.q - r.q).norm(), 1e-9) << "t = " << t;
      EXPECT_LT((later.qd - r.qd).norm(), 1e-8) << "t = " << t;
    }
  }
  const ReferenceSample s = path.evaluate(0.0);
  EXPECT_LT((s.q - config.protocol.q0).norm(), 1e-15);
  EXPECT_LT(s.qd.norm(), 1e-15);
  EXPECT_LT(s.qdd.norm(), 1e-15);
  config.trajectory.free_space_path = "sweep";
  EXPECT_THROW(validate_config(config), rcm::InputError);
}

TEST(SimTrajectory, TeleopHasPauses) {
  SimConfig config = make_default_config();
  config.trajectory.pause_fraction = 0.3;
  const TeleopPath path(config.trajectory, config.protocol.q0, 7, 120.0);
  int still = 0, total = 0;
  for (double t = 1.0; t < 120.0; t += 0.01, ++total)
    if (path.evaluate(t).qd.norm() < 1e-9) ++still;
  // Fully stopped during the flat part of each pause (ramps excluded).
  EXPECT_GT(still, total / 10);
  EXPECT_LT(still, total / 2);
}

TEST(SimTrajectory, QuinticMoveMeetsBoundaryConditionsAndDerivatives) {
  ReferenceSample from;
  from.q = Eigen::Vector3d(0.2, -0.1, 0.1);
  from.qd = Eigen::Vector3d(0.3, 0.1, -0.01);
  from.qdd = Eigen::Vector3d(-1.0, 0.5, 0.02);
  const Eigen::Vector3d to(0.0, 0.0, 0.12);
  const QuinticMove m = QuinticMove::make(1.0, 2.0, from, to);
  const ReferenceSample a = m.evaluate(1.0), b = m.evaluate(3.0);
  EXPECT_LT((a.q - from.q).norm(), 1e-14);
  EXPECT_LT((a.qd - from.qd).norm(), 1e-14);
  EXPECT_LT((a.qdd - from.qdd).norm(), 1e-14);
  EXPECT_LT((b.q - to).norm(), 1e-12);
  const ReferenceSample c = m.evaluate(2.999999);
  EXPECT_LT(c.qd.norm(), 1e-5);
  EXPECT_LT(c.qdd.norm(), 1e-4);
  const double h = 1e-6, t = 1.7;
  EXPECT_LT((m.evaluate(t).qd - (m.evaluate(t + h).q - m.evaluate(t - h).q) / (2 * h)).norm(), 1e-8);
  EXPECT_LT((m.evaluate(t).qdd - (m.evaluate(t + h).qd - m.evaluate(t - h).qd) / (2 * h)).norm(), 1e-7);
}

TEST(SimFriction, HoldingForceDependsOnApproachDirection) {
  SimConfig config = make_default_config();
  apply_friction_preset(config, "hysteretic");
  const auto& fp = config.friction;
  const double dt = 5e-4;
  auto hold_after = [&](double v) {
    FrictionState z;
    for (int i = 0; i < 2000; ++i) z = advance_friction_state(fp, z, Eigen::Vector3d::Constant(v), dt);
    return compute_friction(fp, z, Eigen::Vector3d::Zero()).tau;  // at rest now
  };
  const Eigen::Vector3d up = hold_after(0.05), down = hold_after(-0.05);
  for (int j = 0; j < 3; ++j) {
    const auto& p = fp[static_cast<std::size_t>(j)];
    // Sliding has loaded the bristles to about the Coulomb level, which stays at rest.
    EXPECT_NEAR(up[j] - p.offset, p.coulomb_pos, 0.05 * p.coulomb_pos) << "joint " << j + 1;
    EXPECT_NEAR(down[j] - p.offset, -p.coulomb_neg, 0.05 * p.coulomb_neg) << "joint " << j + 1;
  }
}

// The Maxwell-slip elements of the real preset, one joint at a time: sliding
// far one way leaves the sum of the element forces (plus the offset) at rest;
// after a reversal the friction changes by sum_i min(2 F_i, F_i travel / x_i),
// at any speed (Masing's rule of the rate-independent model).
TEST(SimFriction, MaxwellSlipLoopFollowsMasingRule) {
  const SimConfig config = make_default_config();
  ASSERT_EQ(config.friction_preset, "real");
  const auto& fp = config.friction;
  for (int j = 0; j < 3; ++j) {
    const auto& p = fp[static_cast<std::size_t>(j)];
    ASSERT_GE(p.slip_elements.size(), 4u) << "joint " << j + 1;
    double level = 0.0;
    for (const auto& e : p.slip_elements) level += e[1];
    const double far = 2.0 * p.slip_elements.back()[0];
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    FrictionState z;
    v[j] = 0.05;  // slide far in +q, in steps that move 1 % of the smallest element each
    const double dt = 0.01 * p.slip_elements.front()[0] / v[j];
    for (double x = 0.0; x < far; x += v[j] * dt) z = advance_friction_state(fp, z, v, dt);
    const double held = compute_friction(fp, z, Eigen::Vector3d::Zero()).tau[j];
    EXPECT_NEAR(held, level + p.offset, 1e-9 * level) << "joint " << j + 1;
    for (const double speed : {0.002, 0.2}) {
      FrictionState back = z;
      const double travel = p.slip_elements[p.slip_elements.size() / 2][0];  // the middle element's breakaway
      v[j] = -speed;
      const int steps = 1000;
      for (int k = 0; k < steps; ++k) back = advance_friction_state(fp, back, v, travel / speed / steps);
      double expected = 0.0;
      for (const auto& e : p.slip_elements) expected += std::min(2.0 * e[1], e[1] * travel / e[0]);
      const double change = held - compute_friction(fp, back, Eigen::Vector3d::Zero()).tau[j];
      EXPECT_NEAR(change, expected, 1e-6 * level) << "joint " << j + 1 << " at " << speed;
    }
    v[j] = 0.0;
  }
}

TEST(SimFriction, StaticHoldInClosedLoopRemembersTheApproach) {
  for (const std::string preset : {"real", "hysteretic"}) {
    SimConfig config = make_default_config();
    apply_friction_preset(config, preset);
    config.sensors.noise = false;
    const Eigen::Vector3d q0 = config.protocol.q0;
    auto held_friction = [&](double sign) {
      ReferenceTrajectory ref;
      ref.add_hold(0.0, q0 + sign * Eigen::Vector3d(0.2, 0.2, 0.02));
      ref.add_move(0.0, 1.5, q0);
      ref.add_hold(1.5, q0);
      const auto recs = simulate_run(config, ref, nullptr, {{"hold", 0.0, 3.0}}, 1);
      return Eigen::Vector3d(recs.front().truth.friction.bottomRows(1).transpose());
    };
    const Eigen::Vector3d from_above = held_friction(+1.0), from_below = held_friction(-1.0);
    // Approaching q0 from above means moving in -q: friction at rest keeps the
    // sign of that motion, the level a long motion leaves (the LuGre Coulomb
    // level, the slip elements' sum) on either side.
    for (int j = 0; j < 3; ++j) {
      const auto& p = config.friction[static_cast<std::size_t>(j)];
      double level = p.coulomb_pos;
      for (const auto& e : p.slip_elements) level += e[1];
      EXPECT_GT(from_below[j] - from_above[j], level) << preset << " joint " << j + 1;
    }
  }
}

TEST(SimTissue, StretchIsDTanThetaAndForceLiesInThePad) {
  TissueParams params;
  params.stiffness_n_per_m = 800.0;
  const Eigen::Vector3d q0(0.1, -0.2, 0.12);
  const TissueModel tissue(params, q0, Eigen::Vector3d(0.0, 0.0, 0.03));
  const Eigen::Vector3d n = tissue.R_base_inc.col(2);
  for (const Eigen::Vector3d dq : {Eigen::Vector3d(0.3, 0.0, 0), Eigen::Vector3d(-0.2, 0.4, 0.01),
                                   Eigen::Vector3d(0.5, -0.3, -0.02)}) {
    const Eigen::Vector3d q = q0 + dq;
    const TissueOutput out = compute_tissue_force(tissue, q, Eigen::Vector3d::Zero(), 0.0);
    EXPECT_NEAR(out.stretch_base.norm(), 0.03 * std::tan(out.theta), 1e-14);  // paper Eq. 2
    EXPECT_NEAR(out.f_inc_base.norm(), 800.0 * 0.03 * std::tan(out.theta), 1e-10);
    EXPECT_NEAR(out.f_inc_base.dot(n), 0.0, 1e-12);
    EXPECT_GT(out.f_inc_base.dot(out.stretch_base), 0.0);  // pulls the tissue toward the shaft
  }
}

TEST(SimTissue, JacobianIsTheContractsJD) {
  const rcm::PsmModel robot = rcm::load_robot_model("dvrk-psm-classic");
  rcm::KinematicsData data;
  TissueParams params;
  const Eigen::Vector3d q0(0.0, 0.0, 0.12);
  const TissueModel tissue(params, q0, Eigen::Vector3d(0.01, 0.015, 0.04));
  const rcm::IncisionFrame frame = rcm::make_incision_frame(q0);
  for (const Eigen::Vector3d q : {Eigen::Vector3d(0.3, 0.1, 0.1), Eigen::Vector3d(-0.4, -0.35, 0.14)}) {
    const TissueOutput out = compute_tissue_force(tissue, q, Eigen::Vector3d::Zero(), 0.0);
    const double s = rcm::compute_shaft_distance(frame, q, 0.04);
    EXPECT_NEAR(out.shaft_distance, s, 1e-14);
    EXPECT_LT((out.J_inc_base - rcm::compute_incision_jacobian(q, s)).norm(), 1e-14);
    EXPECT_LT((out.J_inc_base - rcm::compute_incision_jacobian_dh(robot, data, q, s)).norm(), 1e-12);
    EXPECT_NEAR(out.theta, rcm::compute_pivot_angle(frame, q), 1e-14);
    // Material point: velocity = J qd (finite difference of s_fixed * z3(q) + q3 shift).
    const double h = 1e-7;
    for (int j = 0; j < 2; ++j) {
      const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(j);
      const Eigen::Vector3d fd =
          (s * compute_shaft_frame(q + e).z3 - s * compute_shaft_frame(q - e).z3) / (2 * h);
      EXPECT_LT((out.J_inc_base.col(j) - fd).norm(), 1e-8);
    }
  }
}

TEST(SimTissue, CrossingVelocityMatchesFiniteDifference) {
  TissueParams params;
  params.stiffness_n_per_m = 0.0;
  params.damping_n_s_per_m = 1.0;  // then f = d(p_cross)/dt exactly
  const Eigen::Vector3d q0(0.05, 0.1, 0.12);
  const TissueModel tissue(params, q0, Eigen::Vector3d(0.0, 0.0, 0.035));
  const Eigen::Vector3d q(0.3, -0.2, 0.11), qd(0.4, -0.7, 0.02);
  const double h = 1e-6;
  const Eigen::Vector3d fd =
      (compute_tissue_force(tissue, q + h * qd, qd, 0.0).p_cross_base -
       compute_tissue_force(tissue, q - h * qd, qd, 0.0).p_cross_base) / (2 * h);
  EXPECT_LT((compute_tissue_force(tissue, q, qd, 0.0).f_inc_base - fd).norm(), 1e-8);
}

TEST(SimTissue, DampingSeesTheStretchRateOfAMovingIncision) {
  // The incision moves relative to the RCM (a patient, a software RCM shift):
  // the damping force is c d(p_cross - p_anchor)/dt with both moving.
  TissueParams params;
  params.stiffness_n_per_m = 0.0;
  params.damping_n_s_per_m = 1.0;
  const Eigen::Vector3d q0(0.05, 0.1, 0.12);
  const Eigen::Vector3d m0(0.004, -0.003, 0.035), m_rate(0.01, 0.02, -0.015);
  const Eigen::Vector3d q(0.3, -0.2, 0.11), qd(0.4, -0.7, 0.02);
  auto at = [&](double dt) {
    TissueModel tissue(params, q0, m0 + dt * m_rate);
    tissue.misalignment_rate_m_per_s = m_rate;
    return compute_tissue_force(tissue, q + dt * qd, qd, 0.0);
  };
  const double h = 1e-6;
  const Eigen::Vector3d fd = (at(h).stretch_base - at(-h).stretch_base) / (2 * h);
  EXPECT_LT((at(0.0).f_inc_base - fd).norm(), 1e-8);
  // The shaft slides through the tissue at qd3 less the crossing's own speed along it.
  const double s_dot = (at(h).shaft_distance - at(-h).shaft_distance) / (2 * h);
  EXPECT_NEAR(at(0.0).axial_velocity, qd[2] - s_dot, 1e-8);
}

TEST(SimTissue, AxialFrictionActsAlongTheShaft) {
  TissueParams params;
  params.stiffness_n_per_m = 0.0;
  params.axial_friction_n = 2.0;
  const Eigen::Vector3d q0(0.0, 0.0, 0.12);
  const TissueModel tissue(params, q0, Eigen::Vector3d(0.0, 0.0, 0.03));
  const Eigen::Vector3d q(0.2, 0.1, 0.12), qd(0.0, 0.0, 0.05);  // pure insertion
  double z = 0.0;
  for (int i = 0; i < 4000; ++i) {
    const TissueOutput o = compute_tissue_force(tissue, q, qd, z);
    z = advance_tissue_state(tissue, z, o.axial_velocity, 5e-4);
  }
  const TissueOutput o = compute_tissue_force(tissue, q, qd, z);
  const Eigen::Vector3d z3 = compute_shaft_frame(q).z3;
  EXPECT_NEAR(o.f_inc_base.dot(z3), 2.0, 1e-3);  // the shaft drags the tissue inward
  EXPECT_NEAR((o.f_inc_base - o.f_inc_base.dot(z3) * z3).norm(), 0.0, 1e-12);
  EXPECT_NEAR(o.tau[2], 2.0, 1e-3);
}
