// The linear model's zero-phase qddot on the live path (live_zero_phase): the
// torque trails its input by the half window plus half a 100 Hz period, and is
// then the offline torque of the sample it is for, at the model's rate and at
// the other rates the dVRK streams; the delay is kept in the model file; a
// stream whose time goes back restarts the windows; no allocation per sample.
// And the estimate both paths share: sliding moments that give the sums over
// each window to within rounding.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <cmath>
#include <random>
#include <string>
#include <tuple>

#include "../src/dynamics/acceleration.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/networks.hpp"
#include "rcm/dynamics/rigid_body.hpp"

using rcm::test::g_allocations;
using namespace rcm::dynamics;

namespace {

constexpr double kPi = 3.14159265358979323846;

TorqueModelInfo make_info(double period) {
  TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = period;
  return info;
}

// Every term of the model in play, each joint with its own zero-phase window.
LinearTorqueParameters make_parameters(bool live_zero_phase) {
  LinearTorqueParameters p;
  p.gravity = Eigen::VectorXd::LinSpaced(LinearTorqueModel::kGravityTerms, -0.3, 0.4);
  p.armature = Eigen::Vector3d(0.15, 0.2, 0.8);
  p.viscous = Eigen::Vector3d(0.05, 0.1, 1.0);
  p.coulomb = Eigen::Vector3d(0.1, 0.12, 0.4);
  p.offset = Eigen::Vector3d(0.01, -0.02, 0.1);
  p.dahl_displacement = Eigen::Vector3d(0.01, 0.01, 0.002);
  p.acceleration_window_s = Eigen::Vector3d(0.06, 0.06, 0.06);
  p.acceleration_filter_s = Eigen::Vector3d(0.01, 0.01, 0.01);
  p.batch_acceleration_window_s = Eigen::Vector3d(0.07, 0.15, 0.30);
  p.inertia = Eigen::VectorXd::LinSpaced(kInertiaTerms, 0.01, 0.1);
  p.stiffness = Eigen::Vector3d(0.0, 0.0, 1.8);
  p.live_zero_phase = live_zero_phase;
  return p;
}

struct Stream {
  Eigen::VectorXd time;
  Eigen::MatrixXd position, velocity;
};

// Two tones per joint sampled at `period`, with uniform jitter of +- `jitter`
// periods on the stamps.
Stream make_stream(double period, double duration_s, double jitter) {
  const int T = static_cast<int>(duration_s / period);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  Stream s;
  s.time.resize(T);
  s.position.resize(T, 3);
  s.velocity.resize(T, 3);
  for (int k = 0; k < T; ++k) {
    const double t = k * period + (k > 0 ? u(rng) * period : 0.0);
    s.time(k) = t;
    for (int j = 0; j < 3; ++j) {
      const double w1 = 2 * kPi * (0.3 + 0.2 * j), w2 = 2 * kPi * (0.9 + 0.3 * j), a = j == 2 ? 0.03 : 0.5;
      s.position(k, j) = (j == 2 ? 0.1 : 0.0) + a * (std::sin(w1 * t) + 0.3 * std::sin(w2 * t + j));
      s.velocity(k, j) = a * (w1 * std::cos(w1 * t) + 0.3 * w2 * std::cos(w2 * t + j));
    }
  }
  return s;
}

}  // namespace

// The delay covers the largest half window and half a 100 Hz period, in whole
// samples of the model's rate; without the flag, or without a zero-phase
// window, the model is causal.
TEST(LiveZeroPhase, DelayCoversTheLargestHalfWindow) {
  const LinearTorqueModel live(make_info(0.005), make_parameters(true));
  EXPECT_EQ(live.output_delay(), 31);  // (0.15 + 0.005) / 0.005
  EXPECT_NEAR(live.get_output_delay_s(), 0.155, 1e-12);
  EXPECT_EQ(LinearTorqueModel(make_info(0.01), make_parameters(true)).output_delay(), 16);  // 0.155 / 0.01 up
  EXPECT_EQ(LinearTorqueModel(make_info(0.005), make_parameters(false)).output_delay(), 0);
  auto no_window = make_parameters(true);
  no_window.batch_acceleration_window_s.setZero();
  EXPECT_EQ(LinearTorqueModel(make_info(0.005), no_window).output_delay(), 0);
}

