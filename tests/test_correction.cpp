// The correction: from the running estimate to hold / compensate / reposition,
// its gates, its hysteresis, its rate and confidence limits, and its words.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <stdexcept>

#include "../src/estimation/joint_model.hpp"
#include "counting_new.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/kinematics/incision.hpp"

namespace {

using rcm::CorrectionAction;
using rcm::CorrectionOptions;
using rcm::HoldReason;
using rcm::OnlineOutput;
using rcm::RcmCorrector;

rcm::IncisionFrame make_frame() { return rcm::make_incision_frame(Eigen::Vector3d(0.2, -0.3, 0.12)); }

// The gates alone: an action starts at the first sample that calls for it
// (the confirmation time has a test of its own).
CorrectionOptions make_immediate_options() {
  CorrectionOptions o;
  o.confirm_s = 0.0;
  return o;
}

OnlineOutput make_estimate(double time, const Eigen::Vector3d& p, double sd, bool onset = true) {
  OnlineOutput e;
  e.time = time;
  e.used = true;
  e.onset = onset;
  e.misalignment_m = p;
  e.sd_m = Eigen::Vector3d::Constant(sd);
  e.covariance_m2 = Eigen::Matrix3d::Identity() * sd * sd;
  return e;
}

TEST(Correction, OptionsAreChecked) {
  const auto frame = make_frame();
  auto rejects = [&](auto edit) {
    CorrectionOptions o;
    edit(o);
    EXPECT_THROW(RcmCorrector(frame, o), std::invalid_argument);
  };
  rejects([](CorrectionOptions& o) { o.tolerance_m = 0; });
  rejects([](CorrectionOptions& o) { o.compensate_limit_m = 0.001; });
  rejects([](CorrectionOptions& o) { o.max_rate_m_per_s = -1; });
  rejects([](CorrectionOptions& o) { o.confidence_z = std::nan(""); });
  rejects([](CorrectionOptions& o) { o.release_fraction = 1.5; });
  rejects([](CorrectionOptions& o) { o.max_step_dt_s = 0; });
  rejects([](CorrectionOptions& o) { o.confirm_s = -0.1; });
  EXPECT_NO_THROW(RcmCorrector(frame, CorrectionOptions{}));
}

TEST(Correction, HoldsWithoutOnsetWhileUnsureAndWithinTolerance) {
  const RcmCorrector corrector(make_frame(), {});
  auto ws = corrector.create_workspace();
  const Eigen::Vector3d p(0.004, -0.003, 0.005);  // 7.1 mm
  auto c = corrector.compute_correction(ws, make_estimate(0.0, p, 0.0005, /*onset=*/false));
  EXPECT_EQ(c.action, CorrectionAction::hold);
  EXPECT_EQ(c.reason, HoldReason::no_onset);
  // An interval wider than the move: no advice.
  c = corrector.compute_correction(ws, make_estimate(0.01, p, 0.006));
  EXPECT_EQ(c.action, CorrectionAction::hold);
  EXPECT_EQ(c.reason, HoldReason::not_confident);
  EXPECT_EQ(c.distance_low_m, 0.0);
  // Sure, but small: 1 mm.
  c = corrector.compute_correction(ws, make_estimate(0.02, Eigen::Vector3d(0.0, 0.0, 0.001), 0.0002));
  EXPECT_EQ(c.action, CorrectionAction::hold);
  EXPECT_EQ(c.reason, HoldReason::within_tolerance);
  // A non-finite estimate holds too.
  c = corrector.compute_correction(ws, make_estimate(0.03, Eigen::Vector3d(NAN, 0, 0), 0.0002));
  EXPECT_EQ(c.action, CorrectionAction::hold);
  EXPECT_EQ(c.reason, HoldReason::no_onset);
  EXPECT_TRUE(c.step_base.isZero());
}

TEST(Correction, HoldsWhileTheModelDoesNotExplainTheTorques) {
  const RcmCorrector corrector(make_frame(), make_immediate_options());
  auto ws = corrector.create_workspace();
  OnlineOutput e = make_estimate(0.0, Eigen::Vector3d(0.004, 0.0, 0.008), 0.0003);
  e.fit_cost = 15.0;  // e.g. a payload the free-space model never saw
  const auto& c = corrector.compute_correction(ws, e);
  EXPECT_EQ(c.action, CorrectionAction::hold);
  EXPECT_EQ(c.reason, HoldReason::model_mismatch);
  EXPECT_TRUE(c.step_base.isZero());
  EXPECT_NE(rcm::describe_correction(c, corrector).find("does not explain the joint torques (fit cost 15.0"),
            std::string::npos);
  e.fit_cost = 2.0;
  EXPECT_EQ(corrector.compute_correction(ws, e).action, CorrectionAction::compensate);
}

TEST(Correction, CompensatesAtTheRateTowardTheIncisionAndNeverBeyondTheLowerBound) {
  const auto frame = make_frame();
  CorrectionOptions o = make_immediate_options();
  const RcmCorrector corrector(frame, o);
  auto ws = corrector.create_workspace();
  const Eigen::Vector3d p(0.003, 0.002, -0.004);
  const double sd = 0.0008;
  corrector.compute_correction(ws, make_estimate(0.0, p, sd));
  const auto& c = corrector.compute_correction(ws, make_estimate(0.01, p, sd));
  ASSERT_EQ(c.action, CorrectionAction::compensate);
  EXPECT_EQ(c.reason, HoldReason::none);
  EXPECT_TRUE(c.move_base.isApprox(frame.R_base_inc * p, 1e-12));
  EXPECT_NEAR(c.step_base.norm(), o.max_rate_m_per_s * 0.01, 1e-12);
  EXPECT_NEAR(c.step_base.normalized().dot(c.move_base.normalized()), 1.0, 1e-12);  // toward the incision
  EXPECT_TRUE(c.applied_base.isApprox(c.step_base, 1e-15));
  // After a gap, a step is at most max_step_dt_s at the rate.
  const auto& after_gap = corrector.compute_correction(ws, make_estimate(30.0, p, sd), Eigen::Vector3d::Zero());
  EXPECT_NEAR(after_gap.step_base.norm(), o.max_rate_m_per_s * o.max_step_dt_s, 1e-12);
  // Never more than the lower bound: 1.2 mm to go at sd 0.4 mm leaves 0.42 mm
  // the estimate is sure of, less than the 0.5 mm the rate allows after the gap
  // (the hysteresis lets an action go on below the tolerance).
  auto ws2 = corrector.create_workspace();
  corrector.compute_correction(ws2, make_estimate(0.0, Eigen::Vector3d(0.0, 0.0, 0.008), 0.0002));
  const auto& capped = corrector.compute_correction(ws2, make_estimate(10.0, Eigen::Vector3d(0.0012, 0, 0), 0.0004));
  ASSERT_EQ(capped.action, CorrectionAction::compensate);
  ASSERT_LT(capped.distance_low_m, o.max_rate_m_per_s * o.max_step_dt_s);
  EXPECT_NEAR(capped.step_base.norm(), capped.distance_low_m, 1e-15);
}

// A simulated loop: the estimate is the true remaining misalignment with
// noise of the stated sd; the corrector's shift moves the RCM.
struct LoopResult {
  double final_remaining_m = 0.0;
  double settle_time_s = -1.0;
  int overshoots = 0;  // samples where the remaining move pointed against the initial one
  CorrectionAction last = CorrectionAction::hold;
};

LoopResult run_loop(const RcmCorrector& corrector, const Eigen::Vector3d& p_true_inc, double sd, double seconds,
                    unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sd);
  auto ws = corrector.create_workspace();
  const Eigen::Matrix3d& R = corrector.incision().R_base_inc;
  Eigen::Vector3d applied_base = Eigen::Vector3d::Zero();
  LoopResult r;
  const double dt = 0.01;
  for (int k = 0; k * dt < seconds; ++k) {
    const Eigen::Vector3d remaining = p_true_inc - R.transpose() * applied_base;
    if (remaining.dot(p_true_inc) < 0) ++r.overshoots;
    const Eigen::Vector3d measured = remaining + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    const auto& c = corrector.compute_correction(ws, make_estimate(k * dt, measured, sd), applied_base);
    applied_base = c.applied_base;
    r.last = c.action;
    if (r.settle_time_s < 0 && c.action == CorrectionAction::hold && c.reason == HoldReason::within_tolerance)
      r.settle_time_s = k * dt;
  }
  r.final_remaining_m = (p_true_inc - R.transpose() * applied_base).norm();
  return r;
}

