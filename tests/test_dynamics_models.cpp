// Core (LibTorch-free) tests of the torque models: kernels against a plain
// double reference, metrics reference values, the time split, the model-based
// fit with friction memory, the file format and its errors.

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
#include "test_dynamics_synthetic.hpp"

using namespace rcm::dynamics;

namespace {

Eigen::MatrixXf random_matrix(int r, int c, std::mt19937& rng, float scale = 0.3f) {
  std::normal_distribution<float> g(0.0f, scale);
  Eigen::MatrixXf m(r, c);
  for (int i = 0; i < r; ++i)
    for (int j = 0; j < c; ++j) m(i, j) = g(rng);
  return m;
}

LstmNetwork random_lstm(int in, int H, int L, int head, int out, unsigned seed) {
  return make_random_lstm_network(in, H, L, head, out, seed);
}

// Three joints, three outputs at 200 Hz, and a normalization with these input scales.
TorqueModelInfo info3() {
  TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  return info;
}
Normalization norm3(const Eigen::VectorXf& input_scale) {
  Normalization norm;
  norm.input_mean = Eigen::VectorXf::LinSpaced(6, -0.1f, 0.2f);
  norm.input_scale = input_scale;
  norm.output_mean = Eigen::VectorXf::Constant(3, 0.01f);
  norm.output_scale = Eigen::VectorXf::Constant(3, 0.3f);
  return norm;
}

// Plain double LSTM step written from the equations of torch.nn.LSTM.
struct ReferenceLstm {
  const LstmNetwork& n;
  std::vector<Eigen::VectorXd> h, c;
  explicit ReferenceLstm(const LstmNetwork& net) : n(net) {
    for (std::size_t k = 0; k < n.layers.size(); ++k) {
      h.push_back(Eigen::VectorXd::Zero(n.hidden_size()));
      c.push_back(Eigen::VectorXd::Zero(n.hidden_size()));
    }
  }
  Eigen::VectorXd step(const Eigen::VectorXd& x) {
    auto sig = [](double v) { return 1.0 / (1.0 + std::exp(-v)); };
    Eigen::VectorXd in = x;
    const int H = n.hidden_size();
    for (std::size_t k = 0; k < n.layers.size(); ++k) {
      const auto& l = n.layers[k];
      Eigen::VectorXd g = l.weight_ih.cast<double>() * in + l.weight_hh.cast<double>() * h[k] +
                          l.bias_ih.cast<double>() + l.bias_hh.cast<double>();
      for (int i = 0; i < H; ++i) {
        const double ig = sig(g(i)), fg = sig(g(H + i)), gg = std::tanh(g(2 * H + i)), og = sig(g(3 * H + i));
        c[k](i) = fg * c[k](i) + ig * gg;
        h[k](i) = og * std::tanh(c[k](i));
      }
      in = h[k];
    }
    for (const auto& l : n.head.layers) {
      in = l.weight.cast<double>() * in + l.bias.cast<double>();
      if (l.activation == Activation::tanh) in = in.array().tanh();
      if (l.activation == Activation::relu) in = in.cwiseMax(0.0);
    }
    return in;
  }
};

}  // namespace

std::vector<KernelIsa> available_isas() {
  std::vector<KernelIsa> isas{KernelIsa::portable};
  if (kernel_isa_available(KernelIsa::avx2_fma)) isas.push_back(KernelIsa::avx2_fma);
  return isas;
}

