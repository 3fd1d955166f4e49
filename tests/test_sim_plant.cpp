// The arm as its motors drive it (rcm/sim/plant.hpp): the energy balance of the
// two-body cable transmission, the rigid limit against the rigid-body arm
// dynamics, the speed experiment's pair of recordings, and the new
// configuration fields' errors.

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <random>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/sim/arm_dynamics.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/plant.hpp"
#include "rcm/sim/sim_config.hpp"
#include "run_cli.hpp"
#include "temp_dir.hpp"

using namespace rcm::sim;

namespace {

// Friction of exactly zero: LuGre with no bristles, no viscous term and no
// offset (a positive Coulomb level keeps its g(v) away from 0).
std::array<JointFrictionParams, 3> no_friction() {
  std::array<JointFrictionParams, 3> f{};
  for (auto& p : f) {
    p.coulomb_pos = p.coulomb_neg = 1.0;
    p.bristle_stiffness = p.bristle_damping = p.viscous = p.offset = 0.0;
  }
  return f;
}

// The state moved by `h` along the plant's own vector field at `s`.
PlantState move_along(const Plant& plant, PlantState s, const PlantAcceleration& a, double h) {
  s.q += h * s.qd;
  s.qm += h * s.qmd;
  s.qd += h * a.qdd;
  s.qmd += h * a.qmdd;
  for (int j = 0; j < 3; ++j)
    if (!plant.compliant[static_cast<std::size_t>(j)]) {
      s.qm[j] = s.q[j];
      s.qmd[j] = s.qd[j];
    }
  return s;
}

std::string error_of(const SimConfig& c) {
  try {
    validate_config(c, "my.json");
  } catch (const rcm::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// d/dt (kinetic + potential + cable energy) = tau . qmd - cable damping losses
// - tau_ext . qd, on the continuous dynamics: the central difference of the
// energy along the plant's vector field against that power.
TEST(SimPlant, EnergyBalanceWithoutFriction) {
  SimConfig config = make_default_config();
  apply_arm_preset(config, "cable");
  config.arm.transmission[1].stiffness = 0.0;  // one rigid joint among compliant ones, its rotor on the link
  const Plant plant(config.arm, no_friction());
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double h = 1e-6;
  double max_power = 0.0;
  for (int trial = 0; trial < 40; ++trial) {
    PlantState s = make_plant_state_at_rest(plant, config.protocol.q0 + Eigen::Vector3d(0.4 * u(rng), 0.3 * u(rng),
                                                                                        0.03 * u(rng)));
    s.qd = Eigen::Vector3d(u(rng), u(rng), 0.1 * u(rng));
    s.qmd = s.qd + Eigen::Vector3d(0.3 * u(rng), 0.3 * u(rng), 0.03 * u(rng));
    s.qm += Eigen::Vector3d(0.01 * u(rng), 0.01 * u(rng), 0.001 * u(rng));
    s.qm[1] = s.q[1];
    s.qmd[1] = s.qd[1];
    const Eigen::Vector3d tau(2.0 * u(rng), 2.0 * u(rng), 10.0 * u(rng));
    const Eigen::Vector3d tau_ext(0.5 * u(rng), 0.5 * u(rng), 3.0 * u(rng));
    const PlantAcceleration a = compute_plant_acceleration(plant, s, tau, tau_ext);
    EXPECT_LT((a.friction_link + a.friction_motor).norm(), 1e-15);
    double power = tau.dot(s.qmd) - tau_ext.dot(s.qd);
    for (int j = 0; j < 3; ++j)
      if (plant.compliant[static_cast<std::size_t>(j)]) {
        const double slip = s.qmd[j] - s.qd[j];
        power -= plant.transmission[static_cast<std::size_t>(j)].damping * slip * slip;
      }
    const double dE = (compute_plant_energy(plant, move_along(plant, s, a, h)) -
                       compute_plant_energy(plant, move_along(plant, s, a, -h))) /
                      (2.0 * h);
    // Truncation ~h^2 E''' (< 1e-7 here), rounding ~1e-16 E / h (~1e-9).
    EXPECT_NEAR(dE, power, 1e-6 * (1.0 + std::abs(power))) << "trial " << trial;
    max_power = std::max(max_power, std::abs(power));
  }
  EXPECT_GT(max_power, 1.0);  // real power flowed
}

// The rigid preset is the rigid-body arm of arm_dynamics.hpp (the bench before
// cables): the same accelerations and tau_fs, to rounding.
TEST(SimPlant, RigidArmIsTheRigidBodyDynamics) {
  const SimConfig config = make_default_config();
  ASSERT_EQ(config.arm.preset, "rigid");
  const Plant plant(config.arm, config.friction);
  const ArmDynamics& arm = plant.arm;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    PlantState s = make_plant_state_at_rest(plant, config.protocol.q0 + Eigen::Vector3d(0.3 * u(rng), 0.3 * u(rng),
                                                                                        0.02 * u(rng)));
    s.qd = s.qmd = Eigen::Vector3d(u(rng), u(rng), 0.05 * u(rng));
    s.friction_motor.bristles = Eigen::Vector3d(1e-4 * u(rng), 1e-4 * u(rng), 1e-5 * u(rng));
    s.friction_motor.slip.col(0) = s.friction_motor.bristles;
    const Eigen::Vector3d tau(u(rng), u(rng), 5.0 * u(rng)), tau_ext(0.2 * u(rng), 0.2 * u(rng), u(rng));
    const PlantAcceleration a = compute_plant_acceleration(plant, s, tau, tau_ext);
    const FrictionOutput fr = compute_friction(config.friction, s.friction_motor, s.qd);
    const Eigen::Vector3d h = compute_inverse_dynamics(arm, s.q, s.qd, Eigen::Vector3d::Zero(), true);
    const Eigen::Matrix3d M = compute_mass_matrix(arm, s.q);
    const Eigen::Vector3d qdd = M.llt().solve(tau - h - fr.tau - tau_ext);
    EXPECT_LT((a.qdd - qdd).norm(), 1e-12 * (1.0 + qdd.norm())) << trial;
    EXPECT_LT((a.qmdd - qdd).norm(), 1e-12 * (1.0 + qdd.norm())) << trial;
    EXPECT_LT((a.tau_fs - (M * qdd + h + fr.tau)).norm(), 1e-12 * (1.0 + tau.norm())) << trial;
    // One step moves motor and link together, the bristles as before.
    PlantState next = s;
    advance_plant_state(plant, next, a, 5e-4);
    EXPECT_EQ(next.q, next.qm);
    const FrictionState expected = advance_friction_state(config.friction, s.friction_motor, next.qd, 5e-4);
    EXPECT_EQ(next.friction_motor.bristles, expected.bristles);
    EXPECT_EQ(next.friction_motor.slip, expected.slip);
  }
}

// A cable much stiffer than anything else in the joint moves the link as a
// rigid joint whose rotor adds to its inertia.
TEST(SimPlant, StiffCableTendsToTheRigidJointWithItsRotor) {
  SimConfig config = make_default_config();
  apply_arm_preset(config, "cable");
  SimConfig rigid = config;
  for (int j = 0; j < 3; ++j) {
    auto& t = config.arm.transmission[static_cast<std::size_t>(j)];
    t.stiffness *= 1e3;
    t.damping = 2.0 * 0.7 * std::sqrt(t.stiffness * t.rotor_inertia);  // the fast mode well damped
    rigid.arm.transmission[static_cast<std::size_t>(j)].stiffness = 0.0;
  }
  const Plant stiff(config.arm, config.friction), direct(rigid.arm, rigid.friction);
  PlantState a = make_plant_state_at_rest(stiff, config.protocol.q0);
  PlantState b = make_plant_state_at_rest(direct, config.protocol.q0);
  const double dt = 2e-6;
  double travelled = 0.0;
  for (int k = 0; k < 100000; ++k) {  // 0.2 s
    const double t = k * dt;
    const Eigen::Vector3d g =
        compute_inverse_dynamics(direct.arm, b.q, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), true);
    const Eigen::Vector3d tau = g + Eigen::Vector3d(0.8, -0.6, 4.0) * std::sin(2.0 * M_PI * 2.0 * t);
    advance_plant_state(stiff, a, compute_plant_acceleration(stiff, a, tau, Eigen::Vector3d::Zero()), dt);
    advance_plant_state(direct, b, compute_plant_acceleration(direct, b, tau, Eigen::Vector3d::Zero()), dt);
    travelled = std::max(travelled, (b.q - config.protocol.q0).norm());
  }
  EXPECT_GT(travelled, 0.01);
  EXPECT_LT((a.q - b.q).norm(), 2e-3 * travelled);
  EXPECT_LT((a.qd - b.qd).norm(), 2e-2 * (1.0 + b.qd.norm()));
}

// `rcm simulate --experiment speed`: fast.csv at the log rate, slow.csv at half
// of it over twice the time, row k of both at the same point of the path.
TEST(SimSpeedExperiment, WritesBothRecordingsAtTheirRatesOnTheSamePath) {
  rcm::test::TempDir dir("rcm_test_sim_speed_");
  const auto cfg = dir.write("cfg.json", R"({"speed": {"duration_s": 4.0, "ramp_s": 1.0}})");
  const auto out = dir.path() / "out";
  std::string text;
  ASSERT_EQ(rcm::test::run_cli("simulate --experiment speed --seed 3 --config " + cfg.string() + " --out " +
                                   out.string() + " --json",
                               text, rcm::test::CliOutput::stdout_only),
            0)
      << text;
  const nlohmann::json summary = nlohmann::json::parse(text);
  EXPECT_EQ(summary["arm"], "cable");
  EXPECT_EQ(rcm::load_json_file(out / "speed.json"), summary);
  const rcm::Recording fast = rcm::load_recording(out / "fast.csv");
  const rcm::Recording slow = rcm::load_recording(out / "slow.csv");
  EXPECT_TRUE(std::filesystem::exists(out / "fast_truth.csv"));
  EXPECT_TRUE(std::filesystem::exists(out / "slow_truth.csv"));
  ASSERT_EQ(fast.time.size(), 800);
  ASSERT_EQ(slow.time.size(), fast.time.size());
  for (Eigen::Index k = 1; k < fast.time.size(); ++k) {
    ASSERT_NEAR(fast.time[k] - fast.time[k - 1], 0.005, 1e-6) << k;
    ASSERT_NEAR(slow.time[k] - slow.time[k - 1], 0.010, 1e-6) << k;
  }
  // The same path: the positions differ by the tracking errors only, the
  // velocities by the factor 2.
  const Eigen::ArrayXXd dq = (fast.position - slow.position).array().abs();
  const Eigen::ArrayXd range = (fast.position.colwise().maxCoeff() - fast.position.colwise().minCoeff()).transpose();
  for (int j = 0; j < 3; ++j) {
    EXPECT_GT(range[j], 0.05 * (j == 2 ? 0.1 : 1.0)) << j;
    EXPECT_LT(dq.col(j).maxCoeff(), 0.05 * range[j]) << j;
    const double v_fast = fast.velocity.col(j).norm(), v_slow = slow.velocity.col(j).norm();
    EXPECT_NEAR(v_fast / v_slow, 2.0, 0.1) << j;
  }

  EXPECT_NE(rcm::test::run_cli("simulate --experiment speed --arm stiff --out " + out.string(), text), 0);
  EXPECT_NE(text.find("--arm"), std::string::npos) << text;
  EXPECT_NE(text.find("rigid, cable"), std::string::npos) << text;
  EXPECT_NE(rcm::test::run_cli("simulate --experiment sped --out " + out.string(), text), 0);
  EXPECT_NE(text.find("speed"), std::string::npos) << text;
}

TEST(SimConfig, TransmissionVelocityNoiseAndSpeedFieldsAreChecked) {
  const auto expect_error = [](const SimConfig& c, const std::string& field) {
    const std::string e = error_of(c);
    EXPECT_NE(e.find(field), std::string::npos) << "expected an error naming " << field << ", got: " << e;
  };
  SimConfig base = make_default_config();
  EXPECT_EQ(error_of(base), "");
  apply_arm_preset(base, "cable");
  EXPECT_EQ(error_of(base), "");

  SimConfig c = base;
  c.arm.transmission[0].stiffness = -1.0;
  expect_error(c, "arm.transmission.yaw.stiffness");
  c = base;
  c.arm.transmission[2].friction_link_share = 1.5;
  expect_error(c, "arm.transmission.insertion.friction_link_share");
  c = base;
  c.arm.transmission[1].rotor_inertia = 0.0;
  expect_error(c, "arm.transmission.pitch.rotor_inertia");
  c = base;
  c.arm.transmission[1].stiffness = 1e7;  // a motor mode the integration step cannot follow
  expect_error(c, "arm.transmission.pitch.stiffness");
  c = base;
  c.arm.transmission[0].damping = std::nan("");
  expect_error(c, "arm.transmission.yaw.damping");
  c = base;
  c.sensors.velocity_noise[2] = -0.1;
  expect_error(c, "sensors.velocity_noise[2]");
  c = base;
  c.speed.slowdown = 0;
  expect_error(c, "speed.slowdown");
  c = base;
  c.speed.slowdown = 21;
  expect_error(c, "speed.slowdown");
  c = base;
  c.speed.duration_s = 0.0;
  expect_error(c, "speed.duration_s");
  c = base;
  c.speed.amplitude[1] = 3.0;  // a session does not play the speed path; the experiment refuses it
  EXPECT_EQ(error_of(c), "");
  try {
    validate_speed_experiment(c, "my.json");
    ADD_FAILURE() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("speed.amplitude[1]"), std::string::npos) << e.what();
  }
  EXPECT_THROW(run_speed_experiment(c), rcm::InputError);
  c = base;
  c.speed.falloff = -1.0;
  expect_error(c, "speed.falloff");

  SimConfig j = make_default_config();
  try {
    apply_config_json(j, nlohmann::json::parse(R"({"arm": {"preset": "springy"}})"), "my.json");
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("arm.preset"), std::string::npos) << e.what();
  }
  // The preset first, then the explicit fields.
  apply_config_json(j, nlohmann::json::parse(R"({"arm": {"preset": "cable", "transmission": {"yaw": {"stiffness": 300}}}})"),
                    "my.json");
  EXPECT_EQ(j.arm.preset, "cable");
  EXPECT_DOUBLE_EQ(j.arm.transmission[0].stiffness, 300.0);
  EXPECT_GT(j.arm.transmission[1].stiffness, 0.0);
}
