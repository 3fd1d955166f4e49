// Core (LibTorch-free) tests of the torque models: metrics reference values,
// the balanced loss, the time split, the model-based fit with friction memory,
// the file format and its errors. The kernels are tested in
// test_dynamics_kernels.cpp, the networks' input features and output delay in
// test_dynamics_features.cpp.

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
#include "temp_dir.hpp"

using namespace rcm::dynamics;
using namespace rcm::test;

TEST(Metrics, ReferenceValues) {
  Eigen::MatrixXd measured(4, 2), predicted(4, 2);
  measured << 0, 10, 1, 10, 2, 10, 3, 12;
  predicted << 0, 10, 1, 10, 2, 10, 4, 10;
  const auto e = compute_torque_errors(measured, predicted);
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].index, 1);
  EXPECT_DOUBLE_EQ(e[0].rmse, 0.5);
  EXPECT_DOUBLE_EQ(e[0].range, 3.0);
  EXPECT_NEAR(e[0].nrmse_percent, 100.0 / 6.0, 1e-12);
  EXPECT_DOUBLE_EQ(e[1].rmse, 1.0);
  EXPECT_NEAR(e[1].nrmse_percent, 50.0, 1e-12);
  const auto j = to_json(e);
  EXPECT_EQ(j["joints"][1]["index"], 2);
  EXPECT_THROW(compute_torque_errors(measured, predicted.topRows(3)), std::invalid_argument);
}

TEST(Metrics, HuberScaleIsTheSpreadOfTheBulk) {
  // Normal errors: the standard deviation. With 1 % of the samples spikes of
  // 20 standard deviations, the RMSE more than doubles; the scale moves by
  // about their share. A bias counts: the scale is about zero.
  std::mt19937 rng(3);
  std::normal_distribution<double> normal(0.0, 0.05);
  Eigen::VectorXd e(20000);
  for (Eigen::Index i = 0; i < e.size(); ++i) e[i] = normal(rng);
  const double sd = std::sqrt(e.squaredNorm() / static_cast<double>(e.size()));
  EXPECT_NEAR(compute_huber_scale(e), sd, 0.01 * sd);
  Eigen::VectorXd spiky = e;
  for (Eigen::Index i = 0; i < spiky.size(); i += 100) spiky[i] = (i % 200 == 0 ? 1.0 : -1.0);
  const double rms = std::sqrt(spiky.squaredNorm() / static_cast<double>(spiky.size()));
  EXPECT_GT(rms, 2.0 * sd);
  EXPECT_NEAR(compute_huber_scale(spiky), sd, 0.05 * sd);
  EXPECT_NEAR(compute_huber_scale(Eigen::VectorXd::Constant(10, 0.1)), 0.1, 0.005);
  EXPECT_EQ(compute_huber_scale(Eigen::VectorXd::Zero(10)), 0.0);
  EXPECT_THROW(compute_huber_scale(Eigen::VectorXd()), std::invalid_argument);
  // compute_torque_errors gives it per joint; the streaming accumulator cannot.
  Eigen::MatrixXd measured(e.size(), 2), predicted = Eigen::MatrixXd::Zero(e.size(), 2);
  measured << e, spiky;
  const auto errors = compute_torque_errors(measured, predicted);
  EXPECT_NEAR(errors[1].robust_sd, compute_huber_scale(spiky), 1e-12);
  EXPECT_NEAR(errors[1].rmse, rms, 1e-12);
  TorqueErrorAccumulator accumulator(2);
  accumulator.add(measured, predicted);
  EXPECT_TRUE(std::isnan(accumulator.get_errors()[0].robust_sd));
}