TEST(LstmKernel, MatchesDoubleReferenceOverManySteps) {
  // H = 24 pads to two 16-unit panels; head rows 16 and 3 pad to 8-row blocks.
  for (const KernelIsa isa : available_isas())
    for (int layers : {1, 2}) {
      const auto net = random_lstm(6, 24, layers, 16, 3, 11 + layers);
      LstmKernel kernel(net, isa);
      EXPECT_EQ(kernel.isa(), isa);
      auto state = kernel.create_state();
      ReferenceLstm ref(net);
      std::mt19937 rng(5);
      std::normal_distribution<double> g(0.0, 1.5);
      double worst = 0.0;
      for (int t = 0; t < 300; ++t) {
        Eigen::VectorXd x(6);
        for (int i = 0; i < 6; ++i) x(i) = g(rng);
        const Eigen::VectorXf xf = x.cast<float>();
        Eigen::VectorXf y(3);
        kernel.step(state, xf.data(), y.data());
        const Eigen::VectorXd yr = ref.step(xf.cast<double>());
        worst = std::max(worst, (y.cast<double>() - yr).cwiseAbs().maxCoeff());
      }
      EXPECT_LT(worst, 1e-5) << layers << " layers, " << to_string(isa);
    }
}

// The AVX2/FMA kernels (chosen at run time) and the portable ones compute the
// same steps: the default 1 x 128 architecture, two layers, and sizes that are
// not multiples of the panel blocks (H = 20, head 10 -> 7 outputs).
TEST(LstmKernel, Avx2AndPortableKernelsAgree) {
  if (!kernel_isa_available(KernelIsa::avx2_fma)) GTEST_SKIP() << "this CPU has no AVX2/FMA";
  struct Shape {
    int in, H, L, head, out;
  };
  for (const Shape sh : {Shape{12, 128, 1, 64, 6}, Shape{12, 128, 2, 64, 6}, Shape{5, 20, 2, 10, 7}}) {
    const auto net = make_random_lstm_network(sh.in, sh.H, sh.L, sh.head, sh.out, 21, 0.2f);
    const LstmKernel fast(net, KernelIsa::avx2_fma), portable(net, KernelIsa::portable);
    auto sf = fast.create_state(), sp = portable.create_state();
    std::mt19937 rng(9);
    std::normal_distribution<float> g(0.0f, 1.5f);
    Eigen::VectorXf x(sh.in), yf(sh.out), yp(sh.out);
    double worst = 0.0, largest = 0.0;
    for (int t = 0; t < 1000; ++t) {
      for (int i = 0; i < sh.in; ++i) x[i] = g(rng);
      fast.step(sf, x.data(), yf.data());
      portable.step(sp, x.data(), yp.data());
      worst = std::max(worst, static_cast<double>((yf - yp).cwiseAbs().maxCoeff()));
      largest = std::max(largest, static_cast<double>(yp.cwiseAbs().maxCoeff()));
    }
    EXPECT_LT(worst, 1e-5) << sh.H << " hidden, " << sh.L << " layers";
    EXPECT_GT(largest, 0.1);  // the outputs are not trivially zero
  }
}

TEST(DenseForward, MatchesReferenceWithEveryActivation) {
  std::mt19937 rng(3);
  DenseStack s;
  s.layers.push_back({random_matrix(7, 5, rng), random_matrix(7, 1, rng).col(0), Activation::relu});
  s.layers.push_back({random_matrix(9, 7, rng), random_matrix(9, 1, rng).col(0), Activation::tanh});
  s.layers.push_back({random_matrix(2, 9, rng), random_matrix(2, 1, rng).col(0), Activation::identity});
  Eigen::VectorXf x = random_matrix(5, 1, rng, 2.0f).col(0), y(2), a(s.max_width()), b(s.max_width());
  compute_dense_forward(s, x.data(), y.data(), a.data(), b.data());
  Eigen::VectorXd r = x.cast<double>();
  r = (s.layers[0].weight.cast<double>() * r + s.layers[0].bias.cast<double>()).cwiseMax(0.0);
  r = (s.layers[1].weight.cast<double>() * r + s.layers[1].bias.cast<double>()).array().tanh();
  r = s.layers[2].weight.cast<double>() * r + s.layers[2].bias.cast<double>();
  EXPECT_LT((y.cast<double>() - r).cwiseAbs().maxCoeff(), 1e-5);
}

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
  const auto path = std::filesystem::temp_directory_path() / "rcm_test_linear_model.json";
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

