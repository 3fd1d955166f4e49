// Three-step estimation (Algorithm 1) on problems with known answers.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "rcm/common/error.hpp"
#include "rcm/estimation/three_step.hpp"
#include "rcm/force/incision_force.hpp"

namespace {

rcm::TissueLaw linear_law(double k, double x_max = 0.05) {
  rcm::TissueExpression e;
  e.terms.push_back({rcm::TissueTermKind::x, k, 1.0});
  return rcm::TissueLaw(e, 0.0, x_max);
}

rcm::TissueLaw cubic_law(double a, double b) {
  rcm::TissueExpression e;
  e.terms.push_back({rcm::TissueTermKind::x, a, 1.0});
  e.terms.push_back({rcm::TissueTermKind::cube, b, 1.0});
  return rcm::TissueLaw(e, 0.0, 0.06);
}

// The force the instrument applies to the tissue: the shaft's crossing of the
// pad plane against the anchored incision, through g (the simulator's model
// without dynamics).
Eigen::Vector3d tissue_force(const rcm::IncisionFrame& inc, const rcm::TissueLaw& g, const Eigen::Vector3d& q,
                             const Eigen::Vector3d& dp_inc) {
  const double s = rcm::compute_shaft_distance(inc, q, dp_inc[2]);
  const Eigen::Vector3d stretch = s * rcm::compute_z3_base(q) - inc.R_base_inc * dp_inc;
  const double n = stretch.norm();
  return n > 0 ? Eigen::Vector3d(g.evaluate(n) * stretch / n) : Eigen::Vector3d::Zero();
}

struct Synthetic {
  rcm::Recording trial, hold;
  Eigen::MatrixXd tau_fs_trial, tau_fs_hold;
};

Synthetic make_synthetic(const rcm::IncisionFrame& inc, const rcm::TissueLaw& g, const Eigen::Vector3d& dp,
                         double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Synthetic s;
  const int T = 2000;
  rcm::Recording& r = s.trial;
  r.source = "trial";
  r.time = Eigen::VectorXd::LinSpaced(T, 0.0, (T - 1) * 0.005);
  r.position.resize(T, 3);
  r.velocity = Eigen::MatrixXd::Zero(T, 3);
  r.effort.resize(T, 3);
  for (int t = 0; t < T; ++t) {
    const double tt = r.time[t];
    const Eigen::Vector3d q = inc.q0 + Eigen::Vector3d(0.55 * std::sin(0.7 * tt) * std::cos(0.13 * tt),
                                                       0.45 * std::sin(0.51 * tt + 1.0), 0.03 * std::sin(0.3 * tt));
    r.position.row(t) = q.transpose();
    const double sd = rcm::compute_shaft_distance(inc, q, dp[2]);
    const Eigen::Vector3d tau = rcm::compute_incision_jacobian(q, sd).transpose() * tissue_force(inc, g, q, dp);
    r.effort.row(t) = tau.transpose() + noise * Eigen::RowVector3d(n(rng), n(rng), 10 * n(rng));
  }
  s.tau_fs_trial = Eigen::MatrixXd::Zero(T, 3);
  // The hold: 0.5 s of return motion, then 2 s at q0.
  const int H = 500;
  rcm::Recording& h = s.hold;
  h.source = "hold";
  h.time = Eigen::VectorXd::LinSpaced(H, 0.0, (H - 1) * 0.005);
  h.position.resize(H, 3);
  h.velocity = Eigen::MatrixXd::Zero(H, 3);
  h.effort.resize(H, 3);
  for (int t = 0; t < H; ++t) {
    const double a = t < 100 ? 0.2 * (1.0 - t / 100.0) : 0.0;
    const Eigen::Vector3d q = inc.q0 + Eigen::Vector3d(a, -a, 0.0);
    if (t < 100) h.velocity(t, 0) = -0.2 / 0.5;
    h.position.row(t) = q.transpose();
    const double sd = rcm::compute_shaft_distance(inc, q, dp[2]);
    const Eigen::Vector3d tau = rcm::compute_incision_jacobian(q, sd).transpose() * tissue_force(inc, g, q, dp);
    h.effort.row(t) = tau.transpose() + noise * Eigen::RowVector3d(n(rng), n(rng), 10 * n(rng));
  }
  s.tau_fs_hold = Eigen::MatrixXd::Zero(H, 3);
  return s;
}

TEST(ThreeStep, InverseDecompositionEqualsJacobianInverse) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1, 1);
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0.1, -0.05, 0.12));
  for (int k = 0; k < 100; ++k) {
    const Eigen::Vector3d q(0.7 * u(rng), 0.6 * u(rng), 0.1);
    const Eigen::Vector3d dtau(u(rng), u(rng), 3 * u(rng));
    const double D = 0.04 + 0.03 * u(rng);
    const rcm::InverseDecomposition dec = rcm::compute_inverse_decomposition(inc, q, dtau);
    const Eigen::Vector3d f = rcm::compute_incision_force(inc, q, D, dtau).f_inc_base;
    EXPECT_LT((dec.evaluate(D) - f).norm(), 1e-10 * (1 + f.norm()));
  }
}

// A residual function of D (compute_coaxial_residuals or
// compute_total_force_residuals on one problem) against central differences.
using ResidualsOfD = std::function<bool(double D, double* residuals, double* jacobian)>;
void expect_jacobian_matches_finite_differences(const ResidualsOfD& residuals, std::size_t n,
                                                std::initializer_list<double> offsets) {
  std::vector<double> r(n), rp(n), rm(n), J(n);
  for (double D : offsets) {
    ASSERT_TRUE(residuals(D, r.data(), J.data()));
    // Central differences with h = 1e-7 m: truncation ~ h^2 psi''' ~ 1e-14 * 1e6,
    // rounding ~ eps |psi| / h ~ 1e-9 * |psi|.
    const double h = 1e-7;
    ASSERT_TRUE(residuals(D + h, rp.data(), nullptr));
    ASSERT_TRUE(residuals(D - h, rm.data(), nullptr));
    for (std::size_t t = 0; t < n; ++t) {
      const double fd = (rp[t] - rm[t]) / (2 * h);
      EXPECT_NEAR(J[t], fd, 1e-5 * (1.0 + std::abs(fd))) << "D = " << D << " t = " << t;
    }
  }
  EXPECT_FALSE(residuals(0.0, r.data(), nullptr));
}

rcm::CoaxialProblem make_test_problem(const rcm::IncisionFrame& inc, const rcm::TissueLaw& g) {
  const Synthetic s = make_synthetic(inc, g, Eigen::Vector3d(0.008, -0.012, 0.035), 0.02, 2);
  const rcm::StaticHold hold = rcm::compute_static_hold(s.hold, s.tau_fs_hold, inc.q0);
  return rcm::make_coaxial_problem(inc, s.trial, s.tau_fs_trial, hold.get_dtau());
}

TEST(ThreeStep, ResidualJacobianMatchesFiniteDifferences) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::TissueLaw g = cubic_law(600.0, 2.0e6);
  const rcm::CoaxialProblem p = make_test_problem(inc, g);
  expect_jacobian_matches_finite_differences(
      [&](double D, double* r, double* J) { return rcm::compute_coaxial_residuals(p, g, D, r, J); }, p.total.size(),
      {-0.015, 0.012, 0.03, 0.065});
}

TEST(ThreeStep, TotalForceResidualJacobianMatchesFiniteDifferences) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::TissueLaw g = cubic_law(600.0, 2.0e6);
  const rcm::CoaxialProblem p = make_test_problem(inc, g);
  // The radial offset's own derivative first: it enters every residual's.
  const double h = 1e-7;
  for (double D : {0.012, 0.03, 0.065}) {
    const rcm::RadialOffset radial = rcm::compute_radial_offset(p, g, D);
    ASSERT_EQ(radial.inverse, rcm::TissueInverseStatus::ok);
    const Eigen::Vector3d fd_radial =
        (rcm::compute_radial_offset(p, g, D + h).dp_r_base - rcm::compute_radial_offset(p, g, D - h).dp_r_base) /
        (2 * h);
    EXPECT_LT((radial.d_dp_r_dD - fd_radial).norm(), 1e-5 * (1.0 + fd_radial.norm())) << "D = " << D;
  }
  expect_jacobian_matches_finite_differences(
      [&](double D, double* r, double* J) { return rcm::compute_total_force_residuals(p, g, D, r, J); },
      p.total.size(), {0.012, 0.03, 0.065});
}

// The paper's step 3c adds the coaxial and radial stretches' forces as vectors:
// with stiffening tissue and a radial offset D~ comes out long. Fitting g of the
// whole stretch recovers every offset exactly.
TEST(ThreeStep, RecoversExactMisalignmentWithStiffeningTissueAndARadialOffset) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::TissueLaw g = cubic_law(508.33, 2.2917e5);  // 12 N at 20 mm, 35 N at 40 mm
  for (const Eigen::Vector3d dp : {Eigen::Vector3d(0.010, 0.015, 0.050), Eigen::Vector3d(-0.012, 0.008, 0.030),
                                   Eigen::Vector3d(0.010, 0.015, 0.015)}) {
    const Synthetic s = make_synthetic(inc, g, dp, 0.0, 6);
    const rcm::StaticHold hold = rcm::compute_static_hold(s.hold, s.tau_fs_hold, inc.q0);
    const rcm::ThreeStepResult total = rcm::estimate_three_step(inc, g, s.trial, s.tau_fs_trial, hold.get_dtau());
    EXPECT_TRUE(total.solver.converged) << total.solver.brief_report();
    EXPECT_LT((total.misalignment_m - dp).norm(), 1e-6) << total.misalignment_m.transpose() << " vs " << dp.transpose();
    rcm::ThreeStepOptions paper;
    paper.coaxial_force = rcm::CoaxialForce::difference;
    const rcm::ThreeStepResult difference =
        rcm::estimate_three_step(inc, g, s.trial, s.tau_fs_trial, hold.get_dtau(), paper);
    EXPECT_GT(difference.misalignment_m[2] - dp[2], 1e-3) << difference.misalignment_m.transpose();
  }
}

TEST(ThreeStep, RecoversExactMisalignmentWithLinearTissue) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::TissueLaw g = linear_law(788.0);
  for (const Eigen::Vector3d dp : {Eigen::Vector3d(0, 0, 0.030), Eigen::Vector3d(0.010, 0.015, 0.030),
                                   Eigen::Vector3d(0.010, 0.015, 0.010), Eigen::Vector3d(-0.004, 0.007, 0.050)}) {
    const Synthetic s = make_synthetic(inc, g, dp, 0.0, 3);
    const rcm::StaticHold hold = rcm::compute_static_hold(s.hold, s.tau_fs_hold, inc.q0);
    EXPECT_NEAR(hold.segment.duration_s, 399 * 0.005, 1e-9);
    const rcm::ThreeStepResult r = rcm::estimate_three_step(inc, g, s.trial, s.tau_fs_trial, hold.get_dtau());
    EXPECT_TRUE(r.solver.converged) << r.solver.brief_report() << " " << r.solver.message;
    EXPECT_LT((r.misalignment_m - dp).norm(), 1e-6) << r.misalignment_m.transpose() << " vs " << dp.transpose();
    EXPECT_LT(r.solver.final_cost, 1e-12);
  }
}

TEST(ThreeStep, ToleratesTorqueNoise) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::TissueLaw g = linear_law(788.0);
  const Eigen::Vector3d dp(0.010, 0.015, 0.040);
  const Synthetic s = make_synthetic(inc, g, dp, 0.018, 4);  // the dVRK's effort noise
  const rcm::StaticHold hold = rcm::compute_static_hold(s.hold, s.tau_fs_hold, inc.q0);
  const rcm::ThreeStepResult r = rcm::estimate_three_step(inc, g, s.trial, s.tau_fs_trial, hold.get_dtau());
  EXPECT_LT((r.misalignment_m - dp).norm(), 1e-3) << r.misalignment_m.transpose();
}

TEST(ThreeStep, RespectsBoundsAndChecksOptions) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::TissueLaw g = linear_law(788.0);
  const Synthetic s = make_synthetic(inc, g, Eigen::Vector3d(0, 0, 0.060), 0.0, 5);
  rcm::ThreeStepOptions o;
  o.D_max = 0.045;
  const rcm::ThreeStepResult r = rcm::estimate_three_step(inc, g, s.trial, s.tau_fs_trial, Eigen::Vector3d::Zero(), o);
  EXPECT_LE(r.misalignment_m[2], 0.045 + 1e-12);
  EXPECT_NEAR(r.misalignment_m[2], 0.045, 1e-6);
  o.D_initial = 0.5;
  EXPECT_THROW(rcm::estimate_three_step(inc, g, s.trial, s.tau_fs_trial, Eigen::Vector3d::Zero(), o),
               std::invalid_argument);
}

TEST(ThreeStep, NoHoldAtQ0IsALocatedError) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const Synthetic s = make_synthetic(inc, linear_law(788.0), Eigen::Vector3d(0, 0, 0.03), 0.0, 6);
  try {
    rcm::compute_static_hold(s.trial, s.tau_fs_trial, inc.q0);  // the trial never rests
    FAIL();
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("trial: no hold at q0"), std::string::npos) << e.what();
  }
}

// A joint that stops on the edge of an encoder count: the quantized position
// toggles between two counts. The play operator one and a half counts wide
// removes every toggle, keeps real motion (lag at most half the width) and
// leaves an unquantized recording within half its smallest step.
TEST(ThreeStep, PositionChatterIsRemovedAndMotionKept) {
  const double count = 2e-5;
  rcm::Recording r;
  const int T = 400;
  r.time = Eigen::VectorXd::LinSpaced(T, 0.0, (T - 1) * 0.005);
  r.position = Eigen::MatrixXd::Zero(T, 3);
  r.velocity = Eigen::MatrixXd::Zero(T, 3);
  r.effort = Eigen::MatrixXd::Zero(T, 3);
  std::mt19937 rng(3);
  std::bernoulli_distribution toggle(0.4);
  for (int t = 0; t < T; ++t) {
    // joint 1: ramps down 40 counts, then sits on the edge between counts 10 and 11
    const double q1 = (t < 100 ? std::round(50.0 - 0.4 * t) : (toggle(rng) ? 11.0 : 10.0)) * count;
    r.position(t, 0) = q1;
    r.position(t, 1) = std::round(1e-3 * std::sin(0.05 * t) / count) * count;  // moving, quantized
    r.position(t, 2) = 1e-4 * std::sin(0.03 * t);                              // not quantized
  }
  const Eigen::VectorXd quantum = rcm::estimate_position_quantum(r);
  EXPECT_NEAR(quantum[0], count, 1e-12);
  EXPECT_NEAR(quantum[1], count, 1e-12);
  EXPECT_LT(quantum[2], 1e-6);
  const rcm::Recording f = rcm::remove_position_chatter(r, 1.5 * quantum);
  // No reversal left at rest: the filtered joint 1 is constant over the hold.
  EXPECT_EQ(f.position.col(0).segment(110, T - 110).maxCoeff(), f.position.col(0).segment(110, T - 110).minCoeff());
  for (int j = 0; j < 3; ++j)
    EXPECT_LE((f.position.col(j) - r.position.col(j)).cwiseAbs().maxCoeff(), 0.75 * quantum[j] + 1e-15) << j;
  EXPECT_EQ(f.velocity, r.velocity);
  EXPECT_EQ(f.effort, r.effort);
  EXPECT_THROW(rcm::remove_position_chatter(r, Eigen::Vector3d(-1.0, 0.0, 0.0)), std::invalid_argument);
}