TEST(Correction, ClosesTheLoopOnANoisyEstimateWithoutOvershoot) {
  const RcmCorrector corrector(make_frame(), {});
  for (unsigned seed = 1; seed <= 5; ++seed) {
    const Eigen::Vector3d p(0.004, -0.003, 0.006);  // 7.8 mm
    const LoopResult r = run_loop(corrector, p, 0.0003, 10.0, seed);
    EXPECT_LT(r.final_remaining_m, corrector.options().tolerance_m) << "seed " << seed;
    EXPECT_EQ(r.overshoots, 0) << "seed " << seed;
    EXPECT_EQ(r.last, CorrectionAction::hold) << "seed " << seed;
    // At 5 mm/s the 7.8 mm take at least 1.2 s, and the loop should not dawdle.
    EXPECT_GT(r.settle_time_s, 1.0) << "seed " << seed;
    EXPECT_LT(r.settle_time_s, 3.0) << "seed " << seed;
  }
}

TEST(Correction, RepositionsBeyondTheLimitAndCountsTheShiftInEffect) {
  const auto frame = make_frame();
  const RcmCorrector corrector(frame, make_immediate_options());
  auto ws = corrector.create_workspace();
  const Eigen::Vector3d far(0.0, 0.0, 0.023);
  auto c = corrector.compute_correction(ws, make_estimate(0.0, far, 0.001));
  EXPECT_EQ(c.action, CorrectionAction::reposition);
  EXPECT_TRUE(c.changed);
  EXPECT_TRUE(c.step_base.isZero());
  const std::string words = rcm::describe_correction(c, corrector);
  EXPECT_NE(words.find("re-dock, move the RCM 23 mm deeper along the instrument"), std::string::npos) << words;
  // 3 mm to go with 9 mm already shifted in software: beyond what the limit leaves.
  auto ws2 = corrector.create_workspace();
  const Eigen::Vector3d applied = frame.R_base_inc.col(2) * 0.009;
  c = corrector.compute_correction(ws2, make_estimate(0.0, Eigen::Vector3d(0, 0, 0.003), 0.0002), applied);
  EXPECT_EQ(c.action, CorrectionAction::reposition);
  EXPECT_TRUE(c.applied_base.isApprox(applied));
  // With 7 mm shifted, 3 mm are left: 3.5 mm to go is a re-docking, and it
  // turns back into a software shift only once the upper bound fits.
  auto ws3 = corrector.create_workspace();
  const Eigen::Vector3d applied7 = frame.R_base_inc.col(2) * 0.007;
  c = corrector.compute_correction(ws3, make_estimate(0.0, Eigen::Vector3d(0, 0, 0.0035), 0.0002), applied7);
  EXPECT_EQ(c.action, CorrectionAction::reposition);
  c = corrector.compute_correction(ws3, make_estimate(0.01, Eigen::Vector3d(0, 0, 0.0028), 0.0002), applied7);
  EXPECT_EQ(c.action, CorrectionAction::reposition);  // 2.8 + 0.39 mm > 3 mm
  c = corrector.compute_correction(ws3, make_estimate(0.02, Eigen::Vector3d(0, 0, 0.0028), 0.00005), applied7);
  EXPECT_EQ(c.action, CorrectionAction::compensate);
  // The limit bounds the shift from the docked RCM: with 9 mm shifted, 6 mm
  // back is a software shift (3 mm from the docked RCM after it); across, the
  // shift reaches sqrt(10^2 - 9^2) = 4.4 mm: 5 mm (lower bound 4.6 mm) is a
  // re-docking, 4 mm (lower bound 3.6 mm) a shift.
  auto ws4 = corrector.create_workspace();
  c = corrector.compute_correction(ws4, make_estimate(0.0, Eigen::Vector3d(0, 0, -0.006), 0.0002), applied);
  EXPECT_EQ(c.action, CorrectionAction::compensate);
  c = corrector.compute_correction(ws4, make_estimate(0.1, Eigen::Vector3d(0, 0, -0.006), 0.0002), applied);
  EXPECT_LT(c.applied_base.norm(), applied.norm()) << "the shift back shortens the shift in effect";
  auto ws5 = corrector.create_workspace();
  c = corrector.compute_correction(ws5, make_estimate(0.0, Eigen::Vector3d(0.005, 0, 0), 0.0002), applied);
  EXPECT_EQ(c.action, CorrectionAction::reposition);
  auto ws6 = corrector.create_workspace();
  c = corrector.compute_correction(ws6, make_estimate(0.0, Eigen::Vector3d(0.004, 0, 0), 0.0002), applied);
  EXPECT_EQ(c.action, CorrectionAction::compensate) << "the lower bound, 3.6 mm across, fits in the 4.4 mm left";
}