// Runs `model` and a bare kernel of its network over 3 s of the synthetic arm;
// the kernel's input is built by `reference_input(t, q, qd, x)` from the
// documented layout. Returns the largest output difference (joint units) and
// the largest |value| among the inputs after [q, qdot].
struct ReferenceComparison {
  double worst = 0, largest_feature = 0;
};
ReferenceComparison compare_with_reference_input(
    const LstmTorqueModel& model,
    const std::function<void(Eigen::Index, const Eigen::VectorXd&, const Eigen::VectorXd&, Eigen::VectorXf&)>&
        reference_input) {
  const Normalization& norm = model.normalization();
  LstmKernel kernel(model.network());
  auto state = kernel.create_state();
  auto ws = model.create_workspace();
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 3;
  const auto rec = rcm::test::make_synthetic_free_space(so);
  const int I = model.network().input_size();
  ReferenceComparison r;
  for (Eigen::Index t = 0; t < rec.time.size(); ++t) {
    Eigen::VectorXd q = rec.position.row(t).transpose(), qd = rec.velocity.row(t).transpose(), tau(3);
    Eigen::VectorXf x(I), y(3);
    for (int k = 0; k < 3; ++k) {
      x[k] = static_cast<float>((q[k] - norm.input_mean[k]) / norm.input_scale[k]);
      x[3 + k] = static_cast<float>((qd[k] - norm.input_mean[3 + k]) / norm.input_scale[3 + k]);
    }
    reference_input(t, q, qd, x);
    r.largest_feature = std::max(r.largest_feature, static_cast<double>(x.tail(I - 6).cwiseAbs().maxCoeff()));
    kernel.step(state, x.data(), y.data());
    model.compute_step(*ws, rec.time(t), q.data(), qd.data(), tau.data());
    for (int j = 0; j < 3; ++j)
      r.worst = std::max(r.worst, std::abs(tau[j] - (static_cast<double>(y[j]) * norm.output_scale[j] +
                                                     norm.output_mean[j])));
  }
  return r;
}

// The per-joint feature array `key` of the model's normalization, replaced in its
// file by an array holding a 0 or by one whose count is not a multiple of the 3
// joints: each must be an InputError naming the file and the field. The bad
// arrays are borrowed from fields that accept them.
void expect_bad_feature_arrays_located(const LstmTorqueModel& model, const std::string& key) {
  Normalization carrier = model.normalization();
  carrier.input_mean << 0.01f, 0.01f, 0.0f, 0.01f, 0.01f, 0.01f;
  const auto with_zero = torque_model_to_json(LstmTorqueModel(model.info(), model.network(), carrier))
      ["parameters"]["normalization"]["input_mean"];
  const auto five_values =
      torque_model_to_json(LstmTorqueModel(model.info(), random_lstm(model.network().input_size(), 16, 1, 5, 3, 2),
                                           model.normalization()))["parameters"]["lstm"]["head"][0]["bias"];
  const auto good = torque_model_to_json(model);
  ASSERT_NO_THROW(torque_model_from_json(good, "good.json"));
  for (const auto& [bad, expect] : {std::pair{with_zero, std::string("positive")},
                                    std::pair{five_values, std::string("multiple of 3")}}) {
    auto broken = good;
    broken["parameters"]["normalization"][key] = bad;
    try {
      torque_model_from_json(broken, "broken.json");
      FAIL() << "expected InputError for " << key << " " << expect;
    } catch (const rcm::InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("broken.json"), std::string::npos) << what;
      EXPECT_NE(what.find("parameters.normalization." + key), std::string::npos) << what;
      EXPECT_NE(what.find(expect), std::string::npos) << what;
    }
  }
}

