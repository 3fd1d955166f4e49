// The simulated PSM behind the robot's interfaces (include/rcm/sim/simulated_psm.hpp),
// without any middleware: its operating states, commands, refusals of bad
// commands, its tissue and incision, the software RCM, and that its step is
// the bench's own.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "counting_new.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/simulated_psm.hpp"

namespace {

using rcm::sim::PsmCommandVerdict;
using rcm::sim::PsmOperatingState;
using rcm::sim::PsmVector;
using rcm::sim::SimulatedPsm;
using rcm::sim::SimulatedPsmOptions;
using rcm::sim::SimulatedPsmState;

SimulatedPsmOptions make_options(double rate_hz = 1000.0) {
  SimulatedPsmOptions o;
  o.rate_hz = rate_hz;
  return o;
}

void run(const SimulatedPsm& psm, SimulatedPsmState& s, double seconds) {
  const auto n = static_cast<long>(std::llround(seconds / psm.period_s()));
  for (long k = 0; k < n; ++k) psm.compute_step(s);
}

// Enabled and homed, at the docking pose.
SimulatedPsmState make_ready(const SimulatedPsm& psm, std::uint64_t seed = 1) {
  SimulatedPsmState s = psm.create_state(seed);
  EXPECT_EQ(psm.apply_state_command(s, "home"), PsmCommandVerdict::accepted);
  for (int k = 0; k < 100000 && !s.homed; ++k) psm.compute_step(s);
  run(psm, s, 0.05);
  return s;
}

TEST(SimulatedPsm, StartsDisabledAndRefusesMotionUntilEnabledAndHomed) {
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options());
  SimulatedPsmState s = psm.create_state(1);
  psm.compute_step(s);
  EXPECT_EQ(s.sample.state, PsmOperatingState::disabled);
  EXPECT_FALSE(s.sample.homed);
  PsmVector goal = psm.home();
  goal[0] += 0.01;
  EXPECT_EQ(psm.apply_servo_jp(s, goal.data(), 6, nullptr, 0), PsmCommandVerdict::not_ready);
  EXPECT_EQ(psm.apply_move_jp(s, goal.data(), 6), PsmCommandVerdict::not_ready);
  EXPECT_EQ(psm.apply_state_command(s, "enable"), PsmCommandVerdict::accepted);
  run(psm, s, 0.01);
  EXPECT_EQ(s.sample.state, PsmOperatingState::enabled);
  EXPECT_EQ(psm.apply_servo_jp(s, goal.data(), 6, nullptr, 0), PsmCommandVerdict::not_ready) << "not homed";
  EXPECT_EQ(s.counters.not_ready, 3u);
  // Homing: busy while it moves, then homed and idle.
  EXPECT_EQ(psm.apply_state_command(s, "home"), PsmCommandVerdict::accepted);
  psm.compute_step(s);
  EXPECT_TRUE(s.sample.busy);
  run(psm, s, 2.0);
  EXPECT_TRUE(s.sample.homed);
  EXPECT_FALSE(s.sample.busy);
  EXPECT_EQ(psm.apply_servo_jp(s, goal.data(), 6, nullptr, 0), PsmCommandVerdict::accepted);
  EXPECT_EQ(psm.apply_state_command(s, "dance"), PsmCommandVerdict::unknown_command);
  EXPECT_EQ(psm.apply_state_command(s, "disable"), PsmCommandVerdict::accepted);
  run(psm, s, 0.01);
  EXPECT_EQ(s.sample.state, PsmOperatingState::disabled);
  EXPECT_EQ(psm.apply_servo_jp(s, goal.data(), 6, nullptr, 0), PsmCommandVerdict::not_ready);
}