TEST(Correction, HysteresisKeepsTheAdviceSteadyNearTheTolerance) {
  const RcmCorrector corrector(make_frame(), make_immediate_options());
  // An estimate that flickers across the 1.5 mm tolerance changes the advice at
  // most once: a wide interval (1.6 mm +- 2.0 mm, wider than the move) holds
  // throughout; a narrow one (+- 0.2 mm) acts from the first 1.6 mm on and
  // keeps acting, the estimate never falling under half the tolerance.
  for (const double sd : {0.001, 0.0001}) {
    auto ws = corrector.create_workspace();
    int changes = 0;
    for (int k = 0; k < 1000; ++k) {
      const double d = (k % 2 ? 0.0016 : 0.0014);
      const auto& c = corrector.compute_correction(ws, make_estimate(k * 0.01, Eigen::Vector3d(d, 0, 0), sd));
      if (k == 0) EXPECT_EQ(c.reason, HoldReason::not_confident);  // neither sure within nor beyond
      if (k == 1) EXPECT_EQ(c.action, sd > 0.0005 ? CorrectionAction::hold : CorrectionAction::compensate);
      changes += k > 0 && c.changed ? 1 : 0;
    }
    EXPECT_EQ(changes, sd > 0.0005 ? 0 : 1) << "sd " << sd;
  }
  // Out of tolerance, the lower bound under it, the interval narrower than the
  // move (2.0 mm, 1.0 to 3.0 mm): a shift, by no more than the lower bound.
  {
    CorrectionOptions fast = make_immediate_options();
    fast.max_rate_m_per_s = 1.0;  // the rate limit out of the way
    const RcmCorrector quick(make_frame(), fast);
    auto ws = quick.create_workspace();
    const double sd = 0.0005;
    const auto& c = quick.compute_correction(ws, make_estimate(0, Eigen::Vector3d(0.002, 0, 0), sd));
    EXPECT_EQ(c.action, CorrectionAction::compensate);
    const auto& next = quick.compute_correction(ws, make_estimate(0.1, Eigen::Vector3d(0.002, 0, 0), sd));
    EXPECT_NEAR(next.step_base.norm(), 0.002 - 1.96 * sd, 1e-12) << "the step is capped by the lower bound";
    // An interval wider than the move holds, its lower bound past the
    // tolerance or not (a restarted estimate: 43 mm, 3.8 to 82 mm).
    auto ws2 = corrector.create_workspace();
    const auto& wide = corrector.compute_correction(ws2, make_estimate(0, Eigen::Vector3d(0, 0, 0.043), 0.02));
    EXPECT_GT(wide.distance_low_m, corrector.options().tolerance_m);
    EXPECT_EQ(wide.action, CorrectionAction::hold);
    EXPECT_EQ(wide.reason, HoldReason::not_confident);
  }
  // A restart of the estimate ends the action: the restarted estimate (3 mm,
  // 1 to 5 mm: a lower bound past zero, an interval wider than the move) must
  // earn a new one.
  {
    auto ws = corrector.create_workspace();
    EXPECT_EQ(corrector.compute_correction(ws, make_estimate(0, Eigen::Vector3d(0.005, 0, 0), 0.0001)).action,
              CorrectionAction::compensate);
    OnlineOutput restarted = make_estimate(0.01, Eigen::Vector3d(0.003, 0, 0), 0.001);
    EXPECT_EQ(corrector.compute_correction(ws, restarted).action, CorrectionAction::compensate)
        << "without a restart, the action goes on while the lower bound is past zero";
    restarted.time = 0.02;
    restarted.jumps = 1;
    const auto& c = corrector.compute_correction(ws, restarted);
    EXPECT_EQ(c.action, CorrectionAction::hold);
    EXPECT_EQ(c.reason, HoldReason::not_confident);
    EXPECT_TRUE(c.step_base.isZero());
  }
  // Sure within (upper bound 1.3 mm); a wider interval (upper bound 2.7 mm,
  // under twice the tolerance) keeps it so, 3.8 mm does not.
  auto ws3 = corrector.create_workspace();
  EXPECT_EQ(corrector.compute_correction(ws3, make_estimate(0, Eigen::Vector3d(0.0011, 0, 0), 0.0001)).reason,
            HoldReason::within_tolerance);
  EXPECT_EQ(corrector.compute_correction(ws3, make_estimate(0.01, Eigen::Vector3d(0.0011, 0, 0), 0.0008)).reason,
            HoldReason::within_tolerance);
  EXPECT_EQ(corrector.compute_correction(ws3, make_estimate(0.02, Eigen::Vector3d(0.0011, 0, 0), 0.0014)).reason,
            HoldReason::not_confident);
  // Once acting, it keeps acting until the estimate falls under half the tolerance.
  auto ws2 = corrector.create_workspace();
  EXPECT_EQ(corrector.compute_correction(ws2, make_estimate(0, Eigen::Vector3d(0.005, 0, 0), 0.0001)).action,
            CorrectionAction::compensate);
  EXPECT_EQ(corrector.compute_correction(ws2, make_estimate(0.01, Eigen::Vector3d(0.0015, 0, 0), 0.0001)).action,
            CorrectionAction::compensate);
  const auto& done = corrector.compute_correction(ws2, make_estimate(0.02, Eigen::Vector3d(0.0006, 0, 0), 0.0001));
  EXPECT_EQ(done.action, CorrectionAction::hold);
  EXPECT_EQ(done.reason, HoldReason::within_tolerance);
}

