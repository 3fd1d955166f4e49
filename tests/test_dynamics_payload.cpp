// Payload re-identification: the four payload terms are the gradient of the
// sliding body's potential; a known payload and inertia are recovered exactly
// from a recording the model made; a weight added to the simulated arm's insertion
// stage after the free-space fit is re-identified from a minute of motion and
// the model predicts another recording with it as well as a model fitted with
// it; what cannot identify it is refused; `rcm dynamics payload` writes the
// refitted model.

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/payload.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"
#include "run_cli.hpp"

namespace {

namespace fs = std::filesystem;
using rcm::dynamics::kPayloadTerms;

TEST(PayloadRegressor, IsTheGradientOfTheSlidingBodysPotential) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Vector3d g = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const Eigen::Vector3d e = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const double q[3] = {u(rng), u(rng), 0.1 + 0.1 * u(rng)};
    Eigen::Matrix<double, kPayloadTerms, 1> x;
    x << u(rng), u(rng), u(rng), u(rng);
    // The sliding body's moments: v1 = h, v2 = m e.
    Eigen::Matrix<double, rcm::dynamics::kGravityMoments, 1> v = Eigen::Matrix<double, rcm::dynamics::kGravityMoments, 1>::Zero();
    v.segment<3>(1) = x.head<3>();
    v.segment<3>(4) = x[3] * e;
    Eigen::Matrix<double, 3, kPayloadTerms> Y;
    rcm::dynamics::compute_payload_regressor(g, e, q, Y);
    const Eigen::Vector3d tau = Y * x;
    const double h = 1e-6;
    for (int j = 0; j < 3; ++j) {
      double qp[3] = {q[0], q[1], q[2]}, qm[3] = {q[0], q[1], q[2]};
      qp[j] += h;
      qm[j] -= h;
      const double dU = (rcm::dynamics::compute_rigid_body_potential(g, v, qp) -
                         rcm::dynamics::compute_rigid_body_potential(g, v, qm)) / (2 * h);
      EXPECT_NEAR(tau[j], dU, 1e-7 * (1.0 + std::abs(dU))) << "trial " << trial << " joint " << j + 1;
    }
  }
}

rcm::dynamics::FitOptions quiet() {
  rcm::dynamics::FitOptions o;
  o.verbose = false;
  return o;
}

rcm::Recording simulate_free_space(double extra_mass_kg, double seconds, std::uint64_t seed) {
  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  config.arm.insertion_stage.mass_kg += extra_mass_kg;
  config.protocol.free_space_s = seconds;
  config.seed = seed;
  return rcm::sim::simulate_free_space(config).recording;
}

// The arm's free-space model fitted, then 200 g put on the insertion stage:
// the gravity torque of that weight is what the model now misses.
TEST(PayloadRefit, AWeightOnTheInsertionStageIsReidentifiedFromAMinute) {
  const rcm::Recording light = simulate_free_space(0.0, 300.0, 1);
  const rcm::Recording heavy_minute = simulate_free_space(0.2, 60.0, 2);
  const rcm::Recording heavy_other = simulate_free_space(0.2, 120.0, 3);
  const auto fit = rcm::dynamics::fit_linear_torque_model({light}, quiet());
  ASSERT_EQ(fit.summary.structure.rfind("r", 0), 0u) << fit.summary.structure;  // rigid-body or remote-center
  const auto& model = static_cast<const rcm::dynamics::LinearTorqueModel&>(*fit.model);
  const rcm::dynamics::PayloadRefit refit = rcm::dynamics::refit_payload(model, {heavy_minute});
  EXPECT_EQ(refit.samples, heavy_minute.num_samples());

  // The weight along the instrument is the payload's, up to the sign the
  // model's gravity direction carries.
  EXPECT_NEAR(std::abs(refit.payload[3]), 0.2 * 9.81, 0.2 * 0.2 * 9.81) << refit.to_json().dump();

  const auto before = rcm::dynamics::evaluate_torque_model(model, {heavy_other});
  const auto after = rcm::dynamics::evaluate_torque_model(*refit.model, {heavy_other});
  const auto with_it = rcm::dynamics::fit_linear_torque_model({simulate_free_space(0.2, 300.0, 1)}, quiet());
  const auto reference = rcm::dynamics::evaluate_torque_model(*with_it.model, {heavy_other});
  for (int j = 0; j < 3; ++j) {
    std::cout << "[ payload  ] joint " << j + 1 << ": RMSE " << before[j].rmse << " without, " << after[j].rmse
              << " re-identified, " << reference[j].rmse << " fitted with it\n";
    EXPECT_LT(after[j].rmse, 1.25 * reference[j].rmse + 1e-3) << "joint " << j + 1;
  }
  // Without the refit every joint errs more; the insertion, which carries the
  // weight along the instrument, several times more.
  for (int j = 0; j < 3; ++j) EXPECT_LT(after[j].rmse, 0.75 * before[j].rmse) << "joint " << j + 1;
  EXPECT_LT(after[2].rmse, 0.2 * before[2].rmse);
  // The residual on the recording it was identified on falls with it.
  for (int j = 0; j < 3; ++j) EXPECT_LE(refit.rms_after[j], refit.rms_before[j] + 1e-12);
  // The refitted model says what was done to it.
  ASSERT_TRUE(refit.model->info().training.contains("payload_refit"));
}

