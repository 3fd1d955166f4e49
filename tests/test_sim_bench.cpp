// The simulated bench end to end: the force identity of the contract on its
// ground truth, Fig. 3, determinism, configuration errors, and files that the
// project's readers (and `rcm inspect`) accept.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "rcm/common/error.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/plot.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"

using namespace rcm::sim;
namespace fs = std::filesystem;

namespace {

fs::path make_temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("rcm_test_sim_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

SimConfig short_config() {
  SimConfig c = make_default_config();
  c.protocol.free_space_s = 6.0;
  c.protocol.calibration_s = 4.0;
  c.protocol.trial_s = 4.0;
  c.protocol.static_return_s = 1.5;
  c.protocol.static_hold_s = 1.0;
  c.protocol.baseline_approach_s = 1.0;
  c.protocol.baseline_hold_s = 1.0;
  c.protocol.coaxial_offsets_m = {0.03};
  c.protocol.radial_offsets_m = {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(0.01, 0.015)};
  return c;
}

}  // namespace

// f = J_D^{-T} (tau - tau_fs) must reproduce the simulated tissue force, with the
// contract's J_D from the kinematics module: sign, application point and frame.
TEST(SimBench, ForceIdentityHoldsOnGroundTruth) {
  for (const std::string tissue : {"linear", "viscoelastic", "sliding", "stiffening"}) {
    SimConfig config = short_config();
    config.sensors.noise = false;
    apply_tissue_preset(config.tissue, tissue);
    const Eigen::Vector3d m(0.01, 0.015, 0.03);
    const SimulatedTrial trial = simulate_trial(config, m);
    const rcm::IncisionFrame frame = rcm::make_incision_frame(config.protocol.q0);
    double max_force = 0.0, max_error = 0.0;
    for (const SimulatedRecording* rec : {&trial.recording, &trial.static_recording}) {
      const rcm::Recording& r = rec->recording;
      for (Eigen::Index k = 0; k < r.effort.rows(); ++k) {
        const Eigen::Vector3d q = r.position.row(k).transpose();
        const Eigen::Vector3d dtau = r.effort.row(k).transpose() - rec->truth.tau_fs.row(k).transpose();
        const double s = rcm::compute_shaft_distance(frame, q, m.z());
        const Eigen::Matrix3d J = rcm::compute_incision_jacobian(q, s);
        const Eigen::Vector3d f = J.transpose().fullPivLu().solve(dtau);
        const Eigen::Vector3d f_true = rec->truth.force.row(k).transpose();
        max_error = std::max(max_error, (f - f_true).norm());
        max_force = std::max(max_force, f_true.norm());
        // The ATI columns are the same force when the sensors are exact.
        EXPECT_LT((r.force->row(k).transpose() - f_true).norm(), 1e-12);
      }
    }
    EXPECT_LT(max_error, 1e-9) << tissue;
    EXPECT_GT(max_force, 10.0) << tissue;  // the identity was tested under real load
  }
}

TEST(SimBench, ForceModuleAgreesWithTruth) {
  SimConfig config = short_config();
  config.sensors.noise = false;
  const Eigen::Vector3d m(0.0, 0.0, 0.04);
  const SimulatedTrial trial = simulate_trial(config, m);
  const rcm::IncisionFrame frame = rcm::make_incision_frame(config.protocol.q0);
  const rcm::IncisionForceSeries series = rcm::compute_incision_force_series(
      frame, trial.recording.recording, trial.recording.truth.tau_fs, m.z());
  for (Eigen::Index k = 0; k < series.f_inc_base.rows(); ++k) {
    if (series.status[static_cast<std::size_t>(k)] == rcm::JacobianStatus::singular) continue;
    EXPECT_LT((series.f_inc_base.row(k) - trial.recording.truth.force.row(k)).norm(), 1e-9) << k;
  }
}

TEST(SimBench, StaticHoldIsAtQ0UnderTheRadialForce) {
  SimConfig config = short_config();
  const Eigen::Vector3d m(0.01, 0.015, 0.03);
  const SimulatedTrial trial = simulate_trial(config, m);
  const SimTruth& t = trial.static_recording.truth;
  const Eigen::Index last = t.q.rows() - 1;
  EXPECT_LT((t.q.row(last).transpose() - config.protocol.q0).norm(), 5e-3);
  EXPECT_LT(t.qd.row(last).norm(), 1e-3);
  // At q0 only the radial offset stretches the incision: g(|dr|).
  EXPECT_NEAR(t.force.row(last).norm(), 875.0 * std::hypot(0.01, 0.015), 0.6);
  // Time continues from the trial into the static file.
  EXPECT_GT(trial.static_recording.recording.time[0], trial.recording.recording.time.tail(1)[0]);
}

TEST(SimBench, Fig3CalibrationPoints) {
  SimConfig config = make_default_config();
  config.force_angle.offsets_m = {0.0, 0.010, 0.030, 0.040};
  config.force_angle.angles_deg = {-45, 0, 45};
  config.force_angle.move_s = 1.0;
  config.force_angle.hold_s = 0.8;
  config.force_angle.average_s = 0.4;
  const ForceAngleResult r = run_force_angle_experiment(config);
  ASSERT_EQ(r.points.size(), 12u);
  for (const auto& p : r.points) {
    if (p.offset_m <= 0.010) EXPECT_LT(p.force_n, 12.0) << p.offset_m << " " << p.theta_rad;
    if (p.theta_rad == 0.0) EXPECT_LT(p.force_n, 0.5);
    if (p.offset_m >= 0.030 && std::abs(p.theta_rad) > 0.7) EXPECT_GT(p.force_n, 12.0);
    if (p.offset_m == 0.040 && std::abs(p.theta_rad) > 0.7) EXPECT_NEAR(p.force_n, 35.0, 1.5);
    EXPECT_NEAR(p.force_true_n, p.force_law_n, 0.05);
  }
  // The stiffening preset reads Fig. 3 literally: 12 N at 20 mm, 35 N at 40 mm (45 deg).
  apply_tissue_preset(config.tissue, "stiffening");
  config.force_angle.offsets_m = {0.020, 0.040};
  config.force_angle.angles_deg = {45};
  const ForceAngleResult s = run_force_angle_experiment(config);
  EXPECT_NEAR(s.points[0].force_n, 12.0, 0.6);
  EXPECT_NEAR(s.points[1].force_n, 35.0, 1.5);
}

TEST(SimBench, DeterministicBySeed) {
  SimConfig config = short_config();
  const Eigen::Vector3d m(0.01, 0.015, 0.03);
  const SimulatedTrial a = simulate_trial(config, m), b = simulate_trial(config, m);
  EXPECT_EQ(a.recording.recording.effort, b.recording.recording.effort);
  EXPECT_EQ(a.recording.recording.position, b.recording.recording.position);
  EXPECT_EQ(*a.static_recording.recording.force, *b.static_recording.recording.force);
  config.seed = 2;
  const SimulatedTrial c = simulate_trial(config, m);
  EXPECT_GT((a.recording.recording.effort - c.recording.recording.effort).norm(), 1.0);
  // By default each trial moves through its own path; shared, the trials replay
  // the calibration's path and only the misalignment differs.
  SimConfig exact = short_config();
  exact.sensors.noise = false;
  ASSERT_EQ(exact.protocol.trial_paths, "own");
  const SimulatedTrial own_d = simulate_trial(exact, Eigen::Vector3d(0, 0, 0.02));
  const SimulatedTrial own_e = simulate_trial(exact, Eigen::Vector3d(0, 0, 0.05));
  EXPECT_GT((own_d.recording.truth.q - own_e.recording.truth.q).cwiseAbs().maxCoeff(), 0.02);
  exact.protocol.trial_paths = "shared";
  const SimulatedTrial d = simulate_trial(exact, Eigen::Vector3d(0, 0, 0.02));
  const SimulatedTrial e = simulate_trial(exact, Eigen::Vector3d(0, 0, 0.05));
  EXPECT_LT((d.recording.truth.q - e.recording.truth.q).cwiseAbs().maxCoeff(), 0.01);
  EXPECT_LT((d.recording.truth.q - simulate_calibration(exact).truth.q.topRows(d.recording.truth.q.rows()))
                .cwiseAbs()
                .maxCoeff(),
            0.01);
}

TEST(SimBench, SessionFilesDoNotDependOnThreadCount) {
  SimConfig config = short_config();
  const fs::path one = make_temp_dir("threads1"), two = make_temp_dir("threads2");
  config.threads = 1;
  simulate_session(config, one);
  config.threads = 2;
  simulate_session(config, two);
  int compared = 0;
  for (const auto& entry : fs::directory_iterator(one)) {
    if (entry.path().filename() == "sim_config.json") continue;  // records the thread count itself
    EXPECT_EQ(read_file(entry.path()), read_file(two / entry.path().filename())) << entry.path();
    ++compared;
  }
  EXPECT_GE(compared, 14);
  fs::remove_all(one);
  fs::remove_all(two);
}

TEST(SimBench, SessionRoundTripsThroughTheReaders) {
  SimConfig config = short_config();
  config.sensors.repeat_row_probability = 0.02;
  const fs::path dir = make_temp_dir("session");
  const SessionWriteSummary summary = simulate_session(config, dir);
  const rcm::Session s = rcm::load_session(summary.manifest);
  EXPECT_EQ(s.free_space.size(), 1u);
  ASSERT_EQ(s.trials.size(), 2u);
  ASSERT_TRUE(s.calibration.has_value());
  EXPECT_DOUBLE_EQ(s.calibration->coaxial_offset_m, 0.03);
  EXPECT_TRUE(s.trials[1].truth_misalignment_m->isApprox(Eigen::Vector3d(0.01, 0.015, 0.03)));
  EXPECT_EQ(s.trials[1].name, "D30_r10_15");
  const rcm::Recording rec = rcm::load_recording(*s.trials[1].static_recording);
  EXPECT_TRUE(rec.has_force());
  EXPECT_EQ(rec.num_joints(), 3);
  const rcm::Recording fs_rec = rcm::load_recording(s.free_space[0]);
  EXPECT_GT(fs_rec.repeated_rows, 0u);
  EXPECT_EQ(fs_rec.num_samples(), 1200u);
  // The resolved configuration reproduces the session.
  const SimConfig again = load_config(dir / "sim_config.json");
  EXPECT_EQ(config_to_json(again), config_to_json(config));
  fs::remove_all(dir);
}

TEST(SimBench, InspectAcceptsEveryFileTheSimulatorWrites) {
  const fs::path dir = make_temp_dir("inspect");
  const std::string cli = RCM_CLI_PATH;
  const std::string sim = cli + " simulate --out " + dir.string() +
                          " --free-space-s 4 --trial-s 3 --calibration-s 3 --json > " +
                          (dir / "summary.json").string() + " 2>/dev/null";
  ASSERT_EQ(std::system(sim.c_str()), 0) << sim;
  const auto summary = nlohmann::json::parse(read_file(dir / "summary.json"));
  EXPECT_EQ(summary["recordings"].size(), 23u);  // free space, baseline, calibration, 10 x 2 trials
  fs::remove(dir / "summary.json");
  int inspected = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name == "sim_config.json") continue;  // a simulator input, not a recording or session
    const std::string cmd = cli + " inspect " + entry.path().string() + " --json > /dev/null 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    ++inspected;
  }
  EXPECT_EQ(inspected, 1 + 23 * 2);  // session.json, recordings and their truth files
  fs::remove_all(dir);
}