// A compensation that stopped at its lower bound goes on once that bound
// clears zero again; a first action, or one after a restart or a settled hold,
// needs an interval narrower than the move.
TEST(Correction, AStoppedCompensationResumesOnItsLowerBound) {
  const RcmCorrector corrector(make_frame(), make_immediate_options());
  const Eigen::Vector3d rest(0.003, 0, 0);  // 3 mm remain
  const double sure_of_bound = 0.0012;      // 0.65 to 5.4 mm: lower bound past zero, interval wider than 3 mm
  ASSERT_GT(2.0 * 1.96 * sure_of_bound, rest.norm());
  ASSERT_GT(rest.norm() - 1.96 * sure_of_bound, 0.0);
  {
    auto fresh = corrector.create_workspace();
    EXPECT_EQ(corrector.compute_correction(fresh, make_estimate(0, rest, sure_of_bound)).reason,
              HoldReason::not_confident)
        << "a first action needs the interval narrower than the move";
  }
  auto stopped = [&](RcmCorrector::Workspace& ws) {
    EXPECT_EQ(corrector.compute_correction(ws, make_estimate(0, Eigen::Vector3d(0.010, 0, 0), 0.001)).action,
              CorrectionAction::compensate);
    const auto& c = corrector.compute_correction(ws, make_estimate(0.01, rest, 0.002));  // 0 to 6.9 mm
    EXPECT_EQ(c.reason, HoldReason::not_confident);
    EXPECT_TRUE(c.step_base.isZero());
  };
  auto ws = corrector.create_workspace();
  stopped(ws);
  const auto& resumed = corrector.compute_correction(ws, make_estimate(0.02, rest, sure_of_bound));
  EXPECT_EQ(resumed.action, CorrectionAction::compensate);
  EXPECT_GT(resumed.step_base.norm(), 0.0);
  EXPECT_LE(resumed.step_base.norm(), resumed.distance_low_m + 1e-15) << "never beyond the lower bound";

  // A restart, or a hold sure to be within tolerance, ends what could resume.
  auto ws2 = corrector.create_workspace();
  stopped(ws2);
  OnlineOutput restarted = make_estimate(0.02, rest, sure_of_bound);
  restarted.jumps = 1;
  for (; restarted.time < 0.02 + 3.0 * corrector.options().restart_confirm_s; restarted.time += 0.01)
    EXPECT_EQ(corrector.compute_correction(ws2, restarted).action, CorrectionAction::hold) << restarted.time;
  auto ws3 = corrector.create_workspace();
  stopped(ws3);
  EXPECT_EQ(corrector.compute_correction(ws3, make_estimate(0.02, Eigen::Vector3d(0.0005, 0, 0), 0.0001)).reason,
            HoldReason::within_tolerance);
  EXPECT_EQ(corrector.compute_correction(ws3, make_estimate(0.03, rest, sure_of_bound)).action,
            CorrectionAction::hold);
}

