// One battery for every torque-model kind (fit, predict, stream, save/load,
// metrics), and what the LibTorch fits take from FitOptions: input features,
// loss balance, output delay, warnings; the BLAS LibTorch binds to. The
// cross-checks against LibTorch and TorchScript are in test_torch_interop.cpp.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <tuple>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/training.hpp"
#include "test_dynamics_synthetic.hpp"

using namespace rcm::dynamics;

namespace {

FitOptions tiny_options() {
  FitOptions o;
  o.verbose = false;
  // Tiny networks: a second intra-op thread only adds synchronization.
  o.threads = 1;
  o.hidden_size = 12;
  o.num_layers = 1;
  o.head_hidden = 8;
  o.window = 25;
  o.streams = 4;
  o.burn_in = 50;
  o.mlp_hidden = 16;
  o.max_epochs = 12;
  o.learning_rate = 1e-2;
  return o;
}

const rcm::Recording& synthetic_minute() {
  static const rcm::Recording rec = [] {
    rcm::test::SyntheticArmOptions so;
    so.duration_s = 60;
    return rcm::test::make_synthetic_free_space(so);
  }();
  return rec;
}

class EveryModelKind : public ::testing::TestWithParam<TorqueModelKind> {};

}  // namespace

TEST_P(EveryModelKind, FitPredictStreamSaveLoadAndMetrics) {
  const auto& rec = synthetic_minute();
  const FitResult fit = fit_torque_model(GetParam(), {rec}, tiny_options());
  ASSERT_TRUE(fit.model);
  const auto& model = *fit.model;
  EXPECT_EQ(model.kind(), GetParam());
  EXPECT_EQ(model.num_joints(), 3);
  EXPECT_EQ(model.num_outputs(), 3);
  EXPECT_NEAR(model.info().sample_period_s, 0.005, 1e-12);
  if (GetParam() == TorqueModelKind::lstm)  // [q, qdot], three direction, one acceleration, three Dahl per joint
    EXPECT_EQ(static_cast<const LstmTorqueModel&>(model).network().input_size(), 27);
  // The default output delay: 40 ms for the lstm, the half zero-phase window
  // and half a 100 Hz period for the linear model (its zero-phase qddot live),
  // none for the others.
  const int d = model.output_delay();
  if (GetParam() == TorqueModelKind::linear) {
    const double half = 0.5 * static_cast<const LinearTorqueModel&>(model).parameters().batch_acceleration_window_s.maxCoeff();
    EXPECT_EQ(d, static_cast<int>(std::ceil((half + 0.005) / 0.005 - 1e-9)));
  } else {
    EXPECT_EQ(d, GetParam() == TorqueModelKind::lstm ? 8 : 0);
  }
  EXPECT_EQ(fit.summary.to_json().value("output_delay_samples", 0), d);
  if (GetParam() == TorqueModelKind::mlp)
    EXPECT_EQ(static_cast<const MlpTorqueModel&>(model).networks().front().input_size(), 6);
  if (GetParam() == TorqueModelKind::hybrid)  // none by default (get_default_*)
    EXPECT_EQ(static_cast<const HybridTorqueModel&>(model).residual_network().input_size(), 6);

  // Predict over the whole recording, and the test split scored as in the summary.
  const Eigen::MatrixXd p = predict_torque(model, rec);
  ASSERT_EQ(p.rows(), rec.time.size());
  ASSERT_TRUE(p.allFinite());
  ASSERT_EQ(fit.summary.test_errors.size(), 3u);
  const auto split = split_in_time({rec}, 0.7, 0.2);
  const auto again = evaluate_on_segments(model, {rec}, split.test);
  // The model learned something: on the fitted part (train + validation) it
  // beats predicting the mean by far. (Generalization from one synthetic minute
  // is not asserted here; docs/validation-free-space.md measures it.)
  const Eigen::Index fitted = split.validation.back().end;
  const Eigen::MatrixXd measured = rec.effort.topRows(fitted);
  const Eigen::RowVectorXd mean = measured.colwise().mean();
  const auto baseline = compute_torque_errors(measured, mean.replicate(fitted, 1));
  const auto in_sample = compute_torque_errors(measured, p.topRows(fitted));
  for (int j = 0; j < 3; ++j) {
    EXPECT_DOUBLE_EQ(again[j].rmse, fit.summary.test_errors[j].rmse);
    EXPECT_LT(in_sample[j].rmse, 0.75 * baseline[j].rmse) << to_string(GetParam()) << " joint " << j + 1;
  }

  // Streaming one sample at a time equals the causal whole-recording run (call
  // t + d giving row t), also after a reset; predict_torque equals it too unless
  // the model's batch path looks ahead (the linear model's zero-phase qddot,
  // inherited by the hybrid), and then stays close to it.
  const Eigen::MatrixXd p_stream = predict_torque_streaming(model, rec.time, rec.position, rec.velocity);
  const bool looks_ahead = GetParam() == TorqueModelKind::linear || GetParam() == TorqueModelKind::hybrid;
  if (!looks_ahead) {
    EXPECT_EQ((p_stream - p).cwiseAbs().maxCoeff(), 0.0);
  } else {
    const auto stream_errors = compute_torque_errors(measured, p_stream.topRows(fitted));
    for (int j = 0; j < 3; ++j) EXPECT_LT(stream_errors[j].rmse, 0.75 * baseline[j].rmse) << "streaming, joint " << j + 1;
  }
  auto ws = model.create_workspace();
  for (int pass = 0; pass < 2; ++pass) {
    model.reset_state(*ws);
    for (Eigen::Index t = 0; t < 300; ++t) {
      Eigen::VectorXd q = rec.position.row(t).transpose(), qd = rec.velocity.row(t).transpose(), tau(3);
      model.compute_step(*ws, rec.time(t), q.data(), qd.data(), tau.data());
      if (t >= d) ASSERT_EQ((tau.transpose() - p_stream.row(t - d)).cwiseAbs().maxCoeff(), 0.0);
    }
  }

  // Save and load: same document, bit-identical predictions.
  const auto path = std::filesystem::temp_directory_path() / ("rcm_test_model_" + to_string(GetParam()) + ".json");
  save_torque_model(path, model);
  const auto loaded = load_torque_model(path);
  EXPECT_EQ(torque_model_to_json(*loaded), torque_model_to_json(model));
  EXPECT_EQ((predict_torque(*loaded, rec) - p).cwiseAbs().maxCoeff(), 0.0);
  std::filesystem::remove(path);
  EXPECT_FALSE(fit.summary.brief_report().empty());
}