TEST(DirectionFeatures, NetworkSeesTanhOfVelocityAfterQAndQdot) {
  const TorqueModelInfo info = info3();
  Normalization norm = norm3(Eigen::VectorXf::LinSpaced(6, 0.3f, 0.9f));
  norm.velocity_tanh_scale.resize(6);
  norm.velocity_tanh_scale << 0.003f, 0.002f, 0.0005f, 0.03f, 0.02f, 0.005f;  // two features, joint-minor
  const LstmNetwork net = random_lstm(12, 16, 1, 8, 3, 21);
  const LstmTorqueModel model(info, net, norm);
  // Reference: the kernel fed inputs built in double from the documented layout.
  const auto r = compare_with_reference_input(
      model, [&](Eigen::Index, const Eigen::VectorXd&, const Eigen::VectorXd& qd, Eigen::VectorXf& x) {
        for (int k = 0; k < 3; ++k)
          for (int f = 0; f < 2; ++f)
            x[6 + 3 * f + k] = static_cast<float>(std::tanh(qd[k] / norm.velocity_tanh_scale[3 * f + k]));
      });
  EXPECT_GT(r.largest_feature, 0.9);  // the motion drives the features into saturation
  EXPECT_LE(r.worst, 1e-5);
  // A network that does not take the features is refused.
  EXPECT_THROW(LstmTorqueModel(info, random_lstm(6, 16, 1, 8, 3, 21), norm), std::invalid_argument);
  Normalization odd = norm;
  odd.velocity_tanh_scale.resize(5);
  odd.velocity_tanh_scale.setConstant(0.01f);
  EXPECT_THROW(LstmTorqueModel(info, random_lstm(11, 16, 1, 8, 3, 21), odd), std::invalid_argument);

  // In a file: a scale that is not positive, or a count that is not a multiple of the joints.
  expect_bad_feature_arrays_located(model, "velocity_tanh_scale");
}

TEST(AccelerationFeatures, FilterMatchesItsRecurrenceAndFollowsARamp) {
  const Eigen::VectorXf tau = Eigen::Vector2f(0.01f, 0.04f);
  AccelerationFilter filter(tau, 2);
  const double dt = 0.005;
  // qdot of joint 1 is a ramp of slope 2 rad/s^2, joint 2 of slope -0.5.
  auto qd_at = [](double t) { return Eigen::Vector2d(2.0 * t + 0.3, -0.5 * t); };
  Eigen::Vector4d a_ref = Eigen::Vector4d::Zero();
  for (int k = 0; k < 400; ++k) {
    const double t = 1.0 + k * dt;
    const Eigen::Vector2d qd = qd_at(t);
    filter.update(t, qd.data());
    if (k > 0) {
      const Eigen::Vector2d slope(2.0, -0.5);
      for (int f = 0; f < 2; ++f) {
        const double alpha = dt / (static_cast<double>(tau[f]) + dt);
        a_ref.segment<2>(2 * f) += alpha * (slope - a_ref.segment<2>(2 * f));
      }
    }
    ASSERT_LE((filter.values() - a_ref).cwiseAbs().maxCoeff(), 1e-9) << "sample " << k;
  }
  EXPECT_NEAR(filter.values()[0], 2.0, 1e-9);  // 2 s of ramp: both filters have settled
  EXPECT_NEAR(filter.values()[3], -0.5, 1e-9);
  // A repeated time stamp changes nothing; time going back restarts from zero.
  const Eigen::VectorXd before = filter.values();
  const Eigen::Vector2d jump(5.0, 5.0);
  filter.update(1.0 + 399 * dt, jump.data());
  EXPECT_EQ(filter.values(), before);
  filter.update(0.5, jump.data());
  EXPECT_EQ(filter.values(), Eigen::VectorXd::Zero(4));
  filter.reset();
  filter.update(3.0, jump.data());
  EXPECT_EQ(filter.values(), Eigen::VectorXd::Zero(4));  // the first sample after a reset has no difference
  // The batch form is the filter run over the recording.
  Eigen::VectorXd time = Eigen::VectorXd::LinSpaced(50, 0.0, 49 * dt);
  Eigen::MatrixXd velocity(50, 3);
  for (int k = 0; k < 50; ++k) velocity.row(k) << std::sin(0.3 * k), 0.1 * k, 1.0;
  const Eigen::MatrixXd batch = compute_acceleration_features(tau, time, velocity, 2);
  ASSERT_EQ(batch.rows(), 50);
  ASSERT_EQ(batch.cols(), 4);
  AccelerationFilter again(tau, 2);
  for (int k = 0; k < 50; ++k) {
    const Eigen::Vector2d qd = velocity.row(k).head<2>().transpose();
    again.update(time[k], qd.data());
    EXPECT_EQ(batch.row(k), again.values().transpose());
  }
}