// Streamed sample by sample, the torque of every sample whose windows lie
// inside the stream is the offline one (predict_torque), at the model's rate
// and at 100 Hz and 1 kHz, with regular and jittered stamps; the causal model
// is not.
TEST(LiveZeroPhase, StreamedTorqueIsTheOfflineTorque) {
  const LinearTorqueModel live(make_info(0.005), make_parameters(true));
  const LinearTorqueModel causal(make_info(0.005), make_parameters(false));
  for (const auto& [period, jitter] : {std::pair{0.005, 0.1}, std::pair{0.01, 0.0}, std::pair{0.001, 0.0},
                                      std::pair{0.01, 0.1}, std::pair{0.001, 0.1}}) {
    const Stream s = make_stream(period, 8.0, jitter);
    const Eigen::MatrixXd offline = predict_torque(live, s.time, s.position, s.velocity);
    EXPECT_EQ(offline, predict_torque(causal, s.time, s.position, s.velocity));  // one offline estimate
    const Eigen::MatrixXd streamed = predict_torque_streaming(live, s.time, s.position, s.velocity);
    const Eigen::MatrixXd streamed_causal = predict_torque_streaming(causal, s.time, s.position, s.velocity);
    // Rows past the first half window and before the held tail.
    const auto inner = Eigen::seq(static_cast<Eigen::Index>(0.2 / period),
                                  s.time.size() - 1 - static_cast<Eigen::Index>(0.2 / period));
    const double scale = offline.cwiseAbs().maxCoeff();
    EXPECT_LT((streamed(inner, Eigen::all) - offline(inner, Eigen::all)).cwiseAbs().maxCoeff(), 1e-9 * scale)
        << period;
    // The causal estimate lags: off by a few percent of the torque.
    EXPECT_GT((streamed_causal(inner, Eigen::all) - offline(inner, Eigen::all)).cwiseAbs().maxCoeff(), 1e-3 * scale)
        << period;
  }
}

// A model that predicts fewer joints than it reads keeps every joint read in
// its ring: the potential reads the positions of joints 1-3.
TEST(LiveZeroPhase, FewerOutputsThanJointsRead) {
  TorqueModelInfo info = make_info(0.005);
  info.num_outputs = 2;
  LinearTorqueParameters p = make_parameters(true);
  for (Eigen::VectorXd* v : {&p.armature, &p.viscous, &p.coulomb, &p.offset, &p.dahl_displacement,
                             &p.acceleration_window_s, &p.acceleration_filter_s, &p.batch_acceleration_window_s,
                             &p.stiffness})
    v->conservativeResize(2);
  p.inertia.resize(0);
  const LinearTorqueModel live(info, p);
  const Stream s = make_stream(0.005, 4.0, 0.0);
  const Eigen::MatrixXd offline = predict_torque(live, s.time, s.position, s.velocity);
  const Eigen::MatrixXd streamed = predict_torque_streaming(live, s.time, s.position, s.velocity);
  const auto inner = Eigen::seq(40, s.time.size() - 41);
  EXPECT_LT((streamed(inner, Eigen::all) - offline(inner, Eigen::all)).cwiseAbs().maxCoeff(),
            1e-9 * offline.cwiseAbs().maxCoeff());
}

// A repeated stamp is the same sample; a stamp that goes back restarts the
// windows: the torque is then again the offline torque of the new stream, with
// the friction states carried over.
TEST(LiveZeroPhase, TimeGoingBackRestartsTheWindows) {
  const LinearTorqueModel live(make_info(0.005), make_parameters(true));
  const Stream s = make_stream(0.005, 4.0, 0.0);
  const Eigen::Index T = s.time.size(), d = live.output_delay();
  auto ws = live.create_workspace();
  double tau[3];
  for (int pass = 0; pass < 2; ++pass)
    for (Eigen::Index k = 0; k < T; ++k) {
      const Eigen::Vector3d q = s.position.row(k).transpose(), qd = s.velocity.row(k).transpose();
      live.compute_step(*ws, s.time(k), q.data(), qd.data(), tau);
      if (k == T / 2) live.compute_step(*ws, s.time(k), q.data(), qd.data(), tau);  // repeated stamp
      if (pass == 1 && k == T - 1) {
        // The second pass's offline torque, with the first pass's friction states as its start.
        Stream twice = s;
        twice.time.conservativeResize(2 * T);
        twice.position.conservativeResize(2 * T, 3);
        twice.velocity.conservativeResize(2 * T, 3);
        twice.time.tail(T) = s.time.array() + 10.0;
        twice.position.bottomRows(T) = s.position;
        twice.velocity.bottomRows(T) = s.velocity;
        const Eigen::MatrixXd offline = predict_torque(live, twice.time, twice.position, twice.velocity);
        for (int j = 0; j < 3; ++j) EXPECT_NEAR(tau[j], offline(2 * T - 1 - d, j), 1e-9) << j;
      }
    }
}