INSTANTIATE_TEST_SUITE_P(Kinds, EveryModelKind,
                         ::testing::Values(TorqueModelKind::lstm, TorqueModelKind::mlp, TorqueModelKind::linear,
                                           TorqueModelKind::hybrid),
                         [](const auto& info) { return to_string(info.param); });

TEST(DirectionFeatures, ExplicitScalesReachLstmAndHybridNotMlp) {
  auto o = tiny_options();
  o.max_epochs = 1;
  o.velocity_tanh_scales = std::vector<double>{0.05, 0.2};
  const auto& rec = synthetic_minute();
  o.acceleration_filters_s = std::vector<double>{};
  o.dahl_fractions = std::vector<double>{};
  const auto lstm = fit_lstm_torque_model({rec}, o);
  const auto& lm = static_cast<const LstmTorqueModel&>(*lstm.model);
  EXPECT_EQ(lm.network().input_size(), 12);
  ASSERT_EQ(lm.normalization().velocity_tanh_scale.size(), 6);
  // s x the training split's velocity sd, feature-major.
  const Eigen::Index train_end = split_in_time({rec}, 0.7, 0.2).train.back().end;
  for (int k = 0; k < 3; ++k) {
    const Eigen::ArrayXd v = rec.velocity.col(k).head(train_end).array();
    const double sd = std::sqrt((v - v.mean()).square().mean());
    EXPECT_NEAR(lm.normalization().velocity_tanh_scale[k], 0.05 * sd, 1e-6 * sd);
    EXPECT_NEAR(lm.normalization().velocity_tanh_scale[3 + k], 0.2 * sd, 1e-6 * sd);
  }
  const auto hybrid = fit_hybrid_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const HybridTorqueModel&>(*hybrid.model).residual_network().input_size(), 12);
  const auto mlp = fit_mlp_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const MlpTorqueModel&>(*mlp.model).networks().front().input_size(), 6);
  o.velocity_tanh_scales = std::vector<double>{};  // explicitly none
  const auto plain = fit_lstm_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const LstmTorqueModel&>(*plain.model).network().input_size(), 6);
  o.velocity_tanh_scales = std::vector<double>{0.1, -1.0};
  EXPECT_THROW(fit_lstm_torque_model({rec}, o), rcm::InputError);
}

