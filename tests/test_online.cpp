// The online estimator on streams generated from the joint model itself (known
// truth, controlled noise): convergence, onset, alarm, rest handling, the
// derivative it linearizes with, and no allocation per sample.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <random>

#include "../src/estimation/joint_model.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/online.hpp"

using rcm::test::g_allocations;

namespace {

const Eigen::Vector3d kQ0(0.0, 0.0, 0.12);

rcm::JointTissueModel linear_tissue() {
  rcm::JointTissueModel t;
  t.parameters = Eigen::Vector4d(875.0, 0.0, 2.0, 0.3);
  return t;
}

// A pivoting teleoperation-like path about q0: yaw and pitch sweep +-0.5 rad at
// incommensurate rates, insertion +-2 cm.
struct PathSample {
  double t;
  Eigen::Vector3d q, qd;
};
PathSample path(double t) {
  const double w1 = 2 * M_PI / 7.0, w2 = 2 * M_PI / 5.3, w3 = 2 * M_PI / 9.1;
  PathSample s;
  s.t = t;
  s.q = kQ0 + Eigen::Vector3d(0.5 * std::sin(w1 * t), 0.45 * std::sin(w2 * t + 0.4), 0.02 * std::sin(w3 * t));
  s.qd = Eigen::Vector3d(0.5 * w1 * std::cos(w1 * t), 0.45 * w2 * std::cos(w2 * t + 0.4), 0.02 * w3 * std::cos(w3 * t));
  return s;
}

// The residual the model predicts for `truth`, plus white noise of sd `noise`.
Eigen::Vector3d make_dtau(const rcm::IncisionFrame& incision, const rcm::JointTissueModel& tissue, const PathSample& s,
                          const Eigen::Vector3d& truth, const Eigen::Vector3d& noise, std::mt19937& rng) {
  rcm::JointSample js;
  EXPECT_TRUE(rcm::compute_joint_sample(incision, s.q, s.qd, Eigen::Vector3d::Zero(), M_PI / 2, js));
  std::normal_distribution<double> n(0.0, 1.0);
  return rcm::compute_joint_model_torque(incision, tissue, js, truth) +
         Eigen::Vector3d(noise[0] * n(rng), noise[1] * n(rng), noise[2] * n(rng));
}

rcm::OnlineEstimatorOptions default_options() {
  rcm::OnlineEstimatorOptions o;
  o.torque_sigma = Eigen::Vector3d(0.02, 0.02, 0.1);
  return o;
}

}  // namespace

TEST(OnlineEstimator, ConvergesToTheTruthAndSettlesWithinTwentySeconds) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  const rcm::OnlineEstimator estimator(incision, tissue, default_options());
  for (const Eigen::Vector3d truth : {Eigen::Vector3d(0.010, 0.015, 0.030), Eigen::Vector3d(-0.008, 0.012, 0.005),
                                      Eigen::Vector3d(0.0, 0.0, 0.060), Eigen::Vector3d(0.005, -0.020, -0.010)}) {
    auto ws = estimator.create_workspace();
    std::mt19937 rng(3);
    const double dt = 1.0 / 200.0;
    Eigen::Vector3d at_20s = Eigen::Vector3d::Constant(NAN);
    for (int k = 0; k < 60 * 200; ++k) {
      const PathSample s = path(k * dt);
      estimator.compute_update(ws, s.t, s.q, s.qd, make_dtau(incision, tissue, s, truth, Eigen::Vector3d(0.02, 0.02, 0.1), rng));
      if (k == 20 * 200) at_20s = rcm::get_online_output(ws).misalignment_m;
    }
    const rcm::OnlineOutput& out = rcm::get_online_output(ws);
    EXPECT_LT((out.misalignment_m - truth).norm(), 0.0005) << truth.transpose() << " -> " << out.misalignment_m.transpose();
    EXPECT_LT((at_20s - out.misalignment_m).norm(), 0.005) << truth.transpose();
    // The reported standard deviation is that of an honest filter: errors within 4 sd.
    EXPECT_TRUE(((out.misalignment_m - truth).array().abs() < 4.0 * out.sd_m.array() + 1e-5).all())
        << (out.misalignment_m - truth).transpose() << " sd " << out.sd_m.transpose();
    EXPECT_TRUE(out.onset);
  }
}

TEST(OnlineEstimator, DetectsOnsetOnlyAfterTheIncisionMoves) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  const rcm::OnlineEstimator estimator(incision, tissue, default_options());
  auto ws = estimator.create_workspace();
  std::mt19937 rng(5);
  const double dt = 1.0 / 500.0, t_shift = 60.0;
  const Eigen::Vector3d truth(0.004, -0.003, 0.015);
  for (int k = 0; k < 90 * 500; ++k) {
    const PathSample s = path(k * dt);
    // Aligned (p = 0: sliding friction only) until t_shift, then misaligned.
    const Eigen::Vector3d p = s.t < t_shift ? Eigen::Vector3d::Zero() : truth;
    const auto& out =
        estimator.compute_update(ws, s.t, s.q, s.qd, make_dtau(incision, tissue, s, p, Eigen::Vector3d(0.02, 0.02, 0.1), rng));
    if (s.t < t_shift) ASSERT_FALSE(out.onset) << "false onset at " << s.t << " s, cusum " << out.cusum;
  }
  const rcm::OnlineOutput& out = rcm::get_online_output(ws);
  ASSERT_TRUE(out.onset);
  EXPECT_GT(out.onset_time, t_shift);
  EXPECT_LT(out.onset_time, t_shift + 3.0);
  EXPECT_LT((out.misalignment_m - truth).norm(), 0.001);
}

TEST(OnlineEstimator, AlarmRisesAboveTheThresholdAndClearsWithHysteresis) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  const rcm::OnlineEstimator estimator(incision, tissue, default_options());
  auto ws = estimator.create_workspace();
  std::mt19937 rng(7);
  const Eigen::Vector3d truth(0.0, 0.0, 0.045);
  int raised = 0, cleared = 0;
  double max_force_without_alarm = 0.0, min_force_with_alarm = 1e9;
  for (int k = 0; k < 60 * 200; ++k) {
    const PathSample s = path(k / 200.0);
    const auto& out =
        estimator.compute_update(ws, s.t, s.q, s.qd, make_dtau(incision, tissue, s, truth, Eigen::Vector3d(0.02, 0.02, 0.1), rng));
    raised += out.alarm_raised;
    cleared += out.alarm_cleared;
    if (s.t < 10.0) continue;  // converged
    // The alarm follows the true force, not the noise.
    rcm::JointSample js;
    ASSERT_TRUE(rcm::compute_joint_sample(incision, s.q, s.qd, Eigen::Vector3d::Zero(), M_PI / 2, js));
    const double f_true = rcm::compute_joint_model_force(incision, tissue, js, truth).norm();
    if (out.alarm_raised) EXPECT_GT(f_true, 9.5) << s.t;
    if (out.alarm_cleared) EXPECT_LT(f_true, 9.5) << s.t;
    if (out.alarm) min_force_with_alarm = std::min(min_force_with_alarm, out.force_norm_n);
    else max_force_without_alarm = std::max(max_force_without_alarm, out.force_norm_n);
  }
  // D = 45 mm at up to ~0.6 rad of pivot: the force crosses 10 N back and forth.
  EXPECT_GE(raised, 2);
  EXPECT_GE(cleared, 1);
  EXPECT_GE(min_force_with_alarm, 9.0 - 1e-9);
  EXPECT_LE(max_force_without_alarm, 10.0 + 1e-9);
}

TEST(OnlineEstimator, RestDoesNotFeedTheOnsetTest) {
  // At rest the free-space model misses the stiction band: a constant residual
  // that a radial offset would explain as well. It must not trigger an onset.
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  auto ws = estimator.create_workspace();
  const Eigen::Vector3d q = kQ0 + Eigen::Vector3d(0.1, -0.05, 0.0);
  for (int k = 0; k < 60 * 200; ++k)
    estimator.compute_update(ws, k / 200.0, q, Eigen::Vector3d::Zero(), Eigen::Vector3d(0.15, -0.1, 0.5));
  EXPECT_FALSE(rcm::get_online_output(ws).onset);
  EXPECT_TRUE(rcm::get_online_output(ws).at_rest);
  // The same residual while moving is evidence.
  rcm::OnlineEstimatorOptions o = default_options();
  o.rest_angular_speed = 0.0;
  o.rest_linear_speed = 0.0;
  const rcm::OnlineEstimator moving(incision, linear_tissue(), o);
  auto ws2 = moving.create_workspace();
  for (int k = 0; k < 60 * 200; ++k)
    moving.compute_update(ws2, k / 200.0, q, Eigen::Vector3d::Zero(), Eigen::Vector3d(0.15, -0.1, 0.5));
  EXPECT_TRUE(rcm::get_online_output(ws2).onset);
}

TEST(OnlineEstimator, JetDerivativeMatchesFiniteDifferences) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  using Jet = ceres::Jet<double, 3>;
  for (int trial = 0; trial < 200; ++trial) {
    const PathSample s = path(50.0 * (u(rng) + 1.0));
    rcm::JointSample js;
    ASSERT_TRUE(rcm::compute_joint_sample(incision, s.q, s.qd, Eigen::Vector3d::Zero(), M_PI / 2, js));
    const Eigen::Vector3d p(0.02 * u(rng), 0.02 * u(rng), 0.035 + 0.03 * u(rng));
    Jet pj[3], tj[3], tissue_j[4];
    for (int k = 0; k < 3; ++k) pj[k] = Jet(p[k], k);
    for (int k = 0; k < 4; ++k) tissue_j[k] = Jet(tissue.parameters[k]);
    rcm::detail::predict_joint_torque(js, incision.R_base_inc, tissue.axial_velocity_scale, pj, tissue_j, tj);
    // Central differences; step h = 1e-6 m gives an error ~ h^2 |f'''| plus
    // rounding eps |tau| / h, both far below the tolerance.
    const double h = 1e-6;
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d pp = p, pm = p;
      pp[k] += h;
      pm[k] -= h;
      const Eigen::Vector3d fd = (rcm::compute_joint_model_torque(incision, tissue, js, pp) -
                                  rcm::compute_joint_model_torque(incision, tissue, js, pm)) /
                                 (2 * h);
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(tj[j].v[k], fd[j], 1e-5 * (1.0 + std::abs(fd[j]))) << trial << " " << j << k;
    }
  }
}

TEST(OnlineEstimator, PerSampleUpdateDoesNotAllocate) {
  const long before_check = g_allocations;
  auto* probe = new std::vector<int>(10);
  delete probe;
  ASSERT_GT(g_allocations - before_check, 0);  // the counter works

  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  // A pipeline with a linear free-space model (its step is allocation free, as
  // every kind's, see test_dynamics_no_alloc).
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  rcm::dynamics::LinearTorqueParameters lp{Eigen::VectorXd::Ones(17),          Eigen::VectorXd::Ones(3),
                                           Eigen::VectorXd::Ones(3),           Eigen::VectorXd::Ones(3),
                                           Eigen::VectorXd::Ones(3),           Eigen::VectorXd::Constant(3, 1e-3)};
  const rcm::OnlinePipeline pipeline(std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, lp), estimator);
  auto ws = pipeline.create_workspace();
  auto ews = estimator.create_workspace();
  std::mt19937 rng(1);
  const long before = g_allocations;
  for (int k = 0; k < 2000; ++k) {
    const PathSample s = path(k / 200.0);
    const double effort[3] = {0.1, -0.2, 0.5};
    pipeline.compute_sample(ws, s.t, s.q.data(), s.qd.data(), effort);
    estimator.compute_update(ews, s.t, s.q, s.qd, Eigen::Vector3d(0.1, 0.05, 0.3));
  }
  EXPECT_EQ(g_allocations - before, 0);
}

namespace {
// tau_fs = a fixed function of the joint state, written `delay` calls late as by
// a fixed-lag network (TorqueModel::output_delay).
Eigen::Vector3d trailing_torque(const double* q, const double* qd) {
  return {0.3 * q[0] + 0.05 * qd[0], -0.2 * q[1], 2.0 * q[2] - 0.1 * qd[2]};
}

class TrailingModel final : public rcm::dynamics::TorqueModel {
 public:
  explicit TrailingModel(int delay) : TorqueModel(make_info()), delay_(delay) {}
  rcm::dynamics::TorqueModelKind kind() const override { return rcm::dynamics::TorqueModelKind::lstm; }
  int output_delay() const override { return delay_; }
  std::unique_ptr<rcm::dynamics::TorqueModelWorkspace> create_workspace() const override {
    auto ws = std::make_unique<Ws>();
    ws->ring.assign(static_cast<std::size_t>(delay_ + 1), Eigen::Vector3d::Zero());
    return ws;
  }
  void reset_state(rcm::dynamics::TorqueModelWorkspace& w) const override { static_cast<Ws&>(w).calls = 0; }
  void compute_step(rcm::dynamics::TorqueModelWorkspace& w, double, const double* q, const double* qd,
                    double* tau) const override {
    auto& ws = static_cast<Ws&>(w);
    const std::size_t n = ws.ring.size();
    ws.ring[ws.calls % n] = trailing_torque(q, qd);
    ++ws.calls;
    // The oldest entry: the sample of `delay` calls before.
    const Eigen::Vector3d& v = ws.ring[ws.calls % n];
    for (int j = 0; j < 3; ++j) tau[j] = v[j];
  }
  nlohmann::json save_parameters() const override { return nlohmann::json::object(); }

 private:
  struct Ws final : rcm::dynamics::TorqueModelWorkspace {
    std::vector<Eigen::Vector3d> ring;
    std::size_t calls = 0;
  };
  static rcm::dynamics::TorqueModelInfo make_info() {
    rcm::dynamics::TorqueModelInfo info;
    info.num_joints = info.num_outputs = 3;
    info.sample_period_s = 0.005;
    return info;
  }
  int delay_;
};
}  // namespace

TEST(OnlinePipeline, PairsADelayedModelWithTheSampleItsTorqueBelongsTo) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  const int d = 6;
  const rcm::OnlinePipeline now(std::make_shared<const TrailingModel>(0), estimator);
  const rcm::OnlinePipeline late(std::make_shared<const TrailingModel>(d), estimator);
  auto ws_now = now.create_workspace();
  auto ws_late = late.create_workspace();
  std::mt19937 rng(3);
  const Eigen::Vector3d truth(0.004, -0.003, 0.02), noise(0.02, 0.02, 0.1);
  std::vector<rcm::OnlineOutput> reference;
  const rcm::OnlineOutput fresh = rcm::get_online_output(estimator.create_workspace());
  for (int pass = 0; pass < 2; ++pass) {  // the second after a reset
    now.reset(ws_now);
    late.reset(ws_late);
    reference.clear();
    long allocations = 0;
    for (int k = 0; k < 4000; ++k) {
      const PathSample s = path(k / 200.0);
      const Eigen::Vector3d effort =
          make_dtau(incision, linear_tissue(), s, truth, noise, rng) + trailing_torque(s.q.data(), s.qd.data());
      reference.push_back(now.compute_sample(ws_now, s.t, s.q.data(), s.qd.data(), effort.data()));
      const long a0 = g_allocations;
      const rcm::OnlineOutput& o = late.compute_sample(ws_late, s.t, s.q.data(), s.qd.data(), effort.data());
      allocations += g_allocations - a0;
      if (k < d) {  // nothing yet: the reset output
        EXPECT_EQ(o.time, fresh.time);
        EXPECT_EQ(o.misalignment_m, fresh.misalignment_m);
        continue;
      }
      const rcm::OnlineOutput& r = reference[static_cast<std::size_t>(k - d)];
      ASSERT_EQ(o.time, r.time) << k;
      ASSERT_EQ(o.misalignment_m, r.misalignment_m) << k;
      ASSERT_EQ(o.f_inc_base, r.f_inc_base) << k;
      ASSERT_EQ(o.onset, r.onset) << k;
    }
    EXPECT_EQ(allocations, 0);
    // What was compared is an estimate, near the truth after 20 s.
    EXPECT_LT((reference.back().misalignment_m - truth).norm(), 0.006);
  }
}

// An RCM shift declared while the model's torque trails: the estimator takes it
// when it reaches the samples taken after it, and meanwhile the misalignment is
// reported relative to the RCM as it is now.
TEST(OnlinePipeline, ADelayedEstimateTakesAnRcmShiftWithItsSamples) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  const int d = 20, k_shift = 2000;
  const rcm::OnlinePipeline now(std::make_shared<const TrailingModel>(0), estimator);
  const rcm::OnlinePipeline late(std::make_shared<const TrailingModel>(d), estimator);
  auto ws_now = now.create_workspace();
  auto ws_late = late.create_workspace();
  std::mt19937 rng(3);
  const Eigen::Vector3d truth(0.004, -0.003, 0.02), noise(0.02, 0.02, 0.1);
  const Eigen::Vector3d shift_base(0.002, -0.001, 0.003);
  const Eigen::Vector3d shift_inc = incision.R_base_inc.transpose() * shift_base;
  std::vector<rcm::OnlineOutput> reference;
  for (int k = 0; k < 3000; ++k) {
    if (k == k_shift) {
      now.apply_rcm_shift(ws_now, shift_base);
      late.apply_rcm_shift(ws_late, shift_base);
    }
    const PathSample s = path(k / 200.0);
    const Eigen::Vector3d offset = k < k_shift ? truth : Eigen::Vector3d(truth - shift_inc);
    const Eigen::Vector3d effort =
        make_dtau(incision, linear_tissue(), s, offset, noise, rng) + trailing_torque(s.q.data(), s.qd.data());
    reference.push_back(now.compute_sample(ws_now, s.t, s.q.data(), s.qd.data(), effort.data()));
    const rcm::OnlineOutput& o = late.compute_sample(ws_late, s.t, s.q.data(), s.qd.data(), effort.data());
    if (k < d) continue;
    const rcm::OnlineOutput& r = reference[static_cast<std::size_t>(k - d)];
    ASSERT_EQ(o.time, r.time) << k;
    // Samples taken before the shift, reported relative to the shifted RCM.
    const bool pending = k >= k_shift && k - d < k_shift;
    ASSERT_LT((o.misalignment_m - (pending ? Eigen::Vector3d(r.misalignment_m - shift_inc) : r.misalignment_m)).norm(),
              1e-12)
        << k;
    ASSERT_EQ(o.sd_m, r.sd_m) << k;
  }
  EXPECT_LT((reference.back().misalignment_m - (truth - shift_inc)).norm(), 0.006);
}

// A linear model with its zero-phase qddot live (LinearTorqueParameters::
// live_zero_phase): its torque trails by 21 samples of 5 ms.
namespace {
std::shared_ptr<const rcm::dynamics::LinearTorqueModel> make_live_zero_phase_model() {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = info.num_outputs = 3;
  info.sample_period_s = 0.005;
  rcm::dynamics::LinearTorqueParameters p;
  p.gravity = Eigen::VectorXd::LinSpaced(rcm::dynamics::LinearTorqueModel::kGravityTerms, -0.2, 0.3);
  p.armature = Eigen::Vector3d(0.15, 0.2, 0.8);
  p.viscous = Eigen::Vector3d(0.05, 0.1, 1.0);
  p.coulomb = Eigen::Vector3d(0.1, 0.12, 0.4);
  p.offset = Eigen::Vector3d::Zero();
  p.dahl_displacement = Eigen::Vector3d(0.01, 0.01, 0.002);
  p.batch_acceleration_window_s = Eigen::Vector3d(0.1, 0.15, 0.2);
  p.live_zero_phase = true;
  return std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, p);
}

// One sample of the path at time t, its effort the free-space torque alone.
const rcm::OnlineOutput& compute_path_sample(const rcm::OnlinePipeline& pipeline, rcm::OnlinePipeline::Workspace& ws,
                                             double t) {
  const PathSample s = path(t);
  const Eigen::Vector3d effort = trailing_torque(s.q.data(), s.qd.data());
  return pipeline.compute_sample(ws, t, s.q.data(), s.qd.data(), effort.data());
}
}  // namespace

// The linear model with its zero-phase qddot live trails by its own delay; the
// pipeline pairs each output with the effort of the sample it is for, so the
// stream gives the estimate that the offline torque would, that delay late.
TEST(OnlinePipeline, PairsTheLinearModelsZeroPhaseTorqueWithItsSample) {
  const auto model = make_live_zero_phase_model();
  const int d = model->output_delay();
  ASSERT_EQ(d, 21);  // (0.1 + 0.005) / 0.005
  const int T = 4000;
  Eigen::VectorXd time(T);
  Eigen::MatrixXd q(T, 3), qd(T, 3);
  for (int k = 0; k < T; ++k) {
    const PathSample s = path(k / 200.0);
    time(k) = s.t;
    q.row(k) = s.q.transpose();
    qd.row(k) = s.qd.transpose();
  }
  const Eigen::MatrixXd offline = rcm::dynamics::predict_torque(*model, time, q, qd);

  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  const rcm::OnlinePipeline reference(std::make_shared<const TrailingModel>(0), estimator);
  const rcm::OnlinePipeline live(model, estimator);
  auto ws_ref = reference.create_workspace();
  auto ws_live = live.create_workspace();
  std::mt19937 rng(3);
  const Eigen::Vector3d truth(0.004, -0.003, 0.02), noise(0.02, 0.02, 0.1);
  std::vector<rcm::OnlineOutput> expected;
  long allocations = 0;
  for (int k = 0; k < T; ++k) {
    const PathSample s = path(time(k));
    const Eigen::Vector3d dtau = make_dtau(incision, linear_tissue(), s, truth, noise, rng);
    const Eigen::Vector3d effort_ref = dtau + trailing_torque(s.q.data(), s.qd.data());
    const Eigen::Vector3d effort_live = dtau + offline.row(k).transpose();
    expected.push_back(reference.compute_sample(ws_ref, s.t, s.q.data(), s.qd.data(), effort_ref.data()));
    const long a0 = g_allocations;
    const rcm::OnlineOutput& o = live.compute_sample(ws_live, s.t, s.q.data(), s.qd.data(), effort_live.data());
    allocations += g_allocations - a0;
    if (k < d) continue;
    const rcm::OnlineOutput& r = expected[static_cast<std::size_t>(k - d)];
    ASSERT_EQ(o.time, r.time) << k;
    ASSERT_LT((o.misalignment_m - r.misalignment_m).norm(), 1e-9) << k;
    ASSERT_LT((o.f_inc_base - r.f_inc_base).norm(), 1e-6) << k;
  }
  EXPECT_EQ(allocations, 0);
  EXPECT_LT((expected.back().misalignment_m - truth).norm(), 0.006);
}