TEST(AccelerationFeatures, NetworkSeesScaledAccelerationAfterTheDirectionFeatures) {
  const TorqueModelInfo info = info3();
  Normalization norm = norm3(Eigen::VectorXf::LinSpaced(6, 0.3f, 0.9f));
  norm.velocity_tanh_scale = Eigen::Vector3f(0.003f, 0.002f, 0.0005f);
  norm.acceleration_filter_s = Eigen::Vector2f(0.02f, 0.06f);
  norm.acceleration_scale.resize(6);
  norm.acceleration_scale << 0.5f, 0.4f, 0.02f, 0.3f, 0.3f, 0.01f;
  const LstmNetwork net = random_lstm(15, 16, 1, 8, 3, 23);
  const LstmTorqueModel model(info, net, norm);
  // Reference inputs in double, the acceleration from the recurrence written out
  // (the synthetic arm is sampled evenly at its default 200 Hz).
  Eigen::VectorXd a = Eigen::VectorXd::Zero(6), qd_prev(3);
  const double dt = 1.0 / rcm::test::SyntheticArmOptions{}.rate_hz;
  const auto r = compare_with_reference_input(
      model, [&](Eigen::Index t, const Eigen::VectorXd&, const Eigen::VectorXd& qd, Eigen::VectorXf& x) {
        if (t > 0)
          for (int f = 0; f < 2; ++f)
            for (int k = 0; k < 3; ++k)
              a[3 * f + k] += dt / (norm.acceleration_filter_s[f] + dt) * ((qd[k] - qd_prev[k]) / dt - a[3 * f + k]);
        qd_prev = qd;
        for (int k = 0; k < 3; ++k) {
          x[6 + k] = static_cast<float>(std::tanh(qd[k] / norm.velocity_tanh_scale[k]));
          for (int f = 0; f < 2; ++f)
            x[9 + 3 * f + k] = static_cast<float>(a[3 * f + k] / norm.acceleration_scale[3 * f + k]);
        }
      });
  EXPECT_GT(r.largest_feature, 0.5);  // the motion does accelerate
  EXPECT_LE(r.worst, 1e-5);

  // Sizes that do not chain are refused, and the memoryless MLP takes none.
  EXPECT_THROW(LstmTorqueModel(info, random_lstm(9, 16, 1, 8, 3, 23), norm), std::invalid_argument);
  Normalization short_scale = norm;
  short_scale.acceleration_scale.conservativeResize(5);
  EXPECT_THROW(LstmTorqueModel(info, random_lstm(14, 16, 1, 8, 3, 23), short_scale), std::invalid_argument);
  std::vector<DenseStack> stacks = make_random_mlp_stacks(15, 10, 3, 4);
  EXPECT_THROW(MlpTorqueModel(info, stacks, norm), std::invalid_argument);

  // In a file: each of the pair missing, a time constant <= 0, a wrong count.
  const auto good = torque_model_to_json(model);
  ASSERT_NO_THROW(torque_model_from_json(good, "good.json"));
  const auto& gn = good["parameters"]["normalization"];
  Normalization carrier = norm;
  carrier.input_mean << 0.01f, 0.01f, 0.0f, 0.01f, 0.01f, 0.01f;
  const auto with_zero =
      torque_model_to_json(LstmTorqueModel(info, net, carrier))["parameters"]["normalization"]["input_mean"];
  struct Case {
    std::string key;
    nlohmann::json value;  // null: remove the key
    std::string field, expect;
  };
  const std::vector<Case> cases = {
      {"acceleration_scale", nullptr, "acceleration_scale", "missing"},
      {"acceleration_filter_s", nullptr, "acceleration_filter_s", "missing"},
      {"acceleration_scale", with_zero, "acceleration_scale", "positive"},
      {"acceleration_filter_s", gn["velocity_tanh_scale"], "acceleration_scale", "6"},
  };
  for (const auto& c : cases) {
    auto broken = good;
    auto& bn = broken["parameters"]["normalization"];
    if (c.value.is_null())
      bn.erase(c.key);
    else
      bn[c.key] = c.value;
    try {
      torque_model_from_json(broken, "broken.json");
      FAIL() << "expected InputError for " << c.key << " " << c.expect;
    } catch (const rcm::InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("broken.json"), std::string::npos) << what;
      EXPECT_NE(what.find(c.field), std::string::npos) << what;
      EXPECT_NE(what.find(c.expect), std::string::npos) << what;
    }
  }
}