TEST(AccelerationFeatures, ExplicitFiltersReachLstmAndHybridNotMlp) {
  auto o = tiny_options();
  o.max_epochs = 1;
  o.velocity_tanh_scales = std::vector<double>{};
  o.dahl_fractions = std::vector<double>{};
  const auto& rec = synthetic_minute();
  // Default for lstm: one filter of 0.03 s, scaled by the root mean square of
  // the filtered signal over the training split.
  const auto lstm = fit_lstm_torque_model({rec}, o);
  const auto& lm = static_cast<const LstmTorqueModel&>(*lstm.model);
  EXPECT_EQ(lm.network().input_size(), 9);
  ASSERT_EQ(lm.normalization().acceleration_filter_s.size(), 1);
  EXPECT_FLOAT_EQ(lm.normalization().acceleration_filter_s[0], 0.03f);
  const Eigen::Index train_end = split_in_time({rec}, 0.7, 0.2).train.back().end;
  const Eigen::MatrixXd a = compute_acceleration_features(lm.normalization().acceleration_filter_s, rec.time,
                                                          rec.velocity, 3);
  ASSERT_EQ(lm.normalization().acceleration_scale.size(), 3);
  for (int k = 0; k < 3; ++k) {
    const double rms = std::sqrt(a.col(k).head(train_end).squaredNorm() / static_cast<double>(train_end));
    EXPECT_GT(rms, 0.0);
    EXPECT_NEAR(lm.normalization().acceleration_scale[k], rms, 1e-5 * rms);
  }
  o.acceleration_filters_s = std::vector<double>{0.01, 0.1};
  const auto two = fit_lstm_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const LstmTorqueModel&>(*two.model).network().input_size(), 12);
  const auto hybrid = fit_hybrid_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const HybridTorqueModel&>(*hybrid.model).residual_network().input_size(), 12);
  const auto mlp = fit_mlp_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const MlpTorqueModel&>(*mlp.model).networks().front().input_size(), 6);
  o.acceleration_filters_s = std::vector<double>{0.0};
  EXPECT_THROW(fit_lstm_torque_model({rec}, o), rcm::InputError);
}