// A recording made by the model itself with a known payload and inertia added
// (its gravity moved by the payload's moments, its yaw and pitch armatures
// raised): the refit returns those numbers and a model that reproduces the
// recording.
TEST(PayloadRefit, RecoversAKnownPayloadAndInertiaExactly) {
  using namespace rcm::dynamics;
  const rcm::Recording light = simulate_free_space(0.0, 120.0, 7);
  const auto fit = fit_linear_torque_model({light}, quiet());
  const auto& model = static_cast<const LinearTorqueModel&>(*fit.model);
  LinearTorqueParameters p = model.parameters();
  const Eigen::Vector3d e = get_instrument_axis(p);
  Eigen::Matrix<double, 17, kGravityMoments> P;
  compute_gravity_moment_map(p.gravity_direction, P);
  Eigen::Matrix<double, kGravityMoments, 1> v = Eigen::Matrix<double, kGravityMoments, 1>::Zero();
  const Eigen::Vector4d payload(0.08, -0.3, 0.45, 1.2);  // h (N m), m along e (N)
  v.segment<3>(1) = payload.head<3>();
  v.segment<3>(4) = payload[3] * e;
  p.gravity += P * v;
  const Eigen::Vector2d inertia(0.04, -0.02);
  p.armature.head<2>() += inertia;
  const LinearTorqueModel truth(model.info(), p);
  rcm::Recording heavy = simulate_free_space(0.0, 60.0, 8);
  heavy.effort.leftCols(3) = predict_torque(truth, heavy);

  const PayloadRefit refit = refit_payload(model, {heavy});
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(refit.payload[k], payload[k], 1e-6) << "term " << k << " " << refit.to_json().dump();
  for (int j = 0; j < 2; ++j) EXPECT_NEAR(refit.inertia[j], inertia[j], 1e-6) << "joint " << j + 1;
  const Eigen::MatrixXd again = predict_torque(*refit.model, heavy);
  EXPECT_LT((again - heavy.effort.leftCols(3)).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_EQ(refit.to_json()["payload"]["inertia_kg_m2"].size(), 2u);
}

TEST(PayloadRefit, RefusesWhatCannotIdentifyIt) {
  const rcm::Recording light = simulate_free_space(0.0, 120.0, 4);
  rcm::dynamics::FitOptions generic = quiet();
  generic.rigid_body = false;
  const auto free_potential = rcm::dynamics::fit_linear_torque_model({light}, generic);
  try {
    rcm::dynamics::refit_payload(static_cast<const rcm::dynamics::LinearTorqueModel&>(*free_potential.model), {light});
    FAIL() << "a generic potential was accepted";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("rigid-body structure"), std::string::npos) << e.what();
  }
  // An arm that never moves tells nothing apart.
  const auto fit = rcm::dynamics::fit_linear_torque_model({light}, quiet());
  rcm::Recording still = light;
  still.source = "still.csv";
  for (Eigen::Index t = 0; t < still.position.rows(); ++t) still.position.row(t) = light.position.row(0);
  still.velocity.setZero();
  try {
    rcm::dynamics::refit_payload(static_cast<const rcm::dynamics::LinearTorqueModel&>(*fit.model), {still});
    FAIL() << "a motionless recording was accepted";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("still.csv"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("undetermined"), std::string::npos) << e.what();
  }
}

TEST(PayloadCli, WritesTheRefittedModelAndRefusesANetwork) {
  const fs::path dir = fs::temp_directory_path() / ("rcm_test_payload_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  rcm::save_recording(dir / "light.csv", simulate_free_space(0.0, 180.0, 5));
  rcm::save_recording(dir / "heavy.csv", simulate_free_space(0.2, 60.0, 6));
  std::string out;
  ASSERT_EQ(rcm::test::run_cli("dynamics fit --model linear --out " + (dir / "light.json").string() + " " +
                                   (dir / "light.csv").string(),
                               out),
            0)
      << out;
  ASSERT_EQ(rcm::test::run_cli("dynamics payload " + (dir / "light.json").string() + " " + (dir / "heavy.csv").string() +
                                   " --out " + (dir / "heavy.json").string() + " --json",
                               out, rcm::test::CliOutput::stdout_only),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_NEAR(std::abs(j["payload"]["weight_n"].get<double>()), 0.2 * 9.81, 0.2 * 0.2 * 9.81) << j.dump();
  EXPECT_GT(j["samples"].get<std::size_t>(), 50u * 200u);
  const auto refitted = rcm::dynamics::load_torque_model((dir / "heavy.json").string());
  EXPECT_EQ(refitted->kind(), rcm::dynamics::TorqueModelKind::linear);
  EXPECT_TRUE(refitted->info().training.contains("payload_refit"));
  // The text output names the residuals per joint.
  ASSERT_EQ(rcm::test::run_cli("dynamics payload " + (dir / "light.json").string() + " " + (dir / "heavy.csv").string() +
                                   " --out " + (dir / "heavy2.json").string(),
                               out),
            0)
      << out;
  EXPECT_NE(out.find("RMS residual before"), std::string::npos) << out;
  // Neither a missing recording nor a bad model leaves a file behind.
  EXPECT_NE(rcm::test::run_cli("dynamics payload " + (dir / "light.json").string() + " " + (dir / "nope.csv").string() +
                                   " --out " + (dir / "nope.json").string(),
                               out),
            0);
  EXPECT_NE(out.find("nope.csv"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "nope.json"));
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace
