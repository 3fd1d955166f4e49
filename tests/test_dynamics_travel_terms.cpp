// The travel terms of the linear model (dynamics/travel_terms.hpp): the
// regressor against its definition, the model's torque against the regressor
// times the coefficients, the fit on an arm whose pitch has a torque and a
// hysteretic friction along its travel, and the model file.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "rcm/dynamics/travel_terms.hpp"

namespace {

using rcm::dynamics::kTravelColumns;
using rcm::dynamics::kTravelHysteresisElements;
using rcm::dynamics::kTravelHysteresisKnots;
using rcm::dynamics::kTravelTorqueKnots;

// Piecewise-linear interpolation through K values at knots equally spaced over
// [lo, hi], constant beyond: written out here, apart from compute_knot_weights.
double interpolate(const double* values, int K, double lo, double hi, double x) {
  const double step = (hi - lo) / (K - 1);
  if (x <= lo) return values[0];
  if (x >= hi) return values[K - 1];
  const int k = std::min(static_cast<int>((x - lo) / step), K - 2);
  const double u = (x - (lo + k * step)) / step;
  return (1.0 - u) * values[k] + u * values[k + 1];
}

TEST(TravelTerms, RegressorIsTheKnotBasisAndTheElementsTimesTheirKnots) {
  const double lo = -0.7, hi = 0.9;
  double z[kTravelHysteresisElements];
  for (int h = 0; h < kTravelHysteresisElements; ++h) z[h] = 0.9 - 0.3 * h;
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd torque(kTravelTorqueKnots), levels(kTravelHysteresisElements * kTravelHysteresisKnots);
  for (auto& v : torque) v = n(rng);
  for (auto& v : levels) v = n(rng);
  Eigen::VectorXd c(kTravelColumns);
  c << torque, levels;
  for (double q : {-2.0, -0.7, -0.31, 0.0, 0.123, 0.5, 0.9, 1.7}) {
    Eigen::VectorXd row(kTravelColumns);
    rcm::dynamics::compute_travel_regressor(q, lo, hi, z, kTravelHysteresisElements, kTravelTorqueKnots,
                                            kTravelHysteresisKnots, row.data());
    // The torque's knot weights sum to one, as do each element's.
    EXPECT_NEAR(row.head(kTravelTorqueKnots).sum(), 1.0, 1e-12) << "q " << q;
    double expected = interpolate(torque.data(), kTravelTorqueKnots, lo, hi, q);
    for (int h = 0; h < kTravelHysteresisElements; ++h) {
      EXPECT_NEAR(row.segment(kTravelTorqueKnots + h * kTravelHysteresisKnots, kTravelHysteresisKnots).sum(), z[h],
                  1e-12);
      expected += z[h] * interpolate(levels.data() + h * kTravelHysteresisKnots, kTravelHysteresisKnots, lo, hi, q);
    }
    EXPECT_NEAR(row.dot(c), expected, 1e-12) << "q " << q;
  }
}

// A model with nothing but joint `j`'s travel terms (and zero elsewhere).
rcm::dynamics::LinearTorqueParameters make_travel_only(int j, double lo, double hi, unsigned seed) {
  rcm::dynamics::LinearTorqueParameters p;
  p.gravity = Eigen::VectorXd::Zero(17);
  p.armature = p.viscous = p.coulomb = p.offset = Eigen::VectorXd::Zero(3);
  p.dahl_displacement = Eigen::VectorXd::Constant(3, 1e-3);
  p.travel_range = Eigen::MatrixXd(3, 2);
  p.travel_range.col(0).setConstant(lo);
  p.travel_range.col(1).setConstant(hi);
  p.travel_torque = Eigen::MatrixXd::Zero(3, kTravelTorqueKnots);
  p.travel_hysteresis = Eigen::MatrixXd::Zero(3, kTravelHysteresisElements * kTravelHysteresisKnots);
  p.travel_hysteresis_displacement = Eigen::MatrixXd(3, kTravelHysteresisElements);
  for (int h = 0; h < kTravelHysteresisElements; ++h)
    p.travel_hysteresis_displacement.col(h).setConstant(rcm::dynamics::kTravelHysteresisFractions[h] * (hi - lo));
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 0.1);
  for (int k = 0; k < kTravelTorqueKnots; ++k) p.travel_torque(j, k) = n(rng);
  for (int k = 0; k < p.travel_hysteresis.cols(); ++k) p.travel_hysteresis(j, k) = n(rng);
  return p;
}