TEST(DahlFeatures, FractionsOfTheRangeReachLstmAndHybridNotMlp) {
  auto o = tiny_options();
  o.max_epochs = 1;
  o.velocity_tanh_scales = std::vector<double>{};
  o.acceleration_filters_s = std::vector<double>{};
  const auto& rec = synthetic_minute();
  // Default for lstm: three states per joint, x_c = {3e-5, 3e-4, 3e-3} x the
  // joint's range of motion over the training split.
  const auto lstm = fit_lstm_torque_model({rec}, o);
  const auto& lm = static_cast<const LstmTorqueModel&>(*lstm.model);
  EXPECT_EQ(lm.network().input_size(), 15);
  ASSERT_EQ(lm.normalization().dahl_displacement.size(), 9);
  const Eigen::Index train_end = split_in_time({rec}, 0.7, 0.2).train.back().end;
  const double fractions[3] = {3e-5, 3e-4, 3e-3};
  for (int k = 0; k < 3; ++k) {
    const Eigen::VectorXd q = rec.position.col(k).head(train_end);
    const double range = q.maxCoeff() - q.minCoeff();
    ASSERT_GT(range, 0.0);
    for (int f = 0; f < 3; ++f)
      EXPECT_NEAR(lm.normalization().dahl_displacement[3 * f + k], fractions[f] * range, 1e-6 * fractions[f] * range);
  }
  o.dahl_fractions = std::vector<double>{1e-3};
  const auto one = fit_lstm_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const LstmTorqueModel&>(*one.model).network().input_size(), 9);
  const auto hybrid = fit_hybrid_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const HybridTorqueModel&>(*hybrid.model).residual_network().input_size(), 9);
  o.dahl_fractions.reset();  // hybrid's default: none
  EXPECT_EQ(static_cast<const HybridTorqueModel&>(*fit_hybrid_torque_model({rec}, o).model)
                .residual_network()
                .input_size(),
            6);
  o.dahl_fractions = std::vector<double>{1e-3};
  const auto mlp = fit_mlp_torque_model({rec}, o);
  EXPECT_EQ(static_cast<const MlpTorqueModel&>(*mlp.model).networks().front().input_size(), 6);
  o.dahl_fractions = std::vector<double>{-1e-3};
  EXPECT_THROW(fit_lstm_torque_model({rec}, o), rcm::InputError);
}

TEST(LossBalance, DefaultsAndRange) {
  auto o = tiny_options();
  o.max_epochs = 1;
  const auto& rec = synthetic_minute();
  const auto lstm = fit_lstm_torque_model({rec}, o);
  EXPECT_EQ(lstm.summary.loss_balance, 0.5);
  EXPECT_EQ(lstm.summary.to_json()["loss_balance"], 0.5);
  EXPECT_EQ(lstm.model->info().training["loss_balance"], 0.5);
  EXPECT_EQ(fit_hybrid_torque_model({rec}, o).summary.loss_balance, 0.0);
  o.loss_balance = 1.0;
  EXPECT_EQ(fit_hybrid_torque_model({rec}, o).summary.loss_balance, 1.0);
  for (const double bad : {-0.1, 1.5, std::nan("")}) {
    o.loss_balance = bad;
    EXPECT_THROW(fit_lstm_torque_model({rec}, o), rcm::InputError) << bad;
  }
}

// The score early stopping keeps is compute_balanced_loss of the per-joint
// normalized MSE over the validation pieces (2000 samples after burn_in samples
// of context, the state fresh), recomputed here with the Eigen kernel.
TEST(LossBalance, ValidationScoreIsTheBalancedLossOfTheValidationPieces) {
  const auto& rec = synthetic_minute();
  auto o = tiny_options();
  o.max_epochs = 3;
  // Memoryless features, so that a piece cut out of the recording sees the same
  // inputs; no output delay, so that its last samples need nothing after it.
  o.acceleration_filters_s = std::vector<double>{};
  o.dahl_fractions = std::vector<double>{};
  o.output_delay_s = 0.0;
  const auto split = split_in_time({rec}, o.train_fraction, o.validation_fraction);
  ASSERT_EQ(split.validation.size(), 1u);
  const Eigen::Index b = split.validation[0].begin, piece = 2000, context = o.burn_in;
  ASSERT_LT(b + piece, split.validation[0].end);
  ASSERT_GE(b + 2 * piece, split.validation[0].end);  // exactly one piece
  for (const double p : {0.0, 1.0}) {
    o.loss_balance = p;
    const auto fit = fit_lstm_torque_model({rec}, o);
    const auto& norm = static_cast<const LstmTorqueModel&>(*fit.model).normalization();
    const Eigen::MatrixXd pred =
        predict_torque(*fit.model, rec.time.segment(b - context, piece + context),
                       rec.position.middleRows(b - context, piece + context),
                       rec.velocity.middleRows(b - context, piece + context))
            .bottomRows(piece);
    Eigen::ArrayXd mse(3);
    for (int j = 0; j < 3; ++j)
      mse(j) = ((pred.col(j) - rec.effort.col(j).segment(b, piece)).array() / norm.output_scale(j)).square().mean();
    EXPECT_NEAR(fit.summary.best_validation_loss, compute_balanced_loss(mse, p),
                1e-4 * fit.summary.best_validation_loss)
        << "p " << p;
    EXPECT_GT(std::abs(compute_balanced_loss(mse, 1.0 - p) / compute_balanced_loss(mse, p) - 1.0), 1e-3);
  }
}