TEST(Correction, AnActionStartsOnceCalledForWithoutABreakForTheConfirmationTime) {
  const RcmCorrector corrector(make_frame(), {});
  const double confirm = corrector.options().confirm_s;
  ASSERT_GT(confirm, 0.0);
  const Eigen::Vector3d sure_move(0.004, 0, 0);  // 4 mm, +- 0.4 mm
  // The same stream at 200 Hz and at 1.5 kHz: the first shift comes at the
  // same time, not after the same number of samples.
  for (const double rate : {200.0, 1500.0}) {
    auto ws = corrector.create_workspace();
    double first_shift = -1.0;
    for (int k = 0; k <= static_cast<int>(2.0 * rate); ++k) {
      const double t = k / rate;
      const auto& c = corrector.compute_correction(ws, make_estimate(t, sure_move, 0.0002));
      if (c.action == CorrectionAction::hold) EXPECT_EQ(c.reason, HoldReason::not_confident) << t;
      if (first_shift < 0 && !c.step_base.isZero()) first_shift = t;
    }
    EXPECT_NEAR(first_shift, confirm, 1.5 / rate) << rate << " Hz";
  }
  // A sure estimate that breaks off before the confirmation time (a restarted
  // bank sure of a wrong move for a few tenths of a second) never moves the
  // RCM, and a break starts the count over.
  auto ws = corrector.create_workspace();
  const double dt = 1.0 / 1500.0;
  double t = 0.0;
  for (int spell = 0; spell < 5; ++spell) {
    for (; t < (spell + 0.8) * confirm; t += dt)
      EXPECT_TRUE(corrector.compute_correction(ws, make_estimate(t, sure_move, 0.0002)).step_base.isZero()) << t;
    for (; t < (spell + 1.0) * confirm; t += dt)  // unsure: the interval wider than the move
      EXPECT_TRUE(corrector.compute_correction(ws, make_estimate(t, sure_move, 0.003)).step_base.isZero()) << t;
  }
  // A restart starts it over too, and its first action waits the longer
  // restart_confirm_s (a restarted filter can follow a transient for a
  // second); the actions after it, confirm_s again.
  const double after_restart = corrector.options().restart_confirm_s;
  ASSERT_GT(after_restart, 2.0 * confirm);
  auto ws2 = corrector.create_workspace();
  OnlineOutput e = make_estimate(0.0, sure_move, 0.0002);
  for (; e.time < 0.8 * confirm; e.time += dt) corrector.compute_correction(ws2, e);
  const double restart = e.time;
  e.jumps = 1;
  for (; e.time < restart + after_restart - 2 * dt; e.time += dt)
    EXPECT_TRUE(corrector.compute_correction(ws2, e).step_base.isZero()) << e.time;
  for (; e.time < restart + after_restart + 2 * dt; e.time += dt) corrector.compute_correction(ws2, e);
  EXPECT_EQ(corrector.compute_correction(ws2, e).action, CorrectionAction::compensate);
  // Unsure for a while (back to hold), then sure again: confirm_s.
  auto after_jump = [](double t, double sd) {
    OnlineOutput o = make_estimate(t, Eigen::Vector3d(0.004, 0, 0), sd);
    o.jumps = 1;
    return o;
  };
  for (const double until = e.time + 0.1; e.time < until; e.time += dt)
    EXPECT_TRUE(corrector.compute_correction(ws2, after_jump(e.time, 0.003)).step_base.isZero());
  const double sure_again = e.time;
  for (; e.time < sure_again + confirm - 2 * dt; e.time += dt)
    EXPECT_TRUE(corrector.compute_correction(ws2, after_jump(e.time, 0.0002)).step_base.isZero());
  for (; e.time < sure_again + confirm + 2 * dt; e.time += dt)
    corrector.compute_correction(ws2, after_jump(e.time, 0.0002));
  EXPECT_EQ(corrector.compute_correction(ws2, after_jump(e.time, 0.0002)).action, CorrectionAction::compensate);
}

