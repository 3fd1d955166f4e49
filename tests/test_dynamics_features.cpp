// The networks' inputs after [q, qdot] (direction, acceleration and Dahl
// features, each against the documented layout through a bare kernel), with
// their errors in model files (the output delay and clock: test_dynamics_clock.cpp).

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

}  // namespace

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