TEST(DahlFeatures, FilterFollowsTheLinearModelsDahlState) {
  const Eigen::VectorXf x_c = (Eigen::VectorXf(4) << 1e-3f, 2e-2f, 5e-3f, 1e-1f).finished();  // 2 features x 2 joints
  DahlFilter filter(x_c, 2);
  // Reference values in closed form: after a monotonic displacement d from z0,
  // z = s + (z0 - s) exp(-|d| / x_c), whatever the steps it was taken in.
  const Eigen::Vector2d q0(0.3, -1.0);
  filter.update(q0.data());
  EXPECT_EQ(filter.values(), Eigen::VectorXd::Zero(4));  // the first sample has no displacement
  for (int k = 1; k <= 20; ++k) {
    const Eigen::Vector2d q = q0 + Eigen::Vector2d(0.0005 * k, -0.002 * k);
    filter.update(q.data());
  }
  const Eigen::Vector2d d(0.01, 0.04);
  for (int f = 0; f < 2; ++f)
    for (int k = 0; k < 2; ++k) {
      const double s = k == 0 ? 1.0 : -1.0;
      EXPECT_NEAR(filter.values()[2 * f + k], s - s * std::exp(-d[k] / x_c[2 * f + k]), 1e-12) << f << " " << k;
    }
  // At rest it stays put: the holding friction remembers the last direction.
  const Eigen::VectorXd held = filter.values();
  const Eigen::Vector2d q_end = q0 + Eigen::Vector2d(0.01, -0.04);
  for (int k = 0; k < 100; ++k) filter.update(q_end.data());
  EXPECT_EQ(filter.values(), held);
  // A reversal moves every state toward the new direction, each at its own rate.
  const Eigen::Vector2d back = q_end - Eigen::Vector2d(0.001, -0.001);
  filter.update(back.data());
  for (int f = 0; f < 2; ++f)
    for (int k = 0; k < 2; ++k) {
      const double s = k == 0 ? -1.0 : 1.0;
      EXPECT_NEAR(filter.values()[2 * f + k], compute_dahl_state(held[2 * f + k], s * 0.001, x_c[2 * f + k]), 1e-12);
    }
  filter.reset();
  filter.update(q0.data());
  EXPECT_EQ(filter.values(), Eigen::VectorXd::Zero(4));
  // The batch form is the filter run over the recording.
  Eigen::MatrixXd position(60, 3);
  for (int k = 0; k < 60; ++k) position.row(k) << 0.01 * std::sin(0.2 * k), 0.001 * k, 1.0;
  const Eigen::MatrixXd batch = compute_dahl_features(x_c, position, 2);
  ASSERT_EQ(batch.rows(), 60);
  ASSERT_EQ(batch.cols(), 4);
  DahlFilter again(x_c, 2);
  for (int k = 0; k < 60; ++k) {
    const Eigen::Vector2d q = position.row(k).head<2>().transpose();
    again.update(q.data());
    EXPECT_EQ(batch.row(k), again.values().transpose());
  }
}