// A gap in the stream longer than the delay: the first sample after it moves
// the delay's target past every sample left before the gap, which the model
// runs at once (TorqueModel::get_step_runs) and the pipeline estimates in
// order; then nothing until the stream has moved on that long. Each sample is
// estimated once (OnlineOutput::updates counts them), in order, and all but
// the delay's last ones are.
TEST(OnlinePipeline, AGapLongerThanTheDelayEstimatesNoSampleTwice) {
  const auto model = make_live_zero_phase_model();
  const double delay_s = model->get_output_delay_s();
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlinePipeline pipeline(model, rcm::OnlineEstimator(incision, linear_tissue(), default_options()));
  auto ws = pipeline.create_workspace();
  std::vector<double> times;
  for (int k = 0; k < 600; ++k) times.push_back(k / 200.0);
  for (int k = 0; k < 600; ++k) times.push_back(4.0 + k / 200.0);  // 1 s of silence, 10x the delay
  std::uint64_t updates = 0;
  double last = -1.0;
  for (const double t : times) {
    const rcm::OnlineOutput& o = compute_path_sample(pipeline, ws, t);
    if (o.updates == updates) continue;
    // Several at once only at the gap: the 21 samples of the delay before it,
    // the last of them 2.995 s.
    if (t == 4.0) {
      ASSERT_EQ(o.updates, updates + 21);
      ASSERT_EQ(o.time, 2.995);
    } else {
      ASSERT_EQ(o.updates, updates + 1) << t;
      ASSERT_NEAR(o.time, t - delay_s, 1e-9) << t;
    }
    ASSERT_GT(o.time, last) << t;
    last = o.time;
    updates = o.updates;
  }
  std::size_t expected = 0;
  for (const double t : times) expected += t <= times.back() - delay_s + 1e-9;
  EXPECT_EQ(updates, expected);
}

// A time that goes back ends the stream and starts another (as the model
// does): the first stream's last samples are estimated at once, and the new
// stream's from its own delay on, none left out.
TEST(OnlinePipeline, ATimeThatGoesBackStartsAnotherStream) {
  const auto model = make_live_zero_phase_model();
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlinePipeline pipeline(model, rcm::OnlineEstimator(incision, linear_tissue(), default_options()));
  auto ws = pipeline.create_workspace();
  std::uint64_t updates = 0;
  for (int k = 0; k < 600; ++k) updates = compute_path_sample(pipeline, ws, k / 200.0).updates;
  EXPECT_EQ(updates, 600u - 21u);  // all but the delay's 21 samples
  const rcm::OnlineOutput& first = compute_path_sample(pipeline, ws, 0.0);  // back to the start
  EXPECT_EQ(first.updates, 600u);
  EXPECT_EQ(first.time, 599 / 200.0);
  for (int k = 1; k < 600; ++k) {
    const rcm::OnlineOutput& o = compute_path_sample(pipeline, ws, k / 200.0);
    ASSERT_EQ(o.updates, 600u + static_cast<std::uint64_t>(std::max(0, k - 21 + 1))) << k;
    if (k >= 21) ASSERT_EQ(o.time, (k - 21) / 200.0) << k;
  }
}

// The same on streams as they come: rates from 100 Hz to 1.5 kHz, stamps
// jittered by 10 % of the period, gaps from a few periods to a second. Each
// call's estimate is for a sample of the stream at least the delay old (less
// the pick's 5 ms), in order; and every sample up to the last estimated one
// was estimated, once: where jitter or a gap moves the delay's target past
// several samples in one call, the model runs them all and the pipeline
// estimates each.
TEST(OnlinePipeline, EveryStreamEstimatesEachSampleOnceAndInOrder) {
  const auto model = make_live_zero_phase_model();
  const double delay_s = model->get_output_delay_s();
  const double reach = 0.5 * rcm::dynamics::kSlowestStreamPeriod;
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlinePipeline pipeline(model, rcm::OnlineEstimator(incision, linear_tissue(), default_options()));
  auto ws = pipeline.create_workspace();
  std::mt19937 rng(11);
  for (int stream = 0; stream < 20; ++stream) {
    pipeline.reset(ws);
    const double period = 1.0 / std::uniform_real_distribution<double>(100.0, 1500.0)(rng);
    std::uniform_real_distribution<double> jitter(-0.1 * period, 0.1 * period), unit(0.0, 1.0);
    std::vector<double> times;
    double t = 0.0;
    for (int k = 0; k < 1500; ++k) {
      times.push_back(t);
      t += period + jitter(rng);
      if (unit(rng) < 0.005) t += std::uniform_real_distribution<double>(3 * period, 1.0)(rng);  // a gap
    }
    std::uint64_t updates = 0;
    double last = -1.0;
    for (const double s_t : times) {
      const rcm::OnlineOutput& o = compute_path_sample(pipeline, ws, s_t);
      ASSERT_GE(o.updates, updates) << stream;
      if (o.updates == updates) continue;
      updates = o.updates;
      ASSERT_GE(s_t - o.time, delay_s - reach - 1e-9) << stream;
      ASSERT_TRUE(std::binary_search(times.begin(), times.end(), o.time)) << stream;
      ASSERT_GT(o.time, last) << stream;
      last = o.time;
    }
    const auto estimated = static_cast<std::uint64_t>(std::upper_bound(times.begin(), times.end(), last) - times.begin());
    EXPECT_EQ(updates, estimated) << stream;
    // Nothing left out at the end but the samples within the delay.
    const auto next = std::upper_bound(times.begin(), times.end(), last);
    if (next != times.end()) EXPECT_GT(*next, times.back() - delay_s - reach) << stream;
  }
}

TEST(OnlineEstimator, OptionsAreChecked) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  rcm::OnlineEstimatorOptions o;
  o.D_starts = {0.01, 0.02, 0.03, 0.04, 0.05};
  EXPECT_THROW(rcm::OnlineEstimator(incision, linear_tissue(), o), std::invalid_argument);
  o = {};
  o.correlation_time_s = 0.0;
  EXPECT_THROW(rcm::OnlineEstimator(incision, linear_tissue(), o), std::invalid_argument);
  o = {};
  o.D_starts = {0.1};
  EXPECT_THROW(rcm::OnlineEstimator(incision, linear_tissue(), o), std::invalid_argument);
}