// The spread along the move is u^T C u: axes whose errors are correlated
// (as D and the radial offset are) can be sure of a diagonal move that their
// per-axis spreads alone leave in doubt, and the other way round.
TEST(Correction, ReadsTheSpreadAlongTheMoveFromTheFullCovariance) {
  const RcmCorrector corrector(make_frame(), make_immediate_options());
  const double sd = 0.001;
  // 2.8 mm along (1, 0, 1) / sqrt 2; per axis 1 mm, so 1 mm along the move
  // without the correlation: 95 % interval 0.9 to 4.8 mm, wider than the move.
  for (const double rho : {-0.9, 0.0, 0.9}) {
    OnlineOutput e = make_estimate(0.0, Eigen::Vector3d(0.002, 0.0, 0.002), sd);
    e.covariance_m2(0, 2) = e.covariance_m2(2, 0) = rho * sd * sd;
    auto ws = corrector.create_workspace();
    const auto& c = corrector.compute_correction(ws, e);
    const double sd_along = sd * std::sqrt(1.0 + rho);  // u^T C u = (1 + 1 + 2 rho) sd^2 / 2
    EXPECT_NEAR(c.distance_low_m, std::max(0.0, std::sqrt(8e-6) - 1.96 * sd_along), 1e-12) << "rho " << rho;
    EXPECT_NEAR(c.distance_high_m, std::sqrt(8e-6) + 1.96 * sd_along, 1e-12) << "rho " << rho;
    // Anti-correlated: 0.32 mm along the move, sure of it; otherwise not.
    EXPECT_EQ(c.action, rho < 0 ? CorrectionAction::compensate : CorrectionAction::hold) << "rho " << rho;
  }
}