// The model file keeps the flag (and so the delay); a value that is not a
// boolean is refused with its field; files without it are causal.
TEST(LiveZeroPhase, ModelFileKeepsTheFlag) {
  const LinearTorqueModel live(make_info(0.005), make_parameters(true));
  nlohmann::json doc = torque_model_to_json(live);
  EXPECT_EQ(doc["parameters"]["live_zero_phase"], true);
  EXPECT_EQ(torque_model_from_json(nlohmann::json::parse(doc.dump()), "m.json")->output_delay(), 31);
  doc["parameters"]["live_zero_phase"] = "yes";
  try {
    torque_model_from_json(doc, "m.json");
    ADD_FAILURE() << "a string was taken for the flag";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("m.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("parameters.live_zero_phase"), std::string::npos) << e.what();
  }
  // A window too long to run live (its delay and window beyond the ring).
  doc["parameters"]["live_zero_phase"] = true;
  auto p = make_parameters(false);
  p.batch_acceleration_window_s(1) = 1e300;
  doc["parameters"]["batch_acceleration_window_s"] =
      torque_model_to_json(LinearTorqueModel(make_info(0.005), p))["parameters"]["batch_acceleration_window_s"];
  try {
    torque_model_from_json(doc, "m.json");
    ADD_FAILURE() << "a 1e300 s window was run live";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("parameters.live_zero_phase"), std::string::npos) << e.what();
  }
  p.live_zero_phase = true;
  EXPECT_THROW(LinearTorqueModel(make_info(0.005), p), std::invalid_argument);
  doc["parameters"].erase("live_zero_phase");
  EXPECT_EQ(torque_model_from_json(doc, "m.json")->output_delay(), 0);
  EXPECT_FALSE(torque_model_to_json(LinearTorqueModel(make_info(0.005), make_parameters(false)))["parameters"]
                   .contains("live_zero_phase"));
}

// The hybrid steps its base beside its network, both without delay: a base
// with its zero-phase qddot live is refused, in memory and in a file.
TEST(LiveZeroPhase, TheHybridsBaseStaysCausal) {
  const TorqueModelInfo info = make_info(0.005);
  Normalization norm;
  norm.input_mean = Eigen::VectorXf::Zero(6);
  norm.input_scale = Eigen::VectorXf::Ones(6);
  norm.output_mean = Eigen::VectorXf::Zero(3);
  norm.output_scale = Eigen::VectorXf::Ones(3);
  const auto causal = std::make_shared<const LinearTorqueModel>(info, make_parameters(false));
  const auto live = std::make_shared<const LinearTorqueModel>(info, make_parameters(true));
  const HybridTorqueModel hybrid(info, causal, make_random_lstm_network(6, 3, 1, 3, 3, 3), norm);
  EXPECT_EQ(hybrid.output_delay(), 0);
  EXPECT_THROW(HybridTorqueModel(info, live, make_random_lstm_network(6, 3, 1, 3, 3, 3), norm), std::invalid_argument);
  nlohmann::json doc = torque_model_to_json(hybrid);
  doc["parameters"]["base"]["live_zero_phase"] = true;
  try {
    torque_model_from_json(doc, "h.json");
    ADD_FAILURE() << "a hybrid with a delayed base was loaded";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("parameters.base.live_zero_phase"), std::string::npos) << e.what();
  }
}