// The same motion streamed at 200 Hz and at 1.5 kHz (the dVRK's fastest)
// through a pipeline whose free-space model was fitted at 200 Hz: 20 s of
// pivoting, then 10 s still while the encoders blip a count between the 200 Hz
// samples, as a still PSM's do under their controller. The friction holds the
// direction of the last motion; a model that stepped its friction state on
// every sample would take the blips for motion at 1.5 kHz. The estimator
// gathers the same information per second at either rate (its measurement
// variance is sigma^2 tau_c / dt): the estimate, its intervals and its fit
// cost agree.
TEST(OnlinePipeline, TheEstimateItsIntervalsAndFitCostDoNotDependOnTheStreamsRate) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  rcm::dynamics::LinearTorqueParameters lp;
  lp.gravity = Eigen::VectorXd::Zero(rcm::dynamics::LinearTorqueModel::kGravityTerms);
  lp.armature = Eigen::VectorXd::Zero(3);
  lp.viscous = Eigen::VectorXd::Zero(3);
  const Eigen::Vector3d coulomb(0.05, 0.05, 0.3);
  lp.coulomb = coulomb;
  lp.offset = Eigen::VectorXd::Zero(3);
  lp.dahl_displacement = Eigen::Vector3d(5e-5, 5e-5, 5e-6);
  const rcm::OnlinePipeline pipeline(std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, lp),
                                     rcm::OnlineEstimator(incision, linear_tissue(), default_options()));
  const Eigen::Vector3d truth(0.006, -0.004, 0.02), count(2e-5, 2e-5, 2e-6);
  auto stream = [&](double rate_hz, std::vector<rcm::OnlineOutput>& every_10ms) {
    auto ws = pipeline.create_workspace();
    std::mt19937 rng(11);
    Eigen::Vector3d direction = Eigen::Vector3d::Ones();  // of the last motion: the friction's memory
    const auto n = static_cast<long>(std::llround(30.0 * rate_hz));
    const long every = static_cast<long>(std::llround(rate_hz / 100.0));
    for (long k = 0; k <= n; ++k) {
      const double t = static_cast<double>(k) / rate_hz;
      PathSample s = path(std::min(t, 20.0));
      s.t = t;
      if (t > 20.0) s.qd.setZero();
      for (int j = 0; j < 3; ++j)
        if (s.qd[j] != 0.0) direction[j] = s.qd[j] > 0 ? 1.0 : -1.0;
      // The tissue's torque and a white effort noise, with the friction the model describes.
      Eigen::Vector3d effort = make_dtau(incision, linear_tissue(), s, truth, Eigen::Vector3d(0.01, 0.01, 0.05), rng) +
                               coulomb.cwiseProduct(direction);
      const double phase = std::fmod(t + 1e-9, 0.005);
      if (t > 20.0 && phase >= 0.0005 && phase < 0.0015) s.q += count;  // the encoders blip
      pipeline.compute_sample(ws, t, s.q.data(), s.qd.data(), effort.data());
      if (k % every == 0) every_10ms.push_back(rcm::get_online_output(ws.estimator));
    }
  };
  std::vector<rcm::OnlineOutput> slow, fast;
  stream(200.0, slow);
  stream(1500.0, fast);
  ASSERT_EQ(slow.size(), fast.size());
  for (std::size_t i = 500; i < slow.size(); i += 100) {  // from 5 s on, every second
    const rcm::OnlineOutput &a = slow[i], &b = fast[i];
    ASSERT_NEAR(a.time, b.time, 1e-9);
    EXPECT_LT((a.misalignment_m - b.misalignment_m).norm(), 0.5e-3) << a.time;
    EXPECT_LT((a.sd_m.array() / b.sd_m.array() - 1.0).abs().maxCoeff(), 0.15)
        << a.time << ": sd " << a.sd_m.transpose() << " vs " << b.sd_m.transpose();
    EXPECT_LT(std::abs(a.fit_cost - b.fit_cost), 0.25 * a.fit_cost + 0.2)
        << a.time << ": fit cost " << a.fit_cost << " vs " << b.fit_cost;
  }
  EXPECT_LT((fast.back().misalignment_m - truth).norm(), 1e-3);
}

TEST(OnlinePipeline, FlagsATorqueResidualNoIncisionForceExplains) {
  // A payload the free-space model never saw: the gravity moment of 200 g held
  // 0.1 m off the yaw and pitch axes, a torque no force at the incision
  // explains. The stream with it is flagged for most of its length; the same
  // stream without it, converging on a 10 mm radial offset, hardly at all.
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  const rcm::OnlinePipeline pipeline(std::make_shared<const TrailingModel>(0), estimator);
  const Eigen::Vector3d truth(0.010, 0.015, 0.030), noise(0.02, 0.02, 0.1);
  auto flagged_fraction = [&](bool payload) {
    auto ws = pipeline.create_workspace();
    std::mt19937 rng(5);
    int flagged = 0, samples = 0;
    for (int k = 0; k < 40 * 200; ++k) {
      const PathSample s = path(k / 200.0);
      Eigen::Vector3d effort =
          make_dtau(incision, linear_tissue(), s, truth, noise, rng) + trailing_torque(s.q.data(), s.qd.data());
      if (payload) effort += 0.2 * 9.81 * 0.1 * Eigen::Vector3d(std::cos(s.q[0]), std::cos(s.q[1]), 0.0);
      const rcm::OnlineOutput& o = pipeline.compute_sample(ws, s.t, s.q.data(), s.qd.data(), effort.data());
      if (s.t < 10.0) continue;  // after the estimate has had time to settle
      ++samples;
      flagged += (o.regime_flags & rcm::dynamics::get_residual_regime_flag()) != 0;
      EXPECT_EQ(o.out_of_regime, o.regime_flags != 0);
    }
    return static_cast<double>(flagged) / samples;
  };
  EXPECT_GT(flagged_fraction(true), 0.5);
  EXPECT_LT(flagged_fraction(false), 0.01);
  EXPECT_NE(rcm::dynamics::describe_regime_flags(rcm::dynamics::get_residual_regime_flag()).find("payload"),
            std::string::npos);
}

namespace {
// The estimator on linear_tissue() with the closed-loop bench's change-point test.
rcm::OnlineEstimator make_estimator_with_jumps(const rcm::IncisionFrame& incision) {
  rcm::OnlineEstimatorOptions options = default_options();
  options.jump_threshold = 4.0;
  return rcm::OnlineEstimator(incision, linear_tissue(), options);
}
}  // namespace