// A bad command is rejected and counted, and the arm never moves on it: the
// same seed without the commands publishes bit for bit the same samples.
TEST(SimulatedPsm, RejectsBadCommandsAndNeverMovesOnThem) {
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options());
  SimulatedPsmState a = make_ready(psm), b = make_ready(psm);
  const PsmVector here = a.setpoint;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  PsmVector with_nan = here, beyond = here, jump = here;
  with_nan[1] = nan;
  beyond[2] = 0.30;  // the insertion stops at 0.24 m
  jump[0] += 0.3;    // within the limits, but 0.3 rad from the setpoint in one servo_jp
  for (int k = 0; k < 50; ++k) {
    EXPECT_EQ(psm.apply_servo_jp(a, here.data(), 5, nullptr, 0), PsmCommandVerdict::wrong_joint_count);
    EXPECT_EQ(psm.apply_servo_jp(a, here.data(), 6, here.data(), 3), PsmCommandVerdict::wrong_joint_count);
    EXPECT_EQ(psm.apply_servo_jp(a, with_nan.data(), 6, nullptr, 0), PsmCommandVerdict::not_finite);
    EXPECT_EQ(psm.apply_servo_jp(a, beyond.data(), 6, nullptr, 0), PsmCommandVerdict::beyond_limits);
    EXPECT_EQ(psm.apply_servo_jp(a, jump.data(), 6, nullptr, 0), PsmCommandVerdict::jump);
    EXPECT_EQ(psm.apply_move_jp(a, beyond.data(), 6), PsmCommandVerdict::beyond_limits);
    psm.compute_step(a);
    psm.compute_step(b);
    ASSERT_EQ(a.sample.position, b.sample.position) << "step " << k;
    ASSERT_EQ(a.sample.effort, b.sample.effort) << "step " << k;
    ASSERT_EQ(a.sample.setpoint, b.sample.setpoint) << "step " << k;
  }
  EXPECT_EQ(a.counters.wrong_joint_count, 100u);
  EXPECT_EQ(a.counters.not_finite, 50u);
  EXPECT_EQ(a.counters.beyond_limits, 100u);
  EXPECT_EQ(a.counters.jump, 50u);
  EXPECT_EQ(a.counters.get_rejected(), 300u);
  EXPECT_EQ(a.counters.servo_accepted, 0u);
}

TEST(SimulatedPsm, MoveJpReachesItsGoalBusyWhileMoving) {
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options(1500.0));
  EXPECT_EQ(psm.substeps(), 2);  // physics at 3 kHz, a whole number of steps per period
  SimulatedPsmState s = make_ready(psm);
  PsmVector goal = psm.home();
  goal << 0.3, -0.2, 0.10, 0.5, 0.2, -0.2;
  ASSERT_EQ(psm.apply_move_jp(s, goal.data(), 6), PsmCommandVerdict::accepted);
  psm.compute_step(s);
  EXPECT_TRUE(s.sample.busy);
  double moving_s = 0.0;
  while (s.sample.busy && moving_s < 10.0) {
    psm.compute_step(s);
    moving_s += psm.period_s();
  }
  EXPECT_FALSE(s.sample.busy);
  EXPECT_GT(moving_s, 0.3);
  run(psm, s, 0.5);
  for (int j = 0; j < 3; ++j) EXPECT_NEAR(s.sample.position[j], goal[j], j == 2 ? 5e-4 : 5e-3) << j;
  for (int j = 3; j < 6; ++j) EXPECT_DOUBLE_EQ(s.sample.position[j], goal[j]) << "the wrist reads its setpoint";
  // The move stayed within the speed it was given.
  EXPECT_LT(s.sample.velocity.head<3>().cwiseAbs().maxCoeff(), 0.05);
}

TEST(SimulatedPsm, ServoJpIsTrackedDirectly) {
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options(1000.0));
  SimulatedPsmState s = make_ready(psm);
  const PsmVector q0 = s.setpoint;
  double worst = 0.0;
  for (int k = 0; k < 3000; ++k) {  // 3 s of a 0.5 Hz, 0.1 rad sine on the yaw
    const double t = k * psm.period_s(), w = 2 * M_PI * 0.5;
    PsmVector q = q0, qd = PsmVector::Zero();
    q[0] += 0.1 * std::sin(w * t);
    qd[0] = 0.1 * w * std::cos(w * t);
    ASSERT_EQ(psm.apply_servo_jp(s, q.data(), 6, qd.data(), 6), PsmCommandVerdict::accepted);
    psm.compute_step(s);
    if (k > 200) worst = std::max(worst, std::abs(s.sample.position[0] - q[0]));
  }
  EXPECT_LT(worst, 0.01);
  EXPECT_EQ(s.counters.servo_accepted, 3000u);
}