TEST(Correction, DescribesTheMoveAlongTheArmsAxes) {
  // q0 = 0: the incision frame is frame 3 at rest, whose axes the test reads off.
  const auto frame = rcm::make_incision_frame(Eigen::Vector3d::Zero());
  const Eigen::Matrix3d& R = frame.R_base_inc;
  // 8 mm along +x_base across the shaft needs the lateral part of R^T e_x.
  Eigen::Vector3d lateral_inc = R.transpose() * Eigen::Vector3d(0.008, 0, 0);
  ASSERT_NEAR(lateral_inc[2], 0.0, 1e-12) << "x_base is across the shaft at q0 = 0";
  const Eigen::Vector3d move(lateral_inc[0], lateral_inc[1], -0.012);
  const std::string words = rcm::describe_rcm_move(move, frame);
  EXPECT_EQ(words, "12 mm shallower along the instrument, 8.0 mm toward +x_base");
  EXPECT_EQ(rcm::describe_rcm_move(Eigen::Vector3d(0.0004, 0, 0.0002), frame), "less than 1 mm");
}

TEST(Correction, AlignmentCheckAfterRedocking) {
  const auto frame = make_frame();
  const CorrectionOptions o;
  auto check = rcm::check_alignment(make_estimate(0, Eigen::Vector3d(0.0005, 0.0, 0.0008), 0.0002), frame, o);
  EXPECT_TRUE(check.aligned);
  EXPECT_NEAR(check.within_m, std::sqrt(0.0005 * 0.0005 + 0.0008 * 0.0008) + 1.96 * 0.0002, 1e-12);
  EXPECT_NE(check.message.find("aligned within 1.3 mm"), std::string::npos) << check.message;
  check = rcm::check_alignment(make_estimate(0, Eigen::Vector3d(0, 0, 0.006), 0.0005), frame, o);
  EXPECT_FALSE(check.aligned);
  EXPECT_TRUE(check.confident);
  EXPECT_NE(check.message.find("6.0 mm remain"), std::string::npos) << check.message;
  EXPECT_NE(check.message.find("deeper along the instrument"), std::string::npos) << check.message;
  check = rcm::check_alignment(make_estimate(0, Eigen::Vector3d(0, 0, 0.003), 0.004), frame, o);
  EXPECT_FALSE(check.aligned);
  EXPECT_FALSE(check.confident);
  EXPECT_NE(check.message.find("not yet sure"), std::string::npos) << check.message;
}

TEST(Correction, PerSampleCorrectionDoesNotAllocate) {
  const RcmCorrector corrector(make_frame(), {});
  auto ws = corrector.create_workspace();
  const OnlineOutput e = make_estimate(0.0, Eigen::Vector3d(0.004, 0.0, 0.005), 0.0003);
  Eigen::Vector3d applied = Eigen::Vector3d::Zero();
  const long before = rcm::test::get_allocation_count();
  for (int k = 0; k < 100; ++k) {
    OnlineOutput ek = e;
    ek.time = k * 0.01;
    applied = corrector.compute_correction(ws, ek, applied).applied_base;
  }
  EXPECT_EQ(rcm::test::get_allocation_count(), before);
  EXPECT_GT(applied.norm(), 0.0);
}

// The loop closed on the joint model itself: the tissue torque of the
// incision as it is relative to the RCM as it is (the docked misalignment minus
// the software shift), with free-space-model noise, through a pipeline whose
// free-space model predicts zero (so the effort is the residual), the online
// estimator and the corrector, each step carried out by the "arm".
Eigen::Vector3d pivot_path(double t, Eigen::Vector3d* qd) {
  const Eigen::Vector3d q0(0.0, 0.0, 0.12);
  const double w1 = 2 * M_PI / 7.0, w2 = 2 * M_PI / 5.3, w3 = 2 * M_PI / 9.1;
  *qd = Eigen::Vector3d(0.5 * w1 * std::cos(w1 * t), 0.45 * w2 * std::cos(w2 * t + 0.4), 0.02 * w3 * std::cos(w3 * t));
  return q0 + Eigen::Vector3d(0.5 * std::sin(w1 * t), 0.45 * std::sin(w2 * t + 0.4), 0.02 * std::sin(w3 * t));
}