TEST(SimConfig, UnknownKeysAndWrongTypesAreLocated) {
  SimConfig c = make_default_config();
  try {
    apply_config_json(c, nlohmann::json::parse(R"({"controller": {"kpp": 3}})"), "my.json");
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("my.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("controller.kpp"), std::string::npos) << e.what();
  }
  try {
    apply_config_json(c, nlohmann::json::parse(R"({"sensors": {"effort_noise": [1, "x", 3]}})"), "my.json");
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("sensors.effort_noise[1]"), std::string::npos) << e.what();
  }
  EXPECT_THROW(apply_config_json(c, nlohmann::json::parse(R"({"tissue": {"preset": "jelly"}})"), "my.json"),
               rcm::InputError);
  SimConfig bad = make_default_config();
  bad.trajectory.amplitude = Eigen::Vector3d(1.2, 0.9, 0.03);
  EXPECT_THROW(validate_config(bad, "my.json"), rcm::InputError);
  bad = make_default_config();
  bad.sensors.log_rate_hz = 300.0;
  EXPECT_THROW(validate_config(bad, "my.json"), rcm::InputError);
  // Friction: slip elements located by index, at most kMaxSlipElements; the
  // LuGre element's two levels both 0 (none) or both positive.
  auto field_of = [](const SimConfig& config) {
    try {
      validate_config(config, "my.json");
    } catch (const rcm::InputError& e) {
      return e.where().field;
    }
    return std::string("no error");
  };
  bad = make_default_config();
  bad.friction[1].slip_elements[2] = Eigen::Vector2d(0.0, 0.01);
  EXPECT_EQ(field_of(bad), "friction.pitch.slip_elements[2]");
  bad = make_default_config();
  bad.friction[0].slip_elements.assign(kMaxSlipElements + 1, Eigen::Vector2d(1e-3, 0.01));
  EXPECT_EQ(field_of(bad), "friction.yaw.slip_elements");
  bad = make_default_config();
  bad.friction[2].coulomb_pos = 0.5;
  EXPECT_EQ(field_of(bad), "friction.insertion.coulomb_neg");
  bad = make_default_config();
  bad.protocol.trial_paths = "same";
  EXPECT_EQ(field_of(bad), "protocol.trial_paths");
  // The elements round-trip through JSON with the rest of the configuration.
  SimConfig round = make_default_config();
  apply_config_json(round, config_to_json(make_default_config()), "round.json");
  EXPECT_EQ(round.friction[1].slip_elements, make_default_config().friction[1].slip_elements);
}