TEST(TravelTerms, ModelTorqueIsTheRegressorTimesTheCoefficients) {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.01;
  const double lo = -0.8, hi = 0.8;
  const auto p = make_travel_only(1, lo, hi, 5);
  const rcm::dynamics::LinearTorqueModel model(info, p);
  auto ws = model.create_workspace();
  // Pitch back and forth over the range and beyond it; the elements' states
  // and the torque written out from their definitions.
  // Rows copied out: a matrix row's data() strides over the rows.
  const Eigen::RowVectorXd torque = p.travel_torque.row(1), levels = p.travel_hysteresis.row(1);
  double z[kTravelHysteresisElements] = {};
  double previous = 0.0;
  for (int t = 0; t < 400; ++t) {
    const double q2 = 1.0 * std::sin(0.05 * t) + 0.2 * std::sin(0.31 * t);
    double q[3] = {0.1, q2, 0.12}, qd[3] = {0, 0, 0}, tau[3];
    model.compute_step(*ws, 0.01 * t, q, qd, tau);
    double expected = interpolate(torque.data(), kTravelTorqueKnots, lo, hi, q2);
    for (int h = 0; h < kTravelHysteresisElements; ++h) {
      if (t > 0) {
        const double dq = q2 - previous, x_c = p.travel_hysteresis_displacement(1, h);
        const double s = dq > 0 ? 1.0 : -1.0;
        if (dq != 0.0) z[h] = s + (z[h] - s) * std::exp(-std::abs(dq) / x_c);
      }
      expected += z[h] * interpolate(levels.data() + h * kTravelHysteresisKnots, kTravelHysteresisKnots, lo, hi, q2);
    }
    previous = q2;
    EXPECT_NEAR(tau[1], expected, 1e-12) << "t " << t;
    EXPECT_EQ(tau[0], 0.0);  // the other joints have no travel terms
    EXPECT_EQ(tau[2], 0.0);
  }
}

// An arm whose pitch carries, besides gravity, inertia and Dahl friction, a
// torque along its travel and a friction that overshoots after each reversal
// (a short element over a longer one of the other sign), driven along a
// periodic path at `speed` (0.5: the same path points at half the rate).
rcm::Recording make_run(double speed, double rate_hz, double duration_s, unsigned seed) {
  const Eigen::Vector3d g = Eigen::Vector3d(0.2, -0.3, 0.93).normalized();
  Eigen::Matrix<double, rcm::dynamics::kGravityMoments, 1> v;
  v << 0.3, -0.4, 1.2, -0.6, 0.2, 2.5, 0.8;
  Eigen::Matrix<double, 17, rcm::dynamics::kGravityMoments> P;
  rcm::dynamics::compute_gravity_moment_map(g, P);
  const Eigen::Matrix<double, 17, 1> gravity = P * v;
  const Eigen::Vector3d armature(0.05, 0.06, 0.4), viscous(0.02, 0.03, 0.3), coulomb(0.06, 0.08, 0.4),
      x_c(0.01, 0.01, 0.001);
  const double a[3][3] = {{0.3, 0.1, 0.05}, {0.35, 0.12, 0.04}, {0.04, 0.02, 0.01}};
  const double w0 = 2 * M_PI / 4.0;
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  const auto T = static_cast<Eigen::Index>(duration_s * rate_hz);
  rcm::Recording r;
  r.source = "arm with pitch travel terms";
  r.time.resize(T);
  r.position.resize(T, 3);
  r.velocity.resize(T, 3);
  r.effort.resize(T, 3);
  Eigen::Vector3d z = Eigen::Vector3d::Zero(), q_prev = Eigen::Vector3d::Zero();
  double z_short = 0.0, z_long = 0.0;
  for (Eigen::Index t = 0; t < T; ++t) {
    const double time = static_cast<double>(t) / rate_hz, s = speed * time;
    double q[3] = {0.0, 0.0, 0.13}, qd[3] = {0, 0, 0}, qdd[3] = {0, 0, 0};
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) {
        const double w = (k + 1) * w0 * (1.0 + 0.37 * j), phase = 0.7 * j + 1.3 * k;
        q[j] += a[j][k] * std::sin(w * s + phase);
        qd[j] += a[j][k] * w * speed * std::cos(w * s + phase);
        qdd[j] -= a[j][k] * w * w * speed * speed * std::sin(w * s + phase);
      }
    Eigen::Matrix<double, 3, 17> Yg;
    rcm::dynamics::LinearTorqueModel::compute_gravity_regressor(q, Yg);
    if (t > 0) {
      const double dq2 = q[1] - q_prev[1];
      z_short = rcm::dynamics::compute_dahl_state(z_short, dq2, 0.004);
      z_long = rcm::dynamics::compute_dahl_state(z_long, dq2, 0.08);
    }
    for (int j = 0; j < 3; ++j) {
      if (t > 0) z[j] = rcm::dynamics::compute_dahl_state(z[j], q[j] - q_prev[j], x_c[j]);
      r.time(t) = time;
      r.position(t, j) = q[j];
      r.velocity(t, j) = qd[j];
      double tau = Yg.row(j).dot(gravity) + armature[j] * qdd[j] + viscous[j] * qd[j] + coulomb[j] * z[j] +
                   (j == 2 ? 0.02 : 0.005) * noise(rng);
      if (j == 1) tau += 0.05 * std::sin(7.0 * q[1]) + (0.12 + 0.05 * q[1]) * z_short - 0.07 * z_long;
      r.effort(t, j) = tau;
    }
    q_prev = Eigen::Vector3d(q[0], q[1], q[2]);
  }
  return r;
}