TEST(LossBalance, PowerMeanReferenceValues) {
  Eigen::ArrayXd mse(3);
  mse << 4.0, 1.0, 0.25;
  EXPECT_NEAR(compute_balanced_loss(mse, 0.0), 5.25 / 3.0, 1e-15);  // the mean
  EXPECT_NEAR(compute_balanced_loss(mse, 1.0), 1.0, 1e-15);         // the geometric mean
  EXPECT_NEAR(compute_balanced_loss(mse, 0.5), std::pow(3.5 / 3.0, 2), 1e-15);
  // Scaling every joint's error scales the score alike, whatever p.
  for (const double p : {0.0, 0.3, 0.5, 1.0})
    EXPECT_NEAR(compute_balanced_loss(9.0 * mse, p), 9.0 * compute_balanced_loss(mse, p), 1e-12);
  // A joint predicted exactly leaves a finite, positive geometric mean.
  mse(1) = 0.0;
  EXPECT_GT(compute_balanced_loss(mse, 1.0), 0.0);
  EXPECT_THROW(compute_balanced_loss(Eigen::ArrayXd(0), 0.5), std::invalid_argument);
}

// What makes the running-mean training loss the right one for this score: the
// score's sensitivity to joint j is proportional to mse_j^-p (central
// differences against that claim).
TEST(LossBalance, ScoreGradientWeighsJointsByTheirMseToThePowerMinusP) {
  Eigen::ArrayXd mse(3);
  mse << 0.07, 7e-4, 6e-4;
  for (const double p : {0.0, 0.5, 1.0}) {
    Eigen::ArrayXd grad(3);
    for (int j = 0; j < 3; ++j) {
      const double h = 1e-6 * mse(j);
      Eigen::ArrayXd up = mse, down = mse;
      up(j) += h;
      down(j) -= h;
      grad(j) = (compute_balanced_loss(up, p) - compute_balanced_loss(down, p)) / (2 * h);
    }
    for (int j = 1; j < 3; ++j)
      EXPECT_NEAR(grad(j) / grad(0), std::pow(mse(j) / mse(0), -p), 1e-6 * std::pow(mse(j) / mse(0), -p))
          << "p " << p << ", joint " << j + 1;
  }
}

TEST(Split, TimeOrderedWithoutOverlap) {
  std::vector<rcm::Recording> recs(2);
  recs[0].time = Eigen::VectorXd::LinSpaced(100, 0, 99);
  recs[1].time = Eigen::VectorXd::LinSpaced(50, 0, 49);
  const auto s = split_in_time(recs, 0.7, 0.2);
  ASSERT_EQ(s.train.size(), 2u);
  EXPECT_EQ(s.train[0].recording, 0);
  EXPECT_EQ(s.train[0].size(), 100);
  EXPECT_EQ(s.train[1].recording, 1);
  EXPECT_EQ(s.train[1].end, 5);
  ASSERT_EQ(s.validation.size(), 1u);
  EXPECT_EQ(s.validation[0].begin, 5);
  EXPECT_EQ(s.validation[0].end, 35);
  ASSERT_EQ(s.test.size(), 1u);
  EXPECT_EQ(s.test[0].begin, 35);
  EXPECT_EQ(s.test[0].end, 50);
}

TEST(GravityRegressor, IsTheGradientOfThePotentialBasis) {
  // Finite differences of U_k = a(q1) b(q2) c(q3) against the analytic rows.
  auto basis = [](const double* q, int k) {
    const double a[3] = {1, std::sin(q[0]), std::cos(q[0])}, b[3] = {1, std::sin(q[1]), std::cos(q[1])};
    const double c[2] = {1, q[2]};
    int i = 0;
    for (int al = 0; al < 3; ++al)
      for (int be = 0; be < 3; ++be)
        for (int ga = 0; ga < 2; ++ga) {
          if (al == 0 && be == 0 && ga == 0) continue;
          if (i++ == k) return a[al] * b[be] * c[ga];
        }
    return 0.0;
  };
  double q[3] = {0.3, -0.4, 0.12};
  Eigen::Matrix<double, 3, LinearTorqueModel::kGravityTerms> Y;
  LinearTorqueModel::compute_gravity_regressor(q, Y);
  const double h = 1e-6;
  for (int k = 0; k < LinearTorqueModel::kGravityTerms; ++k)
    for (int j = 0; j < 3; ++j) {
      double qp[3] = {q[0], q[1], q[2]}, qm[3] = {q[0], q[1], q[2]};
      qp[j] += h;
      qm[j] -= h;
      EXPECT_NEAR(Y(j, k), (basis(qp, k) - basis(qm, k)) / (2 * h), 1e-8) << "term " << k << " joint " << j;
    }
}