// Hysteretic friction at the hold: a joint at rest keeps +F after a motion up
// and -F after a motion down. A static file with one approach from each side:
// the paper's last hold reads the friction as force; the balanced step cancels
// it, and says per joint whether both directions were seen.
TEST(ThreeStep, BalancedStaticStepCancelsHystereticFriction) {
  const Eigen::Vector3d q0(0.0, 0.0, 0.12), band(0.12, 0.24, 0.6), true_dtau(0.3, -0.2, 1.5);
  const int H = 1400;
  rcm::Recording r;
  r.source = "static";
  r.time = Eigen::VectorXd::LinSpaced(H, 0.0, (H - 1) * 0.005);
  r.position.resize(H, 3);
  r.velocity = Eigen::MatrixXd::Zero(H, 3);
  r.effort.resize(H, 3);
  // 0.5 s from q0 + a down to q0, 2 s hold, 0.5 s out to q0 - a, 0.5 s back up, 3.5 s hold.
  // Joint 3 arrives from above both times: its holds stay one-sided.
  const Eigen::Vector3d a(0.05, -0.05, 0.005);
  Eigen::Vector3d friction = Eigen::Vector3d::Zero();
  for (int t = 0; t < H; ++t) {
    Eigen::Vector3d q = q0;
    if (t < 100) q = q0 + a * (1.0 - t / 100.0);
    else if (t >= 500 && t < 600) q = q0 - a * ((t - 500) / 100.0);
    else if (t >= 600 && t < 700) q = q0 - a * (1.0 - (t - 600) / 100.0);
    if (t >= 500 && t < 700) q[2] = q0[2] + a[2] * (t < 600 ? (t - 500) / 100.0 : 1.0 - (t - 600) / 100.0);
    if (t > 0) {
      const Eigen::Vector3d dq = q - r.position.row(t - 1).transpose();
      for (int j = 0; j < 3; ++j)
        if (dq[j] != 0.0) friction[j] = dq[j] > 0 ? band[j] : -band[j];
      r.velocity.row(t) = (dq / 0.005).transpose();
    }
    r.position.row(t) = q.transpose();
    r.effort.row(t) = (true_dtau + friction).transpose();
  }
  const Eigen::MatrixXd tau_fs = Eigen::MatrixXd::Zero(H, 3);  // a model that knows nothing of friction

  const rcm::StaticHold last = rcm::compute_static_hold(r, tau_fs, q0, {}, rcm::StaticStep::last_hold);
  ASSERT_EQ(last.holds.size(), 2u);
  EXPECT_EQ(last.holds[0].direction, Eigen::Vector3i(-1, 1, -1));
  EXPECT_EQ(last.holds[1].direction, Eigen::Vector3i(1, -1, -1));
  EXPECT_TRUE(last.get_dtau().isApprox(true_dtau + Eigen::Vector3d(band[0], -band[1], -band[2]), 1e-12));

  const rcm::StaticHold balanced = rcm::compute_static_hold(r, tau_fs, q0);
  EXPECT_EQ(balanced.step, rcm::StaticStep::balanced);
  EXPECT_NEAR(balanced.get_dtau()[0], true_dtau[0], 1e-12);
  EXPECT_NEAR(balanced.get_dtau()[1], true_dtau[1], 1e-12);
  EXPECT_NEAR(balanced.get_dtau()[2], true_dtau[2] - band[2], 1e-12);  // one-sided: the mean of its holds
  EXPECT_TRUE(balanced.direction_balanced[0]);
  EXPECT_TRUE(balanced.direction_balanced[1]);
  EXPECT_FALSE(balanced.direction_balanced[2]);
  // Unequal hold lengths: each side counts once, whatever its duration.
  EXPECT_GT(balanced.holds[1].segment.duration_s, 1.5 * balanced.holds[0].segment.duration_s);

  EXPECT_EQ(rcm::parse_static_step("last-hold"), rcm::StaticStep::last_hold);
  EXPECT_EQ(rcm::to_string(rcm::parse_static_step("balanced")), "balanced");
  EXPECT_THROW(rcm::parse_static_step("both"), std::invalid_argument);
}

}  // namespace