TEST(DahlFeatures, NetworkSeesDahlStatesAfterTheAccelerationFeatures) {
  const TorqueModelInfo info = info3();
  Normalization norm = norm3(Eigen::VectorXf::LinSpaced(6, 0.3f, 0.9f));
  norm.velocity_tanh_scale = Eigen::Vector3f(0.003f, 0.002f, 0.0005f);
  norm.acceleration_filter_s = Eigen::VectorXf::Constant(1, 0.03f);
  norm.acceleration_scale = Eigen::Vector3f(0.5f, 0.4f, 0.02f);
  norm.dahl_displacement.resize(6);
  norm.dahl_displacement << 1e-4f, 2e-4f, 1e-5f, 3e-3f, 4e-3f, 5e-4f;
  const LstmNetwork net = random_lstm(18, 16, 1, 8, 3, 29);
  const LstmTorqueModel model(info, net, norm);
  // Reference inputs in double: the acceleration and Dahl recurrences written out.
  Eigen::VectorXd a = Eigen::VectorXd::Zero(3), z = Eigen::VectorXd::Zero(6), qd_prev(3), q_prev(3);
  const double dt = 1.0 / rcm::test::SyntheticArmOptions{}.rate_hz;
  const auto r = compare_with_reference_input(
      model, [&](Eigen::Index t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, Eigen::VectorXf& x) {
        if (t > 0)
          for (int k = 0; k < 3; ++k) {
            a[k] += dt / (0.03 + dt) * ((qd[k] - qd_prev[k]) / dt - a[k]);
            for (int f = 0; f < 2; ++f) {
              const double dq = q[k] - q_prev[k], s = dq > 0 ? 1.0 : dq < 0 ? -1.0 : 0.0;
              double& zf = z[3 * f + k];
              zf = s + (zf - s) * std::exp(-std::abs(dq) / norm.dahl_displacement[3 * f + k]);
            }
          }
        qd_prev = qd;
        q_prev = q;
        for (int k = 0; k < 3; ++k) {
          x[6 + k] = static_cast<float>(std::tanh(qd[k] / norm.velocity_tanh_scale[k]));
          x[9 + k] = static_cast<float>(a[k] / norm.acceleration_scale[k]);
          for (int f = 0; f < 2; ++f) x[12 + 3 * f + k] = static_cast<float>(z[3 * f + k]);
        }
      });
  EXPECT_GT(r.largest_feature, 0.9);  // the motion drives the Dahl states to saturation
  EXPECT_LE(r.worst, 1e-5);

  // Sizes that do not chain are refused, and the memoryless MLP takes none.
  EXPECT_THROW(LstmTorqueModel(info, random_lstm(12, 16, 1, 8, 3, 29), norm), std::invalid_argument);
  Normalization odd = norm;
  odd.dahl_displacement.conservativeResize(5);
  EXPECT_THROW(LstmTorqueModel(info, random_lstm(17, 16, 1, 8, 3, 29), odd), std::invalid_argument);
  Normalization dahl_only = norm3(Eigen::VectorXf::LinSpaced(6, 0.3f, 0.9f));
  dahl_only.dahl_displacement = Eigen::Vector3f(1e-3f, 1e-3f, 1e-3f);
  EXPECT_THROW(MlpTorqueModel(info, make_random_mlp_stacks(9, 10, 3, 4), dahl_only), std::invalid_argument);

  // In a file: a displacement <= 0, a count that is not a multiple of the joints.
  expect_bad_feature_arrays_located(model, "dahl_displacement");
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