// Over a network a servo_jp now and then comes a period or two late and a
// later period takes several. The setpoint then lags, as on the dVRK; its
// velocity stays the controller's reference, so the effort moves by the
// stiffness times the lag, not by the damping times the whole velocity.
TEST(SimulatedPsm, AServoJpPeriodsLateKeepsItsVelocityAndAStoppedStreamComesToRest) {
  const double rate_hz = 1500.0;
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options(rate_hz));
  const auto largest_effort_step = [&](int late_every, int late_periods) {
    SimulatedPsmState s = make_ready(psm);
    const PsmVector q0 = s.setpoint;
    const double w = 2 * M_PI * 0.5;
    const auto row = [&](int k, PsmVector& q, PsmVector& qd) {
      const double t = k * psm.period_s();
      q = q0;
      qd = PsmVector::Zero();
      q[0] += 0.3 * std::sin(w * t);  // up to 0.94 rad/s
      qd[0] = 0.3 * w * std::cos(w * t);
    };
    double largest = 0.0, last = 0.0;
    PsmVector q, qd;
    for (int k = 0; k < 3000; ++k) {
      // Rows k with k % late_every < late_periods come with the next on time.
      if (late_every == 0 || k % late_every >= late_periods) {
        for (int i = late_every > 0 && k % late_every == late_periods ? k - late_periods : k; i <= k; ++i) {
          row(i, q, qd);
          EXPECT_EQ(psm.apply_servo_jp(s, q.data(), 6, qd.data(), 6), PsmCommandVerdict::accepted);
        }
      }
      psm.compute_step(s);
      if (k > 300) largest = std::max(largest, std::abs(s.sample.effort[0] - last));
      last = s.sample.effort[0];
    }
    return largest;
  };
  const double smooth = largest_effort_step(0, 0);
  // A step of 0.94 rad/s at 1.5 kHz is 0.63 mrad: 0.25 N m at the yaw's 400
  // N m/rad. Losing the velocity would cost 6 N m s/rad times 0.94 rad/s.
  for (int late_periods : {1, 2, 3})
    EXPECT_LT(largest_effort_step(97, late_periods), smooth + 0.3 * late_periods + 0.3)
        << late_periods << " periods late; smooth stream: " << smooth;

  // A stream that stops: the setpoint's velocity is zero within servo_velocity_hold_s.
  SimulatedPsmState s = make_ready(psm);
  PsmVector q = s.setpoint, qd = PsmVector::Zero();
  qd[0] = 0.5;
  ASSERT_EQ(psm.apply_servo_jp(s, q.data(), 6, qd.data(), 6), PsmCommandVerdict::accepted);
  psm.compute_step(s);
  EXPECT_DOUBLE_EQ(s.sample.setpoint_velocity[0], 0.5);
  run(psm, s, SimulatedPsmOptions{}.servo_velocity_hold_s + 2 * psm.period_s());
  EXPECT_EQ(s.sample.setpoint_velocity[0], 0.0);
}
TEST(SimulatedPsm, TeleoperatesWhenIdleAndYieldsToACommand) {
  SimulatedPsmOptions o = make_options(500.0);
  o.teleop = true;
  o.teleop_idle_s = 0.5;
  const SimulatedPsm psm(rcm::sim::make_default_config(), o);
  SimulatedPsmState s = make_ready(psm);
  run(psm, s, 6.0);
  EXPECT_GT((s.sample.position.head<3>() - psm.home().head<3>()).norm(), 0.02) << "the surgeon's motion plays";
  const PsmVector here = s.setpoint;
  ASSERT_EQ(psm.apply_servo_jp(s, here.data(), 6, nullptr, 0), PsmCommandVerdict::accepted);
  run(psm, s, 0.3);
  EXPECT_LT((s.sample.setpoint - here).norm(), 1e-12) << "a command ends the teleoperation";
}

// The incision: placed at q0 without force, a pivot stretches it, the
// truth is the placement, and a motion moves it as the closed-loop bench's.
TEST(SimulatedPsm, TissueAndMovingIncision) {
  SimulatedPsmOptions o = make_options(500.0);
  o.teleop = true;
  const SimulatedPsm psm(rcm::sim::make_default_config(), o);
  SimulatedPsmState s = make_ready(psm);
  EXPECT_EQ(psm.apply_incision_command(s, "place 0 0 0.03"), PsmCommandVerdict::accepted);
  psm.compute_step(s);
  EXPECT_TRUE(s.sample.tissue_engaged);
  EXPECT_LT(s.sample.f_inc_base.norm(), 0.1) << "on the incision's axis at q0: no stretch";
  EXPECT_EQ(s.sample.misalignment_m, Eigen::Vector3d(0, 0, 0.03));
  double peak = 0.0;
  for (int k = 0; k < 5000; ++k) {  // 10 s of teleoperation
    psm.compute_step(s);
    peak = std::max(peak, s.sample.f_inc_base.norm());
  }
  EXPECT_GT(peak, 2.0) << "pivoting about an RCM 30 mm off the incision stretches it";
  EXPECT_EQ(psm.apply_incision_command(s, "motion step"), PsmCommandVerdict::accepted);
  run(psm, s, 19.9);
  EXPECT_NEAR((s.sample.misalignment_m - Eigen::Vector3d(0, 0, 0.03)).norm(), 0.0, 1e-12);
  run(psm, s, 0.2);
  EXPECT_NEAR((s.sample.misalignment_m - Eigen::Vector3d(0.006, 0, 0.038)).norm(), 0.0, 1e-12) << "the 10 mm step";
  EXPECT_EQ(psm.apply_incision_command(s, "motion tango"), PsmCommandVerdict::unknown_command);
  EXPECT_EQ(psm.apply_incision_command(s, "place 0 nan 0"), PsmCommandVerdict::not_finite);
  EXPECT_EQ(psm.apply_incision_command(s, "place 0 zero 0"), PsmCommandVerdict::unknown_command);
  EXPECT_EQ(psm.apply_incision_command(s, "place 0 0 0.5"), PsmCommandVerdict::refused);
  EXPECT_EQ(psm.apply_incision_command(s, "free_space"), PsmCommandVerdict::accepted);
  psm.compute_step(s);
  EXPECT_FALSE(s.sample.tissue_engaged);
  EXPECT_EQ(s.sample.f_inc_base, Eigen::Vector3d::Zero());
}

