// The training regime of a free-space model and the per-sample check that the
// arm is still inside it (dynamics/regime.hpp), through the model file, the
// online pipeline and a study's trial.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <cmath>
#include <filesystem>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/regime.hpp"
#include "rcm/estimation/online.hpp"

namespace {

using rcm::dynamics::RegimeMonitor;
using rcm::dynamics::RegimeQuantity;
using rcm::dynamics::TrainingRegime;
using rcm::dynamics::regime_bit;

const Eigen::Vector3d kQ0(0.0, 0.0, 0.12);
const Eigen::Vector3d kAmplitude(0.5, 0.4, 0.03);
const Eigen::Vector3d kOmega(1.3, 1.7, 2.1);  // rad/s of the path at speed 1

// q = q0 + a sin(speed w t) + shift, with its exact velocity, at `rate_hz` for `duration_s`.
rcm::Recording make_path(double speed, double rate_hz, double duration_s, const Eigen::Vector3d& shift = Eigen::Vector3d::Zero()) {
  const auto T = static_cast<Eigen::Index>(std::round(duration_s * rate_hz)) + 1;
  rcm::Recording r;
  r.source = "path";
  r.time.resize(T);
  r.position.resize(T, 3);
  r.velocity.resize(T, 3);
  r.effort = Eigen::MatrixXd::Zero(T, 3);
  for (Eigen::Index t = 0; t < T; ++t) {
    const double s = static_cast<double>(t) / rate_hz;
    r.time(t) = s;
    for (int j = 0; j < 3; ++j) {
      const double w = speed * kOmega[j];
      r.position(t, j) = kQ0[j] + shift[j] + kAmplitude[j] * std::sin(w * s);
      r.velocity(t, j) = kAmplitude[j] * w * std::cos(w * s);
    }
  }
  return r;
}

TEST(TrainingRegime, SpansEverySampleOfTheFitData) {
  const rcm::Recording a = make_path(1.0, 200.0, 20.0), b = make_path(1.0, 200.0, 5.0, Eigen::Vector3d(0.1, 0, 0));
  const TrainingRegime r = rcm::dynamics::compute_training_regime({a, b}, 3);
  ASSERT_EQ(r.num_joints(), 3);
  EXPECT_EQ(r.samples, a.num_samples() + b.num_samples());
  for (int j = 0; j < 3; ++j) {
    const double lo = std::min(a.position.col(j).minCoeff(), b.position.col(j).minCoeff());
    const double hi = std::max(a.position.col(j).maxCoeff(), b.position.col(j).maxCoeff());
    EXPECT_EQ(r.position_min[j], lo);
    EXPECT_EQ(r.position_max[j], hi);
    EXPECT_EQ(r.velocity_max[j], std::max(a.velocity.col(j).maxCoeff(), b.velocity.col(j).maxCoeff()));
    EXPECT_EQ(r.velocity_min[j], std::min(a.velocity.col(j).minCoeff(), b.velocity.col(j).minCoeff()));
  }
}

TEST(TrainingRegime, AccelerationIsInSecondsWhateverTheRate) {
  // The dVRK streams at 100 Hz to 1.5 kHz: the same motion must give the same
  // acceleration range, close to the true a w^2 (the 30 ms low-pass shaves 1-2 %).
  for (double rate : {100.0, 200.0, 1500.0}) {
    const TrainingRegime r = rcm::dynamics::compute_training_regime({make_path(1.0, rate, 20.0)}, 3);
    for (int j = 0; j < 3; ++j) {
      const double truth = kAmplitude[j] * kOmega[j] * kOmega[j];
      EXPECT_NEAR(r.acceleration_abs_max[j], truth, 0.05 * truth) << rate << " Hz, joint " << j + 1;
    }
  }
}

TEST(RegimeMonitor, FlagsOnlyWhatLeavesTheRegime) {
  const RegimeMonitor monitor(rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 30.0)}, 3));
  ASSERT_TRUE(monitor.known());
  // The same motion at another rate: inside.
  const auto same = rcm::dynamics::compute_regime_summary(monitor, make_path(1.0, 1000.0, 30.0));
  EXPECT_EQ(same.flagged, 0u) << same.to_text();
  // Slower: still inside (coverage says nothing about a model's accuracy there).
  EXPECT_EQ(rcm::dynamics::compute_regime_summary(monitor, make_path(0.5, 100.0, 30.0)).flagged, 0u);
  // Twice as fast: velocity and acceleration of every joint, never position.
  const auto fast = rcm::dynamics::compute_regime_summary(monitor, make_path(2.0, 200.0, 30.0));
  EXPECT_GT(fast.get_fraction(), 0.2);
  for (int j = 0; j < 3; ++j) {
    EXPECT_TRUE(fast.all_flags & regime_bit(j, RegimeQuantity::velocity)) << j;
    EXPECT_TRUE(fast.all_flags & regime_bit(j, RegimeQuantity::acceleration)) << j;
    EXPECT_FALSE(fast.all_flags & regime_bit(j, RegimeQuantity::position)) << j;
  }
  ASSERT_TRUE(fast.first_time_s.has_value());
  EXPECT_NE(fast.to_text().find("joint 1 velocity"), std::string::npos) << fast.to_text();
  // Pitch moved 0.2 rad beyond its range: pitch position only.
  const auto shifted = rcm::dynamics::compute_regime_summary(monitor, make_path(1.0, 200.0, 30.0, Eigen::Vector3d(0, 0.2, 0)));
  EXPECT_EQ(shifted.all_flags, regime_bit(1, RegimeQuantity::position));
  EXPECT_EQ(rcm::dynamics::describe_regime_flags(shifted.all_flags), "joint 2 position");
}