TEST(OnlineEstimator, AJumpOfTheIncisionRestartsTheFiltersAndTheyReconverge) {
  // A settled estimate, then the incision jumps 10 mm: the change-point test
  // fires within seconds and the bank, restarted from the prior, is back within
  // 1 mm soon after. The same stream without the jump (moving, then at rest)
  // never fires.
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  rcm::OnlineEstimatorOptions with_jumps = default_options();
  EXPECT_EQ(with_jumps.jump_threshold, 0.0) << "off by default";
  with_jumps.jump_threshold = 4.0;  // the closed-loop bench's
  const rcm::OnlineEstimator estimator(incision, tissue, with_jumps);
  const Eigen::Vector3d before(0.002, -0.001, 0.012), after = before + Eigen::Vector3d(0.006, 0.0, 0.008);
  const double t_jump = 30.0, rate = 200.0;
  for (const bool jump : {true, false}) {
    SCOPED_TRACE(jump ? "jump" : "no jump");
    auto ws = estimator.create_workspace();
    std::mt19937 rng(9);
    double back_within_1mm = NAN;
    for (int k = 0; k < 60 * rate; ++k) {
      PathSample s = path(k / rate);
      if (!jump && s.t > 45.0) {  // at rest for the last 15 s
        s = path(45.0);
        s.t = k / rate;
        s.qd.setZero();
      }
      const Eigen::Vector3d truth = jump && s.t >= t_jump ? after : before;
      const auto& out = estimator.compute_update(
          ws, s.t, s.q, s.qd, make_dtau(incision, tissue, s, truth, Eigen::Vector3d(0.02, 0.02, 0.1), rng));
      if (jump && s.t >= t_jump && out.jumps > 0 && std::isnan(back_within_1mm) &&
          (out.misalignment_m - truth).norm() < 0.001)
        back_within_1mm = s.t;
    }
    const rcm::OnlineOutput& out = rcm::get_online_output(ws);
    if (!jump) {
      EXPECT_EQ(out.jumps, 0) << "a restart at " << out.jump_time << " s";
      EXPECT_LT((out.misalignment_m - before).norm(), 0.001);
      continue;
    }
    ASSERT_EQ(out.jumps, 1);
    EXPECT_GT(out.jump_time, t_jump);
    EXPECT_LT(out.jump_time, t_jump + 3.0);
    EXPECT_LT(back_within_1mm, out.jump_time + 3.0) << "restart at " << out.jump_time << " s";
    EXPECT_LT((out.misalignment_m - after).norm(), 0.001);
  }
  // Off, the settled filter follows the jump by its random walk only.
  rcm::OnlineEstimatorOptions o = default_options();
  o.jump_threshold = 0.0;
  const rcm::OnlineEstimator without(incision, tissue, o);
  auto ws = without.create_workspace();
  std::mt19937 rng(9);
  for (int k = 0; k < 35 * rate; ++k) {
    const PathSample s = path(k / rate);
    without.compute_update(ws, s.t, s.q, s.qd,
                           make_dtau(incision, tissue, s, s.t >= t_jump ? after : before,
                                     Eigen::Vector3d(0.02, 0.02, 0.1), rng));
  }
  EXPECT_EQ(rcm::get_online_output(ws).jumps, 0);
}

TEST(OnlineEstimator, ARestartedFilterIsNotChargedForConverging) {
  // A stretch of torque the models miss (10 s, then gone: a path the
  // free-space model fits poorly) raises the fit cost and restarts the bank;
  // the incision then jumps 35 mm (the closed-loop bench's large step). Once
  // the bank restarts on the jump, its filters converge from centimetres away:
  // their innovations are large while they do, and they predict so. The fit
  // cost the corrector's mismatch gate reads is the restarted filter's own:
  // below the gate (10) within half a second of that restart, where a cost
  // carried over from before it held the gate to the end of the stream.
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  const rcm::OnlineEstimator estimator = make_estimator_with_jumps(incision);
  const Eigen::Vector3d before(0.002, -0.001, 0.012), after = before + Eigen::Vector3d(0.010, 0.015, 0.030);
  const double t_jump = 30.0, rate = 200.0;
  auto ws = estimator.create_workspace();
  std::mt19937 rng(9);
  double worst_before = 0.0, last_above_gate = 0.0, restart_after_jump = NAN;
  for (int k = 0; k < 50 * rate; ++k) {
    const PathSample s = path(k / rate);
    Eigen::Vector3d dtau =
        make_dtau(incision, tissue, s, s.t >= t_jump ? after : before, Eigen::Vector3d(0.02, 0.02, 0.1), rng);
    if (s.t >= t_jump - 10.0 && s.t < t_jump)
      dtau += 0.15 * std::sin(2.0 * M_PI * 0.7 * s.t) * Eigen::Vector3d(1.0, -1.0, 0.0);
    const auto& out = estimator.compute_update(ws, s.t, s.q, s.qd, dtau);
    if (s.t < t_jump) {
      worst_before = std::max(worst_before, out.fit_cost);
      continue;
    }
    if (std::isnan(restart_after_jump) && out.jump_time >= t_jump) restart_after_jump = out.jump_time;
    if (out.fit_cost > 10.0) last_above_gate = s.t;
  }
  EXPECT_GT(worst_before, 10.0) << "the missed torque must raise the fit cost for this test to mean anything";
  ASSERT_FALSE(std::isnan(restart_after_jump)) << "the jump restarts the bank";
  EXPECT_LT(last_above_gate, restart_after_jump + 0.5) << "restart on the jump at " << restart_after_jump << " s";
  EXPECT_LT((rcm::get_online_output(ws).misalignment_m - after).norm(), 0.001);
}