TEST(TravelTerms, PitchTorqueAndHysteresisAlongTheTravelAreFoundAndCarryToTheSlowRun) {
  const rcm::Recording fast = make_run(1.0, 200.0, 60.0, 7), slow = make_run(0.5, 100.0, 120.0, 8);
  rcm::dynamics::FitOptions options;
  options.verbose = false;
  const auto fit = rcm::dynamics::fit_linear_torque_model({fast}, options);
  options.travel_terms = false;
  const auto without = rcm::dynamics::fit_linear_torque_model({fast}, options);
  const auto& p = static_cast<const rcm::dynamics::LinearTorqueModel&>(*fit.model).parameters();
  ASSERT_EQ(p.travel_torque.rows(), 3);
  EXPECT_GT(p.travel_torque.row(1).norm() + p.travel_hysteresis.row(1).norm(), 0.0);
  EXPECT_EQ(p.travel_torque.row(0).norm() + p.travel_hysteresis.row(0).norm(), 0.0);  // pitch only
  EXPECT_EQ(p.travel_torque.row(2).norm() + p.travel_hysteresis.row(2).norm(), 0.0);
  EXPECT_EQ(static_cast<const rcm::dynamics::LinearTorqueModel&>(*without.model).parameters().travel_range.size(), 0);
  const auto e = rcm::dynamics::evaluate_torque_model(*fit.model, {slow});
  const auto e_without = rcm::dynamics::evaluate_torque_model(*without.model, {slow});
  // On the fitted run's held-out slice the terms take pitch to its noise
  // (0.006 against 0.024 N m without); at half speed less of the gain carries
  // (0.019 against 0.030), as the terms share some of the torque with the
  // speed-dependent friction at the speed they are fitted at.
  const double same = fit.summary.test_errors[1].rmse, same_without = without.summary.test_errors[1].rmse;
  EXPECT_LT(same, 0.4 * same_without) << same << " vs " << same_without;
  EXPECT_LT(e[1].rmse, 0.7 * e_without[1].rmse) << e[1].rmse << " vs " << e_without[1].rmse;
  for (int j : {0, 2}) EXPECT_NEAR(e[j].rmse, e_without[j].rmse, 0.05 * e_without[j].rmse) << "joint " << j + 1;
}

TEST(TravelTerms, TravelWithTheModelFileAndAreChecked) {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  const rcm::dynamics::LinearTorqueModel model(info, make_travel_only(1, -0.7, 0.8, 9));
  const rcm::Recording run = make_run(1.0, 200.0, 10.0, 3);
  const nlohmann::json doc = rcm::dynamics::torque_model_to_json(model);
  ASSERT_TRUE(doc["parameters"].contains("travel_hysteresis"));
  const auto back = rcm::dynamics::torque_model_from_json(doc, "m.json");
  EXPECT_EQ(rcm::dynamics::torque_model_to_json(*back), doc);
  EXPECT_EQ(rcm::dynamics::predict_torque_streaming(model, run), rcm::dynamics::predict_torque_streaming(*back, run));
  auto expect_refused = [&](nlohmann::json bad, const std::string& field) {
    try {
      rcm::dynamics::torque_model_from_json(bad, "m.json");
      ADD_FAILURE() << "accepted a bad " << field;
    } catch (const rcm::InputError& e) {
      EXPECT_NE(std::string(e.what()).find("parameters." + field), std::string::npos) << e.what();
    }
  };
  for (const char* field : {"travel_range", "travel_torque", "travel_hysteresis_displacement", "travel_hysteresis"}) {
    nlohmann::json partial = doc;  // the four come together
    partial["parameters"].erase(field);
    expect_refused(partial, field);
  }
  nlohmann::json swapped = doc;  // element levels that are not H x Kh per row
  swapped["parameters"]["travel_hysteresis"] = doc["parameters"]["travel_torque"];
  expect_refused(swapped, "travel_hysteresis");
  // Built in code, the same checks.
  rcm::dynamics::LinearTorqueParameters bad = model.parameters();
  bad.travel_range(1, 1) = bad.travel_range(1, 0);
  EXPECT_THROW(rcm::dynamics::LinearTorqueModel(info, bad), std::invalid_argument);
  bad = model.parameters();
  bad.travel_hysteresis_displacement(0, 3) = 0.0;
  EXPECT_THROW(rcm::dynamics::LinearTorqueModel(info, bad), std::invalid_argument);
  bad = model.parameters();
  bad.travel_torque.resize(0, 0);
  EXPECT_THROW(rcm::dynamics::LinearTorqueModel(info, bad), std::invalid_argument);
}

}  // namespace