std::shared_ptr<const rcm::dynamics::TorqueModel> make_zero_model() {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  const rcm::dynamics::LinearTorqueParameters lp{Eigen::VectorXd::Zero(17), Eigen::VectorXd::Zero(3),
                                                 Eigen::VectorXd::Zero(3),  Eigen::VectorXd::Zero(3),
                                                 Eigen::VectorXd::Zero(3),  Eigen::VectorXd::Constant(3, 1e-3)};
  return std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, lp);
}

TEST(CorrectionLoop, ClosesTheLoopOnTheJointModelWithoutAWrongMove) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(Eigen::Vector3d(0.0, 0.0, 0.12));
  rcm::JointTissueModel tissue;
  tissue.parameters = Eigen::Vector4d(875.0, 0.0, 2.0, 0.3);
  rcm::OnlineEstimatorOptions eo;
  eo.torque_sigma = Eigen::Vector3d(0.02, 0.02, 0.1);
  const rcm::CorrectionLoop loop(rcm::OnlinePipeline(make_zero_model(), rcm::OnlineEstimator(incision, tissue, eo)),
                                 RcmCorrector(incision, {}));
  const Eigen::Matrix3d& R = incision.R_base_inc;
  for (const Eigen::Vector3d docked : {Eigen::Vector3d(0.004, -0.003, 0.006), Eigen::Vector3d(-0.002, 0.001, -0.007)}) {
    auto ws = loop.create_workspace();
    std::mt19937 rng(11);
    std::normal_distribution<double> n(0.0, 1.0);
    Eigen::Vector3d applied = Eigen::Vector3d::Zero();
    int wrong_moves = 0, compensating = 0;
    const double dt = 1.0 / 200.0;
    for (int k = 0; k < 40 * 200; ++k) {
      Eigen::Vector3d qd;
      const Eigen::Vector3d q = pivot_path(k * dt, &qd);
      const Eigen::Vector3d remaining = docked - R.transpose() * applied;
      rcm::JointSample js;
      ASSERT_TRUE(rcm::compute_joint_sample(incision, q, qd, Eigen::Vector3d::Zero(), M_PI / 2, js));
      const Eigen::Vector3d effort = rcm::compute_joint_model_torque(incision, tissue, js, remaining) +
                                     Eigen::Vector3d(0.02 * n(rng), 0.02 * n(rng), 0.1 * n(rng));
      const auto& c = loop.compute_sample(ws, k * dt, q.data(), qd.data(), effort.data(), applied);
      if (c.step_base.norm() > 0 && c.step_base.dot(R * remaining) < 0) ++wrong_moves;
      if (c.action == CorrectionAction::compensate) ++compensating;
      applied = c.applied_base;  // the arm carries the step out
    }
    const Eigen::Vector3d remaining = docked - R.transpose() * applied;
    // Within the default tolerance, where the corrector holds: sure of it, or
    // with a 95 % upper bound still over it (the release threshold is half the
    // tolerance, under an interval of about +-0.7 mm here), never acting again.
    EXPECT_LT(remaining.norm(), loop.corrector().options().tolerance_m) << docked.transpose() << " -> " << remaining.transpose();
    EXPECT_EQ(wrong_moves, 0) << docked.transpose();
    EXPECT_GT(compensating, 0);
    EXPECT_EQ(ws.corrector.output.action, CorrectionAction::hold) << docked.transpose();
    EXPECT_TRUE(ws.corrector.output.reason == HoldReason::within_tolerance ||
                ws.corrector.output.reason == HoldReason::not_confident)
        << docked.transpose();
    // The estimate follows the RCM: what remains, not the docked offset.
    EXPECT_LT((rcm::get_online_output(ws.pipeline.estimator).misalignment_m - remaining).norm(), 0.001);
  }
}

TEST(CorrectionLoop, RejectsANonFiniteShift) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(Eigen::Vector3d(0.0, 0.0, 0.12));
  rcm::JointTissueModel tissue;
  tissue.parameters = Eigen::Vector4d(875.0, 0.0, 2.0, 0.3);
  const rcm::CorrectionLoop loop(rcm::OnlinePipeline(make_zero_model(), rcm::OnlineEstimator(incision, tissue, {})),
                                 RcmCorrector(incision, {}));
  auto ws = loop.create_workspace();
  const double q[3] = {0.1, 0.1, 0.12}, qd[3] = {0.1, 0.1, 0.0}, effort[3] = {0, 0, 0};
  EXPECT_THROW(loop.compute_sample(ws, 0.0, q, qd, effort, Eigen::Vector3d(NAN, 0, 0)), std::invalid_argument);
}

}  // namespace