TEST(RegimeMonitor, MarginsForgiveTheEdges) {
  TrainingRegime r = rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 30.0)}, 3);
  rcm::dynamics::RegimeCheckOptions options;
  options.velocity_margin = 0.0;
  const RegimeMonitor strict(r, options), lenient(r);
  const rcm::Recording faster = make_path(1.05, 200.0, 30.0);  // 5 % faster, within the default 10 %
  EXPECT_GT(rcm::dynamics::compute_regime_summary(strict, faster).flagged, 0u);
  const auto s = rcm::dynamics::compute_regime_summary(lenient, faster);
  EXPECT_FALSE(s.all_flags & regime_bit(0, RegimeQuantity::velocity)) << s.to_text();
  options.velocity_margin = -1.0;
  EXPECT_THROW(RegimeMonitor(r, options), std::invalid_argument);
}

TEST(RegimeMonitor, UnknownRegimeChecksNothingAndSaysSo) {
  const RegimeMonitor monitor(TrainingRegime{});
  EXPECT_FALSE(monitor.known());
  const auto s = rcm::dynamics::compute_regime_summary(monitor, make_path(3.0, 200.0, 5.0));
  EXPECT_FALSE(s.known);
  EXPECT_EQ(s.flagged, 0u);
  EXPECT_NE(s.to_text().find("not checked"), std::string::npos);
  EXPECT_EQ(s.to_json()["checked"], false);
}

TEST(RegimeMonitor, NanIsOutside) {
  const RegimeMonitor monitor(rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 10.0)}, 3));
  auto ws = monitor.create_workspace();
  const double q[3] = {0.0, std::nan(""), 0.12}, qd[3] = {0, 0, 0};
  EXPECT_TRUE(monitor.compute_flags(ws, 0.0, q, qd) & regime_bit(1, RegimeQuantity::position));
}

TEST(TrainingRegime, JsonRoundTripAndLocatedErrors) {
  const TrainingRegime r = rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 10.0)}, 3);
  const nlohmann::json j = rcm::dynamics::regime_to_json(r);
  const TrainingRegime back = rcm::dynamics::regime_from_json(j, "m.json");
  EXPECT_EQ(back.position_min, r.position_min);
  EXPECT_EQ(back.velocity_max, r.velocity_max);
  EXPECT_EQ(back.acceleration_abs_max, r.acceleration_abs_max);
  EXPECT_EQ(back.samples, r.samples);
  EXPECT_TRUE(rcm::dynamics::regime_from_json(nullptr, "m.json").empty());
  auto expect_error = [](nlohmann::json bad, const std::string& field) {
    try {
      rcm::dynamics::regime_from_json(bad, "m.json");
      ADD_FAILURE() << "accepted " << bad.dump();
    } catch (const rcm::InputError& e) {
      EXPECT_EQ(e.where().file, "m.json");
      EXPECT_EQ(e.where().field, field) << e.what();
    }
  };
  nlohmann::json bad = j;
  bad.erase("velocity_min");
  expect_error(bad, "regime.velocity_min");
  bad = j;
  bad["position_max"] = {1.0, 2.0};
  expect_error(bad, "regime.position_max");
  bad = j;
  bad["velocity_max"] = {-9.0, -9.0, -9.0};
  expect_error(bad, "regime.velocity_max");
  bad = j;
  bad["acceleration_abs_max"][2] = "fast";
  expect_error(bad, "regime.acceleration_abs_max[2]");
  expect_error(nlohmann::json::array(), "regime");
}

std::shared_ptr<const rcm::dynamics::LinearTorqueModel> make_linear_model(TrainingRegime regime) {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  info.regime = std::move(regime);
  rcm::dynamics::LinearTorqueParameters p{Eigen::VectorXd::Zero(17), Eigen::VectorXd::Zero(3), Eigen::VectorXd::Zero(3),
                                          Eigen::VectorXd::Zero(3),  Eigen::VectorXd::Zero(3), Eigen::VectorXd::Constant(3, 1e-3)};
  return std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, p);
}

TEST(TrainingRegime, TravelsWithTheModelFile) {
  const TrainingRegime r = rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 10.0)}, 3);
  const auto model = make_linear_model(r);
  const nlohmann::json doc = rcm::dynamics::torque_model_to_json(*model);
  const auto back = rcm::dynamics::torque_model_from_json(doc, "m.json");
  EXPECT_EQ(back->info().regime.position_max, r.position_max);
  EXPECT_EQ(back->info().regime.acceleration_abs_max, r.acceleration_abs_max);
  // A file without it (written before the regime existed, or by hand) loads, unchecked.
  nlohmann::json old = doc;
  old.erase("regime");
  EXPECT_TRUE(rcm::dynamics::torque_model_from_json(old, "m.json")->info().regime.empty());
  // The regime covers the first joints, those the model reads: fewer than
  // the model's joints load; more are a located error.
  nlohmann::json narrow = doc;
  narrow["regime"] = rcm::dynamics::regime_to_json(rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 1.0)}, 2));
  EXPECT_EQ(rcm::dynamics::torque_model_from_json(narrow, "m.json")->info().regime.num_joints(), 2);
  nlohmann::json wide = doc;
  for (const char* key : {"position_min", "position_max", "velocity_min", "velocity_max", "acceleration_abs_max"})
    wide["regime"][key].push_back(0.0);
  EXPECT_THROW(rcm::dynamics::torque_model_from_json(wide, "m.json"), rcm::InputError);
}

TEST(TrainingRegime, FitsRecordWhatTheySaw) {
  rcm::Recording rec = make_path(1.0, 200.0, 60.0);
  for (Eigen::Index t = 0; t < rec.time.size(); ++t)
    for (int j = 0; j < 3; ++j) rec.effort(t, j) = 0.3 * rec.position(t, j) + 0.05 * rec.velocity(t, j);
  rcm::dynamics::FitOptions options;
  options.verbose = false;
  const auto fit = rcm::dynamics::fit_linear_torque_model({rec}, options);
  const TrainingRegime& r = fit.model->info().regime;
  ASSERT_FALSE(r.empty());
  EXPECT_EQ(r.samples, rec.num_samples());
  EXPECT_EQ(r.velocity_max[2], rec.velocity.col(2).maxCoeff());

  // A dVRK's six joints, the wrist still in free space: the linear model
  // reads joints 1-3, and its regime covers those alone, so a wrist that
  // turns later is not out of it.
  rcm::Recording six = rec;
  six.position.conservativeResize(Eigen::NoChange, 6);
  six.velocity.conservativeResize(Eigen::NoChange, 6);
  six.effort.conservativeResize(Eigen::NoChange, 6);
  six.position.rightCols(3).setZero();
  six.velocity.rightCols(3).setZero();
  six.effort.rightCols(3).setZero();
  const auto fit6 = rcm::dynamics::fit_linear_torque_model({six}, options);
  EXPECT_EQ(fit6.model->info().num_joints, 6);
  EXPECT_EQ(fit6.model->info().regime.num_joints(), 3);
}

rcm::JointTissueModel linear_tissue() {
  rcm::JointTissueModel m;
  m.parameters = Eigen::Vector4d(875.0, 0.0, 2.0, 0.3);
  return m;
}

TEST(OnlinePipeline, FlagsEverySampleBeyondTheModelsRegimeWithoutAllocating) {
  const TrainingRegime r = rcm::dynamics::compute_training_regime({make_path(1.0, 200.0, 30.0)}, 3);
  const rcm::IncisionFrame incision = rcm::make_incision_frame(kQ0);
  const rcm::OnlineEstimator estimator(incision, linear_tissue(), rcm::OnlineEstimatorOptions{});
  const rcm::OnlinePipeline pipeline(make_linear_model(r), estimator);
  const rcm::OnlinePipeline unchecked(make_linear_model(TrainingRegime{}), estimator);
  ASSERT_TRUE(pipeline.regime_monitor().known());
  EXPECT_FALSE(unchecked.regime_monitor().known());

  const rcm::Recording fast = make_path(2.0, 200.0, 10.0);
  const RegimeMonitor reference(r);
  auto ref_ws = reference.create_workspace();
  auto ws = pipeline.create_workspace();
  auto ws_unchecked = unchecked.create_workspace();
  std::size_t flagged = 0;
  long allocations = 0;
  for (Eigen::Index t = 0; t < fast.time.size(); ++t) {
    const Eigen::Vector3d q = fast.position.row(t).transpose(), qd = fast.velocity.row(t).transpose();
    const double effort[3] = {0.1, -0.1, 0.2};
    const long a0 = rcm::test::get_allocation_count();
    const rcm::OnlineOutput& o = pipeline.compute_sample(ws, fast.time(t), q.data(), qd.data(), effort);
    allocations += rcm::test::get_allocation_count() - a0;
    EXPECT_EQ(o.regime_flags, reference.compute_flags(ref_ws, fast.time(t), q.data(), qd.data())) << t;
    EXPECT_EQ(o.out_of_regime, o.regime_flags != 0);
    flagged += o.out_of_regime;
    const rcm::OnlineOutput& u = unchecked.compute_sample(ws_unchecked, fast.time(t), q.data(), qd.data(), effort);
    EXPECT_FALSE(u.out_of_regime);
    // The flag says; it does not change the estimate.
    ASSERT_EQ(o.misalignment_m, u.misalignment_m) << t;
  }
  EXPECT_GT(flagged, fast.num_samples() / 5);
  EXPECT_EQ(allocations, 0);

  const rcm::OnlineReplay replay = rcm::replay_online(pipeline, fast);
  EXPECT_TRUE(replay.regime.known);
  EXPECT_EQ(replay.regime.flagged, flagged);
  EXPECT_EQ(replay.regime.samples, fast.num_samples());
}

}  // namespace