TEST(SimConfig, PresetThenExplicitFieldsAndExampleFile) {
  SimConfig c = make_default_config();
  apply_config_json(c, nlohmann::json::parse(R"({"tissue": {"preset": "viscoelastic", "stiffness_n_per_m": 700}})"),
                    "x.json");
  EXPECT_EQ(c.tissue.preset, "viscoelastic");
  EXPECT_DOUBLE_EQ(c.tissue.stiffness_n_per_m, 700.0);
  EXPECT_GT(c.tissue.damping_n_s_per_m, 0.0);
  const SimConfig example = load_config(fs::path(RCM_SOURCE_DIR) / "examples" / "sim_config.json");
  EXPECT_NO_THROW(validate_config(example));
  EXPECT_FALSE(describe_config(example).empty());
}

TEST(Plot, WritesPngAndSvg) {
  if (!rcm::is_gnuplot_available()) GTEST_SKIP() << "gnuplot not installed";
  const fs::path dir = make_temp_dir("plot");
  rcm::PlotSpec spec;
  spec.title = "it's a test";
  spec.x_label = "x";
  spec.y_label = "y";
  spec.series.push_back({"a", {0, 1, 2}, {1, 3, 2}});
  spec.series.push_back({"b's", {0, 1, 2}, {2, 1, 0}, rcm::PlotStyle::points});
  const rcm::PlotFiles files = rcm::save_plot(spec, dir / "fig");
  const std::string png = read_file(files.png);
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  EXPECT_NE(read_file(files.svg).find("<svg"), std::string::npos);
  spec.series.push_back({"bad", {0, 1}, {1}});
  EXPECT_THROW(rcm::save_plot(spec, dir / "bad"), std::invalid_argument);
  fs::remove_all(dir);
}