namespace {
FitOptions quiet() {
  FitOptions o;
  o.verbose = false;
  return o;
}
}  // namespace

TEST(LinearModel, FitsSyntheticArmAndRemembersApproachDirection) {
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 120;
  const auto rec = rcm::test::make_synthetic_free_space(so);
  const auto fit = fit_linear_torque_model({rec}, quiet());
  ASSERT_TRUE(fit.model);
  ASSERT_EQ(fit.summary.test_errors.size(), 3u);
  for (const auto& e : fit.summary.test_errors) EXPECT_LT(e.nrmse_percent, 6.0) << "joint " << e.index;
  const auto& p = static_cast<const LinearTorqueModel&>(*fit.model).parameters();
  EXPECT_GT(p.coulomb[0], 0.02);  // true Coulomb level 0.05 N m

  // Approach q1 = 0.1 from below and from above, then hold: the holding torque
  // must differ by about twice the friction level, higher after moving up.
  auto hold_torque = [&](double from) {
    const int T = 400;
    Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(T, 0, (T - 1) / 200.0);
    Eigen::MatrixXd q(T, 3), qd = Eigen::MatrixXd::Zero(T, 3);
    for (int i = 0; i < T; ++i) {
      const double s = std::min(1.0, i / 200.0);
      q(i, 0) = from + (0.1 - from) * s;
      qd(i, 0) = i < 200 ? (0.1 - from) : 0.0;
      q(i, 1) = 0.0;
      q(i, 2) = 0.13;
    }
    return predict_torque(*fit.model, t, q, qd)(T - 1, 0);
  };
  const double up = hold_torque(-0.2), down = hold_torque(0.4);
  EXPECT_GT(up - down, 0.05);
}

TEST(ModelFile, LinearRoundTripIsExact) {
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 30;
  const auto rec = rcm::test::make_synthetic_free_space(so);
  const auto fit = fit_linear_torque_model({rec}, quiet());
  const auto path = rcm::test::get_process_temp_dir() / "rcm_test_linear_model.json";
  save_torque_model(path, *fit.model);
  const auto loaded = load_torque_model(path);
  EXPECT_EQ(torque_model_to_json(*loaded), torque_model_to_json(*fit.model));
  const Eigen::MatrixXd a = predict_torque(*fit.model, rec), b = predict_torque(*loaded, rec);
  EXPECT_EQ((a - b).cwiseAbs().maxCoeff(), 0.0);
  std::filesystem::remove(path);
}

