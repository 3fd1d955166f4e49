// The models' time: an output delay in seconds, the clock that steps a network
// at its training period whatever the rate of the samples it is given, and the
// one that steps the linear model's friction states at the rate it was fitted at.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/networks.hpp"
#include "test_dynamics_networks.hpp"
#include "test_dynamics_synthetic.hpp"

using namespace rcm::dynamics;
using namespace rcm::test;

namespace {
// A smooth 3-joint path of T samples at 200 Hz.
struct Path3 {
  Eigen::VectorXd time;
  Eigen::MatrixXd position, velocity;
};
Path3 make_path3(Eigen::Index T) {
  Path3 p;
  p.time = Eigen::VectorXd::LinSpaced(T, 0.0, 0.005 * static_cast<double>(T - 1));
  p.position.resize(T, 3);
  p.velocity.resize(T, 3);
  for (Eigen::Index t = 0; t < T; ++t)
    for (int k = 0; k < 3; ++k) {
      const double w = 2.0 + k, s = p.time(t);
      p.position(t, k) = 0.3 * std::sin(w * s + k);
      p.velocity(t, k) = 0.3 * w * std::cos(w * s + k);
    }
  return p;
}
// The path followed by `extra` copies of its last sample, time advancing at 5 ms.
Path3 hold_last(const Path3& p, Eigen::Index extra) {
  const Eigen::Index T = p.time.size();
  Path3 q;
  q.time.resize(T + extra);
  q.position.resize(T + extra, 3);
  q.velocity.resize(T + extra, 3);
  q.time.head(T) = p.time;
  q.position.topRows(T) = p.position;
  q.velocity.topRows(T) = p.velocity;
  for (Eigen::Index k = 0; k < extra; ++k) {
    q.time(T + k) = p.time(T - 1) + 0.005 * static_cast<double>(k + 1);
    q.position.row(T + k) = p.position.row(T - 1);
    q.velocity.row(T + k) = p.velocity.row(T - 1);
  }
  return q;
}
// With an acceleration feature, so that the held samples' time stamps matter.
Normalization norm3_with_acceleration() {
  Normalization norm = norm3(Eigen::VectorXf::LinSpaced(6, 0.3f, 0.9f));
  norm.acceleration_filter_s = Eigen::VectorXf::Constant(1, 0.02f);
  norm.acceleration_scale = Eigen::VectorXf::LinSpaced(3, 0.5f, 2.0f);
  return norm;
}
}  // namespace