// The ring is sized by create_workspace for streams up to 2 kHz: no allocation
// per sample at 200 Hz or 1.5 kHz, through a stamp that goes back and a reset.
TEST(LiveZeroPhase, ComputeStepDoesNotAllocate) {
  const LinearTorqueModel live(make_info(0.005), make_parameters(true));
  for (double rate : {200.0, 1500.0}) {
    auto ws = live.create_workspace();
    double q[3] = {0, 0, 0.1}, qd[3] = {0, 0, 0}, tau[3];
    const long before = g_allocations;
    for (int k = 0; k < 3000; ++k) {
      qd[0] = std::sin(k / rate);
      q[0] += qd[0] / rate;
      live.compute_step(*ws, (k % 2000) / rate, q, qd, tau);
    }
    live.reset_state(*ws);
    live.compute_step(*ws, 0.0, q, qd, tau);
    EXPECT_EQ(g_allocations - before, 0) << rate;
  }
}

// A fit takes the flag from FitOptions::live_zero_phase.
TEST(LiveZeroPhase, FitOptionSetsTheFlag) {
  const Stream s = make_stream(0.005, 20.0, 0.0);
  const LinearTorqueModel truth(make_info(0.005), make_parameters(false));
  rcm::Recording r;
  r.source = "memory";
  r.time = s.time;
  r.position = s.position;
  r.velocity = s.velocity;
  r.effort = predict_torque(truth, s.time, s.position, s.velocity);
  FitOptions o;
  o.verbose = false;
  const auto live = fit_linear_torque_model({r}, o);
  EXPECT_TRUE(static_cast<const LinearTorqueModel&>(*live.model).parameters().live_zero_phase);
  EXPECT_GT(live.model->output_delay(), 0);
  o.live_zero_phase = false;
  EXPECT_EQ(fit_linear_torque_model({r}, o).model->output_delay(), 0);
}

// The window's moments slide with it (ZeroPhaseSlope): against the sums taken
// afresh over each window, the slope agrees to 1e-10 of its scale at 1.5 kHz
// over a 0.4 s window (600 samples) for a minute of jittered stamps, a
// velocity offset a hundred times its swing, and through every re-anchoring.
TEST(ZeroPhaseSlope, SlidingMomentsMatchTheSumsOverEachWindow) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(-0.2, 0.2);
  std::normal_distribution<double> noise(0.0, 1.0);
  for (const auto& [rate, window, degree] : {std::tuple{1500.0, 0.4, 3}, std::tuple{100.0, 0.07, 3},
                                             std::tuple{200.0, 0.2, 2}}) {
    const int T = static_cast<int>(60 * rate);
    Eigen::VectorXd t(T), v(T);
    for (int k = 0; k < T; ++k) {
      t(k) = (k + jitter(rng)) / rate;
      v(k) = 100.0 + std::sin(2.0 * t(k)) + 0.3 * std::sin(7.0 * t(k)) + 0.002 * noise(rng);
    }
    const Eigen::VectorXd sliding = rcm::dynamics::detail::compute_zero_phase_acceleration(t, v, window, degree);
    const double h = 0.5 * window;
    double worst = 0.0;
    Eigen::Index lo = 0, hi = 0;
    for (Eigen::Index i = 0; i < T; ++i) {
      while (t(lo) < t(i) - h * (1.0 + 1e-9)) ++lo;
      hi = std::max(hi, i + 1);
      while (hi < T && t(hi) <= t(i) + h * (1.0 + 1e-9)) ++hi;
      double m[7] = {}, w[4] = {};
      for (Eigen::Index k = lo; k < hi; ++k) {
        const double x = (t(k) - t(i)) / h;
        double p = 1.0;
        for (int q = 0; q < 7; ++q, p *= x) {
          m[q] += p;
          if (q < 4) w[q] += (v(k) - v(i)) * p;  // the offset out, for a reference that keeps its digits
        }
      }
      // The same fallbacks: the quadratic, then the difference across the window.
      double slope = 0.0, reference = 0.0;
      if (rcm::dynamics::detail::compute_moment_slope(m, w, degree, slope) ||
          rcm::dynamics::detail::compute_moment_slope(m, w, 2, slope))
        reference = slope / h;
      else
        reference = (v(hi - 1) - v(lo)) / (t(hi - 1) - t(lo));
      worst = std::max(worst, std::abs(sliding(i) - reference));
    }
    EXPECT_LT(worst, 1e-10 * sliding.cwiseAbs().maxCoeff()) << rate << " Hz, " << window << " s";
  }
}