TEST(ModelFile, NetworkRoundTripIsExactForEveryKind) {
  const TorqueModelInfo info = info3();
  const Normalization norm = norm3(Eigen::VectorXf::Constant(6, 0.7f));
  std::vector<std::unique_ptr<TorqueModel>> models;
  models.push_back(std::make_unique<LstmTorqueModel>(info, random_lstm(6, 8, 2, 4, 3, 1), norm));
  std::vector<DenseStack> stacks;
  std::mt19937 rng(9);
  for (int j = 0; j < 3; ++j) {
    DenseStack s;
    s.layers.push_back({random_matrix(10, 6, rng), random_matrix(10, 1, rng).col(0), Activation::tanh});
    s.layers.push_back({random_matrix(1, 10, rng), random_matrix(1, 1, rng).col(0), Activation::identity});
    stacks.push_back(s);
  }
  models.push_back(std::make_unique<MlpTorqueModel>(info, stacks, norm));
  LinearTorqueParameters lp{Eigen::VectorXd::LinSpaced(17, -1, 1), Eigen::VectorXd::Constant(3, 0.01),
                            Eigen::VectorXd::Constant(3, 0.02), Eigen::VectorXd::Constant(3, 0.05),
                            Eigen::VectorXd::Constant(3, 0.1), Eigen::VectorXd::Constant(3, 1e-3)};
  auto base = std::make_shared<const LinearTorqueModel>(info, lp);
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, random_lstm(6, 8, 1, 4, 3, 2), norm));
  Normalization with_direction = norm;
  with_direction.velocity_tanh_scale = Eigen::VectorXf::LinSpaced(6, 0.003f, 0.03f);
  models.push_back(std::make_unique<LstmTorqueModel>(info, random_lstm(12, 8, 1, 4, 3, 3), with_direction));
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, random_lstm(12, 8, 1, 4, 3, 4), with_direction));
  Normalization with_acceleration = with_direction;
  with_acceleration.acceleration_filter_s = Eigen::Vector2f(0.01f, 0.05f);
  with_acceleration.acceleration_scale = Eigen::VectorXf::LinSpaced(6, 0.5f, 3.0f);
  models.push_back(std::make_unique<LstmTorqueModel>(info, random_lstm(18, 8, 1, 4, 3, 5), with_acceleration));
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, random_lstm(18, 8, 1, 4, 3, 6), with_acceleration));
  Normalization with_dahl = with_acceleration;
  with_dahl.dahl_displacement = Eigen::VectorXf::LinSpaced(6, 1e-4f, 3e-3f);
  models.push_back(std::make_unique<LstmTorqueModel>(info, random_lstm(24, 8, 1, 4, 3, 7), with_dahl));
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, random_lstm(24, 8, 1, 4, 3, 8), with_dahl));
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 5;
  const auto rec = rcm::test::make_synthetic_free_space(so);
  for (const auto& m : models) {
    const auto doc = torque_model_to_json(*m);
    const auto back = torque_model_from_json(nlohmann::json::parse(doc.dump()), "memory");
    EXPECT_EQ(back->kind(), m->kind());
    EXPECT_EQ(torque_model_to_json(*back), doc);
    EXPECT_EQ((predict_torque(*m, rec) - predict_torque(*back, rec)).cwiseAbs().maxCoeff(), 0.0)
        << to_string(m->kind());
    // Streaming by hand equals predict, and reset_state restarts the history.
    auto ws = m->create_workspace();
    const Eigen::MatrixXd p = predict_torque(*m, rec);
    for (int pass = 0; pass < 2; ++pass) {
      m->reset_state(*ws);
      for (Eigen::Index t = 0; t < 200; ++t) {
        Eigen::VectorXd q = rec.position.row(t).transpose(), qd = rec.velocity.row(t).transpose(), tau(3);
        m->compute_step(*ws, rec.time(t), q.data(), qd.data(), tau.data());
        ASSERT_EQ((tau.transpose() - p.row(t)).cwiseAbs().maxCoeff(), 0.0);
      }
    }
  }
}

TEST(ModelFile, BadFilesAreLocatedInputErrors) {
  const auto dir = std::filesystem::temp_directory_path();
  const auto garbage = dir / "rcm_test_garbage_model.json";
  std::ofstream(garbage) << "{\"format\": \"rcm-torque-model/1\", \"kind\": \"lstm\", \"num_joints\": 3,"
                            " \"num_outputs\": 3, \"sample_period_s\": 0.005, \"parameters\": {\"lstm\": {}}}";
  try {
    load_torque_model(garbage);
    FAIL() << "expected InputError";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("parameters.lstm.layers"), std::string::npos) << e.what();
  }
  std::ofstream(garbage) << "{\"format\": \"something-else\"}";
  EXPECT_THROW(load_torque_model(garbage), rcm::InputError);
  std::ofstream(garbage) << "{\"format\": \"rcm-torque-model/1\", \"kind\": \"svm\"}";
  EXPECT_THROW(load_torque_model(garbage), rcm::InputError);
  std::filesystem::remove(garbage);
  EXPECT_THROW(parse_torque_model_kind("svm"), rcm::InputError);
}