TEST(OutputDelay, TheDelayedLstmLearnsTheTorqueOfTheSampleDBefore) {
  // effort(t) = qdot(t + d) with white qdot: no causal model can predict it, and
  // a network whose output at t + d is trained on the torque of t reads it from
  // its input. A delay applied the wrong way round (or not at all) fails both.
  const int d = 4;
  const Eigen::Index T = 4000;
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  rcm::Recording rec;
  rec.source = "future velocity";
  rec.time = Eigen::VectorXd::LinSpaced(T, 0.0, 0.005 * static_cast<double>(T - 1));
  rec.velocity.resize(T, 3);
  for (Eigen::Index i = 0; i < rec.velocity.size(); ++i) rec.velocity.data()[i] = g(rng);
  rec.position.resize(T, 3);
  rec.position.row(0).setZero();
  for (Eigen::Index t = 1; t < T; ++t) rec.position.row(t) = rec.position.row(t - 1) + 0.005 * rec.velocity.row(t);
  rec.effort = Eigen::MatrixXd::Zero(T, 3);
  rec.effort.topRows(T - d) = rec.velocity.bottomRows(T - d);
  auto o = tiny_options();
  o.velocity_tanh_scales = std::vector<double>{};
  o.acceleration_filters_s = std::vector<double>{};
  o.dahl_fractions = std::vector<double>{};
  o.output_delay_s = d * 0.005;
  const FitResult delayed = fit_torque_model(TorqueModelKind::lstm, {rec}, o);
  ASSERT_EQ(delayed.model->output_delay(), d);
  o.output_delay_s = 0.0;
  const FitResult causal = fit_torque_model(TorqueModelKind::lstm, {rec}, o);
  ASSERT_EQ(causal.model->output_delay(), 0);
  // Scored on the fitted part, past the burn-in, before the zero tail.
  const Eigen::Index b = o.burn_in, n = split_in_time({rec}, 0.7, 0.2).validation.back().end - b;
  const Eigen::MatrixXd measured = rec.effort.middleRows(b, n);
  const auto e_delayed = compute_torque_errors(measured, predict_torque(*delayed.model, rec).middleRows(b, n));
  const auto e_causal = compute_torque_errors(measured, predict_torque(*causal.model, rec).middleRows(b, n));
  for (int j = 0; j < 3; ++j) {
    EXPECT_LT(e_delayed[j].rmse, 0.4) << "joint " << j + 1;  // qdot has sd 1
    EXPECT_GT(e_causal[j].rmse, 0.8) << "joint " << j + 1;
  }
}

TEST(FitWarnings, ShortDataSaysTooFewToTrust) {
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 40;
  const auto rec = rcm::test::make_synthetic_free_space(so);
  auto o = tiny_options();
  o.max_epochs = 2;
  const auto fit = fit_lstm_torque_model({rec}, o);
  bool found = false;
  for (const auto& w : fit.summary.warnings) found |= w.find("too few to trust") != std::string::npos;
  EXPECT_TRUE(found);
}

// Training speed rests on which BLAS LibTorch's sgemm_ binds to in a program
// that links Ceres, SuiteSparse and LibTorch together (as rcm::torch's users
// do): OpenBLAS, not ATLAS's or the reference single-threaded one
// (cmake/rcm_blas.cmake). The rcm program, which opens LibTorch after Ceres's
// BLAS is loaded, is checked by DynamicsCli.TrainsANetworkThroughTheTrainingModuleOnly.
TEST(LibTorchBlas, IsOpenBlasInAProgramLinkingCeresAndLibTorch) {
  const std::string blas = get_libtorch_blas_library();
  ASSERT_FALSE(blas.empty());
  EXPECT_NE(blas.find("openblas"), std::string::npos) << blas;
}