TEST(OutputDelay, PredictionsAlignTheDelayedNetworkAndHoldTheLastSample) {
  const Normalization norm = norm3_with_acceleration();
  const auto net = random_lstm(9, 16, 1, 8, 3, 41);
  const int d = 5;
  const LstmTorqueModel causal(info3(), net, norm), delayed(info3(), net, norm, d);
  EXPECT_EQ(causal.output_delay(), 0);
  EXPECT_EQ(delayed.output_delay(), d);
  const Eigen::Index T = 120;
  const Path3 p = make_path3(T);
  // The network's own outputs over the path and d held samples after it: row t + d
  // is the delayed model's torque of sample t.
  const Path3 held = hold_last(p, d);
  const Eigen::MatrixXd raw = predict_torque(causal, held.time, held.position, held.velocity);
  const Eigen::MatrixXd streamed = predict_torque_streaming(delayed, p.time, p.position, p.velocity);
  ASSERT_EQ(streamed.rows(), T);
  EXPECT_EQ((streamed - raw.bottomRows(T)).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((predict_torque(delayed, p.time, p.position, p.velocity) - streamed).cwiseAbs().maxCoeff(), 0.0);
  // Sample by sample, call t writes the torque of sample t - d.
  auto ws = delayed.create_workspace();
  for (Eigen::Index t = 0; t < T; ++t) {
    Eigen::VectorXd q = p.position.row(t).transpose(), qd = p.velocity.row(t).transpose(), tau(3);
    delayed.compute_step(*ws, p.time(t), q.data(), qd.data(), tau.data());
    if (t >= d) ASSERT_EQ((tau.transpose() - streamed.row(t - d)).cwiseAbs().maxCoeff(), 0.0) << t;
  }
  // A recording shorter than the delay: every row comes from the held samples.
  const Path3 three{p.time.head(3), p.position.topRows(3), p.velocity.topRows(3)};
  const Path3 three_held = hold_last(three, d);
  EXPECT_EQ((predict_torque_streaming(delayed, three.time, three.position, three.velocity) -
             predict_torque(causal, three_held.time, three_held.position, three_held.velocity).bottomRows(3))
                .cwiseAbs()
                .maxCoeff(),
            0.0);
  EXPECT_THROW(LstmTorqueModel(info3(), net, norm, -1), std::invalid_argument);
}

TEST(OutputDelay, ModelFileKeepsTheDelayAndLocatesBadValues) {
  const Normalization norm = norm3_with_acceleration();
  const auto net = random_lstm(9, 16, 1, 8, 3, 43);
  const LstmTorqueModel causal(info3(), net, norm), delayed(info3(), net, norm, 7);
  // Absent when 0: causal model files keep their bytes.
  EXPECT_FALSE(torque_model_to_json(causal)["parameters"].contains("output_delay_samples"));
  const nlohmann::json j = torque_model_to_json(delayed);
  EXPECT_EQ(j["parameters"]["output_delay_samples"], 7);
  const auto loaded = torque_model_from_json(j, "memory");
  EXPECT_EQ(loaded->output_delay(), 7);
  EXPECT_EQ(torque_model_to_json(*loaded), j);
  const Path3 p = make_path3(60);
  EXPECT_EQ((predict_torque(*loaded, p.time, p.position, p.velocity) -
             predict_torque(delayed, p.time, p.position, p.velocity))
                .cwiseAbs()
                .maxCoeff(),
            0.0);
  for (const nlohmann::json& bad : {nlohmann::json(-1), nlohmann::json(2.5), nlohmann::json("7"),
                                    nlohmann::json(1000000), nlohmann::json(nullptr)}) {
    nlohmann::json b = j;
    b["parameters"]["output_delay_samples"] = bad;
    try {
      torque_model_from_json(b, "memory");
      ADD_FAILURE() << "accepted " << bad.dump();
    } catch (const rcm::InputError& e) {
      EXPECT_NE(std::string(e.what()).find("parameters.output_delay_samples"), std::string::npos) << e.what();
    }
  }
}

TEST(OutputDelay, FitOptionResolvesToSamplesWithinTheBurnIn) {
  FitOptions o;
  EXPECT_DOUBLE_EQ(get_default_output_delay_s(TorqueModelKind::lstm), 0.04);
  EXPECT_EQ(resolve_output_delay_samples(TorqueModelKind::lstm, o, 0.005), 8);
  EXPECT_EQ(resolve_output_delay_samples(TorqueModelKind::lstm, o, 1.0 / 1500.0), 60);
  for (const auto kind : {TorqueModelKind::mlp, TorqueModelKind::linear, TorqueModelKind::hybrid}) {
    EXPECT_DOUBLE_EQ(get_default_output_delay_s(kind), 0.0);
    EXPECT_EQ(resolve_output_delay_samples(kind, o, 0.005), 0);
  }
  o.output_delay_s = 0.0;
  EXPECT_EQ(resolve_output_delay_samples(TorqueModelKind::lstm, o, 0.005), 0);
  o.output_delay_s = 1.0;  // 200 samples: the whole burn-in
  EXPECT_EQ(resolve_output_delay_samples(TorqueModelKind::lstm, o, 0.005), 200);
  o.output_delay_s = 1.01;
  EXPECT_THROW(resolve_output_delay_samples(TorqueModelKind::lstm, o, 0.005), rcm::InputError);
  o.output_delay_s = 0.04;
  EXPECT_THROW(resolve_output_delay_samples(TorqueModelKind::mlp, o, 0.005), rcm::InputError);
  EXPECT_THROW(resolve_output_delay_samples(TorqueModelKind::lstm, o, 0.0), rcm::InputError);
  for (const double bad : {-0.01, std::nan(""), HUGE_VAL}) {
    o.output_delay_s = bad;
    EXPECT_THROW(o.check(), rcm::InputError) << bad;
  }
}

namespace {
// The same smooth path sampled at `rate_hz` for `duration_s`.
Path3 sample_path3(double rate_hz, double duration_s) {
  const auto T = static_cast<Eigen::Index>(std::lround(duration_s * rate_hz)) + 1;
  Path3 p;
  p.time.resize(T);
  p.position.resize(T, 3);
  p.velocity.resize(T, 3);
  for (Eigen::Index t = 0; t < T; ++t) {
    const double s = static_cast<double>(t) / rate_hz;
    p.time(t) = s;
    for (int k = 0; k < 3; ++k) {
      const double w = 2.0 + k;
      p.position(t, k) = 0.3 * std::sin(w * s + k);
      p.velocity(t, k) = 0.3 * w * std::cos(w * s + k);
    }
  }
  return p;
}

TorqueModelInfo info3_at(double period_s) {
  TorqueModelInfo info = info3();
  info.sample_period_s = period_s;
  return info;
}
}  // namespace

TEST(NetworkClock, TheNetworkStepsAtItsTrainingRateWhateverTheSampleRate) {
  // A network trained at 200 Hz, given the same motion at 200 Hz, 1 kHz and
  // 100 Hz: at 1 kHz every fifth sample is one of its steps and the torque is
  // the 200 Hz one; at 100 Hz it steps twice per sample, once on inputs
  // interpolated between the samples, and stays close to the 200 Hz torque,
  // where stepping once per sample (a network trained at 100 Hz) does not.
  const Normalization norm = norm3_with_acceleration();
  const auto net = random_lstm(9, 16, 1, 8, 3, 47);
  const LstmTorqueModel model(info3_at(0.005), net, norm), per_sample(info3_at(0.01), net, norm);
  const Path3 p200 = sample_path3(200.0, 3.0), p1000 = sample_path3(1000.0, 3.0), p100 = sample_path3(100.0, 3.0);
  const Eigen::MatrixXd ref = predict_torque(model, p200.time, p200.position, p200.velocity);
  const Eigen::MatrixXd fast = predict_torque(model, p1000.time, p1000.position, p1000.velocity);
  for (Eigen::Index t = 0; t < ref.rows(); ++t)
    ASSERT_LT((fast.row(5 * t) - ref.row(t)).cwiseAbs().maxCoeff(), 1e-9) << t;
  // Between its steps the torque of the latest one is held.
  EXPECT_EQ(fast.row(7), fast.row(5));
  const Eigen::MatrixXd slow = predict_torque(model, p100.time, p100.position, p100.velocity);
  const Eigen::MatrixXd stepped = predict_torque(per_sample, p100.time, p100.position, p100.velocity);
  double clock_error = 0.0, per_sample_error = 0.0;
  for (Eigen::Index t = 20; t < slow.rows(); ++t) {
    clock_error = std::max(clock_error, (slow.row(t) - ref.row(2 * t)).cwiseAbs().maxCoeff());
    per_sample_error = std::max(per_sample_error, (stepped.row(t) - ref.row(2 * t)).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(clock_error, 0.2 * per_sample_error) << clock_error << " vs " << per_sample_error;
  EXPECT_LT(clock_error, 0.01 * (ref.maxCoeff() - ref.minCoeff()));
  // No warning until the samples are more than 4 steps apart.
  rcm::Recording r;
  r.source = "slow.csv";
  r.time = p100.time;
  r.position = p100.position;
  r.velocity = p100.velocity;
  r.effort = Eigen::MatrixXd::Zero(r.time.size(), 3);
  EXPECT_EQ(check_sample_period(model, r), "");
  const Path3 p40 = sample_path3(40.0, 3.0);
  r.time = p40.time;
  r.position = p40.position;
  r.velocity = p40.velocity;
  r.effort = Eigen::MatrixXd::Zero(r.time.size(), 3);
  EXPECT_NE(check_sample_period(model, r).find("interpolated"), std::string::npos);
}

TEST(NetworkClock, AGapRestartsTheClockInsteadOfSteppingThroughIt) {
  // After ten minutes of silence the next sample is one step, as after 0.3 s
  // (features without a time constant, so one step on the same input is the
  // same torque), not the 120 000 steps of interpolated inputs in between.
  const Normalization norm = norm3(Eigen::VectorXf::LinSpaced(6, 0.3f, 0.9f));
  const auto net = random_lstm(6, 16, 1, 8, 3, 53);
  const LstmTorqueModel model(info3_at(0.005), net, norm);
  const Path3 p = sample_path3(200.0, 1.0);
  std::vector<std::unique_ptr<TorqueModelWorkspace>> ws;
  for (int k = 0; k < 3; ++k) ws.push_back(model.create_workspace());
  Eigen::VectorXd tau(3);
  for (Eigen::Index t = 0; t < p.time.size(); ++t) {
    const Eigen::VectorXd q = p.position.row(t).transpose(), qd = p.velocity.row(t).transpose();
    for (auto& w : ws) model.compute_step(*w, p.time(t), q.data(), qd.data(), tau.data());
  }
  const double last = p.time(p.time.size() - 1);
  const Eigen::VectorXd q = p.position.row(0).transpose(), qd = p.velocity.row(0).transpose();
  Eigen::VectorXd after_silence(3), after_gap(3), stepped_through(3);
  model.compute_step(*ws[0], last + 600.0, q.data(), qd.data(), after_silence.data());
  model.compute_step(*ws[1], last + 0.3, q.data(), qd.data(), after_gap.data());
  model.compute_step(*ws[2], last + 0.2, q.data(), qd.data(), stepped_through.data());  // 40 steps
  EXPECT_EQ(after_silence, after_gap);
  EXPECT_GT((stepped_through - after_gap).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(OutputDelay, TheDelayIsInSecondsAtAnotherRate) {
  // A network trained at 200 Hz with a delay of 8 steps (40 ms), given 100 Hz
  // samples: row t of the streamed prediction is the output of call t + 4.
  const Normalization norm = norm3_with_acceleration();
  const auto net = random_lstm(9, 16, 1, 8, 3, 59);
  const LstmTorqueModel delayed(info3_at(0.005), net, norm, 8);
  EXPECT_DOUBLE_EQ(delayed.get_output_delay_s(), 0.04);
  const Path3 p = sample_path3(100.0, 2.0);
  const Eigen::MatrixXd streamed = predict_torque_streaming(delayed, p.time, p.position, p.velocity);
  auto ws = delayed.create_workspace();
  Eigen::VectorXd tau(3);
  for (Eigen::Index t = 0; t < p.time.size(); ++t) {
    const Eigen::VectorXd q = p.position.row(t).transpose(), qd = p.velocity.row(t).transpose();
    delayed.compute_step(*ws, p.time(t), q.data(), qd.data(), tau.data());
    if (t >= 4) ASSERT_EQ((tau.transpose() - streamed.row(t - 4)).cwiseAbs().maxCoeff(), 0.0) << t;
  }
}

namespace {
// Coulomb friction through the Dahl state alone: tau_j = 0.5 z_j.
LinearTorqueModel make_dahl_only_model(double period_s) {
  TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = period_s;
  LinearTorqueParameters p;
  p.gravity = Eigen::VectorXd::Zero(LinearTorqueModel::kGravityTerms);
  p.armature = Eigen::VectorXd::Zero(3);
  p.viscous = Eigen::VectorXd::Zero(3);
  p.coulomb = Eigen::VectorXd::Constant(3, 0.5);
  p.offset = Eigen::VectorXd::Zero(3);
  p.dahl_displacement = Eigen::VectorXd::Constant(3, 5e-5);
  return LinearTorqueModel(info, p);
}
// Joints that move forward for 1 s, then stand while their encoder blips up a
// count (2e-5) for a millisecond in every 5 ms, between the samples of a
// 200 Hz stream: what a still PSM's encoders do under their controller,
// sampled at `rate_hz` for 3 s.
Path3 make_still_with_blipping_encoder(double rate_hz) {
  const auto T = static_cast<Eigen::Index>(std::llround(3.0 * rate_hz)) + 1;
  Path3 p;
  p.time.resize(T);
  p.position.resize(T, 3);
  p.velocity = Eigen::MatrixXd::Zero(T, 3);
  for (Eigen::Index k = 0; k < T; ++k) {
    const double t = static_cast<double>(k) / rate_hz;
    const double phase = std::fmod(t + 1e-9, 0.005);
    const bool blip = t > 1.0 && phase >= 0.0005 && phase < 0.0015;
    p.time(k) = t;
    p.position.row(k).setConstant(0.01 * std::min(t, 1.0) + (blip ? 2e-5 : 0.0));
    if (t < 1.0) p.velocity.row(k).setConstant(0.01);
  }
  return p;
}
}  // namespace

TEST(DahlClock, TheFrictionStateStepsAtTheFittedRateWhateverTheStreamsRate) {
  // A model fitted at 200 Hz, streamed at 200 Hz and at 1.5 kHz over the same
  // motion: the holding torque after a forward move, on a still arm whose
  // encoder blips between the 200 Hz samples. Stepped on every sample at
  // 1.5 kHz, each blip would move the Dahl state up and back, and the blips
  // would erase the friction's memory of the move; on the model's clock the
  // holding torque is the 200 Hz one.
  const LinearTorqueModel model = make_dahl_only_model(0.005);
  const Path3 slow = make_still_with_blipping_encoder(200.0), fast = make_still_with_blipping_encoder(1500.0);
  const Eigen::MatrixXd at_200 = predict_torque(model, slow.time, slow.position, slow.velocity);
  const Eigen::MatrixXd at_1500 = predict_torque(model, fast.time, fast.position, fast.velocity);
  const Eigen::MatrixXd per_sample =
      predict_torque(make_dahl_only_model(1.0 / 1500.0), fast.time, fast.position, fast.velocity);
  const Eigen::Index last_slow = at_200.rows() - 1, last_fast = at_1500.rows() - 1;
  EXPECT_NEAR(at_200(last_slow, 0), 0.5, 1e-6);  // the move's memory: z = 1
  EXPECT_NEAR(at_1500(last_fast, 0), at_200(last_slow, 0), 1e-6);
  EXPECT_LT(per_sample(last_fast, 0), 0.0);  // stepped on every blip: the memory erased
  // While it moves, the state is the same whatever the sampling (exact over any displacement).
  for (Eigen::Index k = 20; k < 200; k += 2)
    EXPECT_NEAR(at_1500(k * 15 / 2, 1), at_200(k, 1), 1e-9) << k;
}

TEST(DahlClock, StepsEverySampleAtTheFittedRateAndSlowerAndRestartsWhenTimeGoesBack) {
  DahlClock clock(0.005);
  EXPECT_TRUE(clock.tick(10.0));
  EXPECT_TRUE(clock.tick(10.0052));  // jittered stamps at the fitted rate
  EXPECT_TRUE(clock.tick(10.0099));
  EXPECT_TRUE(clock.tick(10.020));   // slower
  EXPECT_FALSE(clock.tick(10.021));  // faster: within half a period of the last step
  EXPECT_FALSE(clock.tick(10.0224));
  EXPECT_TRUE(clock.tick(10.0251));
  EXPECT_TRUE(clock.tick(3.0));  // another stream
  EXPECT_FALSE(clock.tick(3.001));
  EXPECT_TRUE(clock.tick(3.006));
  int steps = 0;
  DahlClock fast(0.005);
  for (int k = 0; k <= 1500; ++k) steps += fast.tick(k / 1500.0);
  EXPECT_NEAR(steps, 201, 1);  // a second at 1.5 kHz steps at 200 Hz
}