TEST(OnlineEstimator, ARestartOnATransientKeepsTheEstimateAndAJumpJustAfterIsCaught) {
  // A settled estimate, then a 0.3 s burst of torque the free-space model
  // misses (a friction transient): the change-point test restarts the bank.
  // During the burst a restarted filter explains the torques best, but the
  // filter reported before the restart stays in the bank and is reported again
  // within 0.6 s of the burst's end, within 1 mm of the truth. With a jump
  // 0.9 s after the burst, inside the restart's holdoff, the test fires again
  // within 3 s and the bank follows the jump.
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const auto tissue = linear_tissue();
  const rcm::OnlineEstimator estimator = make_estimator_with_jumps(incision);
  const Eigen::Vector3d before(0.002, -0.001, 0.012), after = before + Eigen::Vector3d(0.006, 0.0, 0.008);
  const double t_burst = 30.0, t_jump = 31.2, rate = 200.0;
  for (const bool jump : {false, true}) {
    SCOPED_TRACE(jump ? "burst, then a jump" : "burst only");
    auto ws = estimator.create_workspace();
    std::mt19937 rng(9);
    double last_off = NAN, back_within_1mm = NAN;
    int jumps_at_burst_end = 0;
    for (int k = 0; k < 45 * rate; ++k) {
      const PathSample s = path(k / rate);
      const Eigen::Vector3d truth = jump && s.t >= t_jump ? after : before;
      Eigen::Vector3d dtau = make_dtau(incision, tissue, s, truth, Eigen::Vector3d(0.02, 0.02, 0.1), rng);
      if (s.t >= t_burst && s.t < t_burst + 0.3) dtau += Eigen::Vector3d(0.6, -0.6, 2.0);
      const auto& out = estimator.compute_update(ws, s.t, s.q, s.qd, dtau);
      if (s.t < t_burst + 0.3) jumps_at_burst_end = out.jumps;
      if (s.t >= t_burst && (!jump || s.t < t_jump) && (out.misalignment_m - before).norm() >= 0.001) last_off = s.t;
      if (jump && s.t >= t_jump && out.jumps > jumps_at_burst_end && std::isnan(back_within_1mm) &&
          (out.misalignment_m - truth).norm() < 0.001)
        back_within_1mm = s.t;
    }
    const rcm::OnlineOutput& out = rcm::get_online_output(ws);
    EXPECT_GE(jumps_at_burst_end, 1) << "the burst restarts the bank";
    EXPECT_LT(last_off, t_burst + 0.3 + 0.6) << "last more than 1 mm off";
    if (!jump) {
      EXPECT_EQ(out.jumps, jumps_at_burst_end);
      EXPECT_LT((out.misalignment_m - before).norm(), 0.001);
      continue;
    }
    ASSERT_GT(out.jumps, jumps_at_burst_end);
    EXPECT_LT(out.jump_time, t_jump + 3.0);
    EXPECT_LT(back_within_1mm, t_jump + 6.0);
    EXPECT_LT((out.misalignment_m - after).norm(), 0.001);
  }
}

// A recording replayed in chunks (OnlineReplayer, what `rcm monitor` streams)
// gives the whole replay: the same outputs in the same order, the same
// summary, the settling time read back from the trace's temporary file.
TEST(OnlineReplay, ChunksGiveTheWholeReplay) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), default_options());
  const int T = 6000;
  rcm::Recording rec;
  rec.source = "path";
  rec.time.resize(T);
  rec.position.resize(T, 3);
  rec.velocity.resize(T, 3);
  rec.effort.resize(T, 3);
  std::mt19937 rng(8);
  for (int k = 0; k < T; ++k) {
    const PathSample s = path(k / 200.0);
    // The incision moves at 10 s: an onset, and a settling time well inside the run.
    const Eigen::Vector3d truth = k < 2000 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(0.004, -0.003, 0.02);
    rec.time(k) = s.t;
    rec.position.row(k) = s.q.transpose();
    rec.velocity.row(k) = s.qd.transpose();
    rec.effort.row(k) = (make_dtau(incision, linear_tissue(), s, truth, Eigen::Vector3d(0.02, 0.02, 0.1), rng) +
                         trailing_torque(s.q.data(), s.qd.data()))
                            .transpose();
  }
  for (int delay : {0, 6}) {
    const rcm::OnlinePipeline pipeline(std::make_shared<const TrailingModel>(delay), estimator);
    std::vector<rcm::OnlineOutput> whole_outputs, chunk_outputs;
    const rcm::OnlineReplay whole =
        rcm::replay_online(pipeline, rec, {}, [&](const rcm::OnlineOutput& o) { whole_outputs.push_back(o); });
    ASSERT_TRUE(whole.settled_after_s.has_value());
    ASSERT_TRUE(whole.onset_s.has_value());
    for (Eigen::Index rows : {1, 999}) {
      chunk_outputs.clear();
      rcm::OnlineReplayer replayer(pipeline, {}, [&](const rcm::OnlineOutput& o) { chunk_outputs.push_back(o); });
      for (Eigen::Index at = 0; at < T; at += rows)
        replayer.add(rcm::get_recording_rows(rec, at, std::min<Eigen::Index>(at + rows, T)));
      const rcm::OnlineReplay chunked = replayer.finish();
      ASSERT_EQ(chunk_outputs.size(), whole_outputs.size());
      for (std::size_t i = 0; i < whole_outputs.size(); ++i) {
        ASSERT_EQ(chunk_outputs[i].time, whole_outputs[i].time);
        ASSERT_EQ(chunk_outputs[i].misalignment_m, whole_outputs[i].misalignment_m);
      }
      EXPECT_EQ(chunked.samples, whole.samples);
      EXPECT_EQ(chunked.estimates, whole.estimates);
      EXPECT_EQ(chunked.final_output.misalignment_m, whole.final_output.misalignment_m);
      EXPECT_EQ(chunked.onset_s, whole.onset_s);
      EXPECT_EQ(chunked.motion_start_s, whole.motion_start_s);
      EXPECT_EQ(chunked.settled_after_s, whole.settled_after_s);
      EXPECT_EQ(chunked.alarms.size(), whole.alarms.size());
      EXPECT_EQ(chunked.peak_force_n, whole.peak_force_n);
      EXPECT_EQ(chunked.regime.samples, whole.regime.samples);
    }
  }
}