TEST(SimulatedPsm, SoftwareRcmFollowsTheShiftAtItsRate) {
  SimulatedPsmOptions o = make_options(1000.0);
  o.software_rcm = true;
  o.max_shift_rate_m_per_s = 0.02;
  const SimulatedPsm psm(rcm::sim::make_default_config(), o);
  SimulatedPsmState s = make_ready(psm);
  ASSERT_EQ(psm.apply_incision_command(s, "place 0 0 0.03"), PsmCommandVerdict::accepted);
  const Eigen::Vector3d shift(0.0, 0.0, 0.010);
  ASSERT_EQ(psm.apply_rcm_shift(s, shift), PsmCommandVerdict::accepted);
  run(psm, s, 0.25);
  EXPECT_NEAR(s.sample.shift_base.norm(), 0.005, 1e-4) << "0.25 s at 20 mm/s";
  run(psm, s, 0.5);
  EXPECT_NEAR((s.sample.shift_base - shift).norm(), 0.0, 1e-12);
  // The incision relative to the RCM as it now is, in the incision frame of q0.
  const Eigen::Matrix3d R = rcm::sim::TissueModel(s.tissue->params, psm.config().protocol.q0, Eigen::Vector3d::Zero())
                                .R_base_inc;
  EXPECT_NEAR((s.sample.misalignment_m - (Eigen::Vector3d(0, 0, 0.03) - R.transpose() * shift)).norm(), 0.0, 1e-12);
  EXPECT_EQ(psm.apply_rcm_shift(s, Eigen::Vector3d(0, 0, 0.2)), PsmCommandVerdict::refused) << "beyond max_shift_m";
  const SimulatedPsm fixed(rcm::sim::make_default_config(), make_options());
  SimulatedPsmState f = fixed.create_state(1);
  EXPECT_EQ(fixed.apply_rcm_shift(f, shift), PsmCommandVerdict::refused) << "no software RCM";
}

TEST(SimulatedPsm, FaultsWhenTheShaftLiesFlatOnThePadAndStandsStill) {
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options(500.0));
  SimulatedPsmState s = make_ready(psm);
  ASSERT_EQ(psm.apply_incision_command(s, "place 0 0 0.03"), PsmCommandVerdict::accepted);
  PsmVector flat = psm.home();
  flat[0] = 1.5;  // 86 degrees of yaw: the shaft nearly parallel to the pad
  ASSERT_EQ(psm.apply_move_jp(s, flat.data(), 6), PsmCommandVerdict::accepted);
  run(psm, s, 5.0);
  EXPECT_EQ(s.sample.state, PsmOperatingState::fault);
  EXPECT_EQ(s.counters.faults, 1u);
  EXPECT_FALSE(s.last_fault.empty());
  const PsmVector stopped = s.sample.position;
  run(psm, s, 0.5);
  EXPECT_LT((s.sample.position - stopped).head<3>().norm(), 1e-12);
  EXPECT_EQ(psm.apply_move_jp(s, psm.home().data(), 6), PsmCommandVerdict::not_ready);
  EXPECT_EQ(psm.apply_state_command(s, "home"), PsmCommandVerdict::refused);
}

// Published at the period, stamped on the arm's own clock; the step allocates
// nothing once running (teleoperation's start draws its path: not here).
TEST(SimulatedPsm, StepsOnItsClockWithoutAllocating) {
  const SimulatedPsm psm(rcm::sim::make_default_config(), make_options(1500.0));
  SimulatedPsmState s = make_ready(psm);
  ASSERT_EQ(psm.apply_incision_command(s, "place 0.01 0 0.03"), PsmCommandVerdict::accepted);
  PsmVector q = s.setpoint;
  const long before = rcm::test::get_allocation_count();
  double last = s.sample.time;
  for (int k = 0; k < 1500; ++k) {
    q[0] = psm.home()[0] + 0.05 * std::sin(k * 0.004);
    psm.apply_servo_jp(s, q.data(), 6, nullptr, 0);
    psm.compute_step(s);
    ASSERT_NEAR(s.sample.time - last, 1.0 / 1500, 1e-9);
    last = s.sample.time;
  }
  EXPECT_EQ(rcm::test::get_allocation_count(), before);
}

}  // namespace
