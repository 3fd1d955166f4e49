// Excitation trajectories (rcm/dynamics/excitation.hpp, `rcm excite`): at rest
// at q0 at both ends, inside every limit, derivatives that are the series'
// own, a better conditioned regressor than its random start and than the
// simulator's random teleoperation, deterministic for a seed, and a CSV that
// `rcm simulate --free-space-trajectory` plays; bad input is located.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/excitation.hpp"
#include "rcm/io/joint_trajectory.hpp"
#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"
#include "rcm/sim/trajectory.hpp"
#include "run_cli.hpp"
#include "temp_dir.hpp"

namespace {

using namespace rcm::dynamics;

const rcm::PsmModel& robot() {
  static const rcm::PsmModel model = rcm::load_robot_model("dvrk-psm-classic");
  return model;
}

// Small enough to design in well under a second.
ExcitationOptions small_options() {
  ExcitationOptions o;
  o.duration_s = 10.0;
  o.period_s = 5.0;
  o.harmonics = 3;
  o.samples_per_period = 96;
  o.max_iterations = 30;
  return o;
}

const ExcitationTrajectory& small_design() {
  static const ExcitationTrajectory r = design_excitation(robot(), small_options());
  return r;
}

std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

TEST(Excitation, StartsAndEndsAtRestAtQ0) {
  const ExcitationTrajectory& r = small_design();
  const ExcitationOptions o = small_options();
  const Eigen::Index last = r.time.size() - 1;
  ASSERT_EQ(r.time.size(), 2001);
  EXPECT_DOUBLE_EQ(r.time[last], o.duration_s);
  for (const Eigen::Index t : {Eigen::Index(0), last}) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(r.position(t, j), o.q0[j], 1e-12) << "sample " << t << " joint " << j;
      EXPECT_NEAR(r.velocity(t, j), 0.0, 1e-12) << "sample " << t << " joint " << j;
      EXPECT_NEAR(r.acceleration(t, j), 0.0, 1e-9) << "sample " << t << " joint " << j;
    }
  }
  // It moves in between: every joint leaves q0 by a good share of its room.
  for (int j = 0; j < 3; ++j) {
    const double room = std::min(r.limits.position_max[j] - o.q0[j], o.q0[j] - r.limits.position_min[j]);
    EXPECT_GT((r.position.col(j).array() - o.q0[j]).abs().maxCoeff(), 0.05 * room) << "joint " << j;
  }
}

TEST(Excitation, EverySampleIsWithinTheLimits) {
  const ExcitationTrajectory& r = small_design();
  EXPECT_TRUE(r.summary.limits_satisfied) << r.summary.brief_report();
  const ExcitationLimits& L = r.limits;
  for (Eigen::Index t = 0; t < r.time.size(); ++t)
    for (int j = 0; j < 3; ++j) {
      ASSERT_GE(r.position(t, j), L.position_min[j]) << "sample " << t << " joint " << j;
      ASSERT_LE(r.position(t, j), L.position_max[j]) << "sample " << t << " joint " << j;
      ASSERT_LE(std::abs(r.velocity(t, j)), L.velocity_max[j]) << "sample " << t << " joint " << j;
      ASSERT_LE(std::abs(r.acceleration(t, j)), L.acceleration_max[j]) << "sample " << t << " joint " << j;
    }
  // The limits are the robot description's less the margin.
  const ExcitationOptions o = small_options();
  EXPECT_DOUBLE_EQ(L.position_min[2], robot().joints()[2].q_min + o.position_margin[2]);
  EXPECT_DOUBLE_EQ(L.position_max[0], robot().joints()[0].q_max - o.position_margin[0]);
}

TEST(Excitation, DerivativesMatchFiniteDifferences) {
  const ExcitationSeries& s = small_design().series;
  // Central differences err by h^2 / 6 times the next derivative; a bound on
  // it from the coefficients sets the tolerance.
  const double w = 2.0 * M_PI / s.period_s(), h = 1e-4;
  Eigen::Vector3d bound3 = Eigen::Vector3d::Zero(), bound4 = Eigen::Vector3d::Zero();
  for (int k = 1; k <= s.harmonics(); ++k) {
    bound3 += (s.a().col(k - 1).cwiseAbs() + s.b().col(k - 1).cwiseAbs()) * std::pow(w * k, 2);
    bound4 += (s.a().col(k - 1).cwiseAbs() + s.b().col(k - 1).cwiseAbs()) * std::pow(w * k, 3);
  }
  Eigen::Vector3d q, qd, qdd, qp, qdp, qddp, qm, qdm, qddm;
  for (double t : {0.3, 1.7, 2.5, 4.2, 7.9}) {
    s.compute_state(t, q, qd, qdd);
    s.compute_state(t + h, qp, qdp, qddp);
    s.compute_state(t - h, qm, qdm, qddm);
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(qd[j], (qp[j] - qm[j]) / (2 * h), h * h / 6 * bound3[j] + 1e-10) << "t " << t << " joint " << j;
      EXPECT_NEAR(qdd[j], (qdp[j] - qdm[j]) / (2 * h), h * h / 6 * bound4[j] + 1e-10) << "t " << t << " joint " << j;
    }
  }
}

TEST(Excitation, CsvVelocityIsTheAnalyticDerivative) {
  const ExcitationTrajectory& r = small_design();
  rcm::test::TempDir dir("rcm_test_excite_");
  rcm::JointTrajectory out;
  out.source = "memory";
  out.time = r.time;
  out.position = r.position;
  out.velocity = r.velocity;
  rcm::save_joint_trajectory(dir.path() / "x.csv", out);
  const rcm::JointTrajectory in = rcm::load_joint_trajectory(dir.path() / "x.csv");
  ASSERT_EQ(in.num_joints(), 3);
  ASSERT_EQ(in.time.size(), r.time.size());
  // Written in the shortest round-trip form: read back exactly.
  EXPECT_EQ(in.position, r.position);
  EXPECT_EQ(in.velocity, r.velocity);
  // The velocity column is the derivative of the position column: against the
  // series at each time stamp, and against central differences of the file's
  // positions within their error h^2 / 6 max|q'''|.
  const ExcitationSeries& s = r.series;
  const double w = 2.0 * M_PI / s.period_s();
  Eigen::Vector3d bound3 = Eigen::Vector3d::Zero(), q, qd, qdd;
  for (int k = 1; k <= s.harmonics(); ++k)
    bound3 += (s.a().col(k - 1).cwiseAbs() + s.b().col(k - 1).cwiseAbs()) * std::pow(w * k, 2);
  const double h = in.time[1] - in.time[0];
  for (Eigen::Index t = 1; t + 1 < in.time.size(); ++t) {
    s.compute_state(in.time[t], q, qd, qdd);
    for (int j = 0; j < 3; ++j) {
      ASSERT_NEAR(in.velocity(t, j), qd[j], 1e-12) << "row " << t;
      const double fd = (in.position(t + 1, j) - in.position(t - 1, j)) / (in.time[t + 1] - in.time[t - 1]);
      ASSERT_NEAR(in.velocity(t, j), fd, h * h / 6 * bound3[j] + 1e-9) << "row " << t << " joint " << j;
    }
  }
}

TEST(Excitation, OptimisedRegressorIsBetterConditionedThanTheStartAndTheRandomTeleoperation) {
  ExcitationOptions o;  // the command's defaults (30 s at 200 Hz) with one harmonic less, for time
  o.harmonics = 4;
  const ExcitationTrajectory r = design_excitation(robot(), o);
  ASSERT_TRUE(r.summary.limits_satisfied);
  ASSERT_TRUE(std::isfinite(r.summary.condition_number));
  EXPECT_LT(r.summary.condition_number, r.summary.initial_condition_number) << r.summary.brief_report();
  // The simulator's default free-space recording (random teleoperation) of
  // the same duration, its true joint states, by the same function.
  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  config.protocol.free_space_s = o.duration_s;
  config.sensors.noise = false;
  const rcm::sim::SimulatedRecording teleop = rcm::sim::simulate_free_space(config);
  const double teleop_condition = compute_regressor_condition_number(
      teleop.truth.q, teleop.truth.qd, teleop.truth.qdd, get_excitation_dahl_displacement(r.limits));
  EXPECT_LT(r.summary.condition_number, teleop_condition);
  std::cout << "condition number over " << o.duration_s << " s at " << o.rate_hz
            << " Hz: optimised " << r.summary.condition_number << ", random start "
            << r.summary.initial_condition_number << ", random teleoperation " << teleop_condition << " ("
            << r.summary.brief_report() << ", " << r.summary.seconds << " s)\n";
  // Every joint reverses as often as asked, and moves to both sides of q0
  // (both are penalties: checked with some slack on the coverage).
  for (int j = 0; j < 3; ++j) {
    EXPECT_GE(r.reversals[static_cast<std::size_t>(j)], o.min_reversals * r.summary.periods) << "joint " << j;
    const double up = (r.position.col(j).maxCoeff() - o.q0[j]) / (r.limits.position_max[j] - o.q0[j]);
    const double down = (o.q0[j] - r.position.col(j).minCoeff()) / (o.q0[j] - r.limits.position_min[j]);
    EXPECT_GT(std::min(up, down), 0.5 * o.position_coverage) << "joint " << j << ": " << down << " / " << up;
  }
}

namespace {
// Per joint, the least share of the speed limit reached in either direction
// (column 0) and the share of the acceleration limit reached (column 1).
Eigen::Matrix<double, 3, 2> get_speed_reach(const ExcitationTrajectory& r) {
  Eigen::Matrix<double, 3, 2> reach;
  for (int j = 0; j < 3; ++j) {
    reach(j, 0) = std::min(r.velocity.col(j).maxCoeff(), -r.velocity.col(j).minCoeff()) / r.limits.velocity_max[j];
    reach(j, 1) = r.acceleration.col(j).cwiseAbs().maxCoeff() / r.limits.acceleration_max[j];
  }
  return reach;
}
}  // namespace

TEST(Excitation, SpeedCoverageDrivesEveryJointTowardItsSpeedLimits) {
  // Conditioning alone settles for a slow motion on some joint; the model's
  // regime is then the speeds it went through, and a faster teleoperation
  // leaves it.
  ExcitationOptions o;
  o.harmonics = 4;
  ExcitationOptions slow = o;
  slow.speed_coverage = 0.0;
  const ExcitationTrajectory covered = design_excitation(robot(), o), uncovered = design_excitation(robot(), slow);
  ASSERT_TRUE(covered.summary.limits_satisfied);
  const Eigen::Matrix<double, 3, 2> reach = get_speed_reach(covered), reach_without = get_speed_reach(uncovered);
  std::cout << "share of the speed limit (both ways) and acceleration limit reached, joints 1-3:\n"
            << reach << "\nwithout the coverage term:\n"
            << reach_without << "\n";
  EXPECT_GT(reach.sum(), reach_without.sum() + 0.1);
  // The speeds are within reach of every joint; the acceleration limits are
  // not, on the insertion's range at a 10 s period with 4 harmonics, and only
  // pull the motion toward them.
  for (int j = 0; j < 3; ++j) EXPECT_GT(reach(j, 0), 0.5 * o.speed_coverage) << "joint " << j;
}

TEST(Excitation, DeterministicForASeed) {
  const ExcitationTrajectory again = design_excitation(robot(), small_options());
  EXPECT_EQ(again.position, small_design().position);
  EXPECT_EQ(again.velocity, small_design().velocity);
  ExcitationOptions other = small_options();
  other.seed = 2;
  EXPECT_NE(design_excitation(robot(), other).position, small_design().position);
}

TEST(Excitation, BadOptionsAreRefused) {
  ExcitationOptions o = small_options();
  o.duration_s = 0.0;
  EXPECT_THROW(o.check(), std::invalid_argument);
  o.duration_s = std::nan("");
  EXPECT_THROW(o.check(), std::invalid_argument);
  o = small_options();
  o.speed_coverage = 1.5;
  EXPECT_THROW(o.check(), std::invalid_argument);
  o = small_options();
  o.harmonics = 1;
  EXPECT_THROW(o.check(), std::invalid_argument);
  o = small_options();
  o.q0 = Eigen::Vector3d(0.0, 0.0, 0.235);  // inside the robot's range, not inside the margin
  try {
    design_excitation(robot(), o);
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().field, "q0[2]") << e.what();
  }
}

TEST(JointTrajectoryCsv, ErrorsNameFileLineAndColumn) {
  const std::string good = "time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3\n"
                           "0,0,0,0.12,0,0,0\n";
  EXPECT_EQ(rcm::parse_joint_trajectory(good, "t.csv").num_samples(), 1u);
  try {
    rcm::parse_joint_trajectory(good + "0.005,0,abc,0.12,0,0,0\n", "t.csv");
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().file, "t.csv");
    EXPECT_EQ(e.where().line, 3u);
    EXPECT_EQ(e.where().field, "position_2") << e.what();
  }
  try {
    rcm::parse_joint_trajectory(good + "0,0,0,0.12,0,0,0\n", "t.csv");
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().line, 3u);
    EXPECT_EQ(e.where().field, "time") << e.what();
  }
  EXPECT_THROW(rcm::parse_joint_trajectory("time,position_1,position_2,position_3\n0,0,0,0\n", "t.csv"),
               rcm::InputError);
}

TEST(SampledPath, InterpolatesACubicExactlyAndHoldsAtTheEnds) {
  // Cubic Hermite interpolation reproduces a cubic from its values and slopes.
  auto f = [](double t) { return 1.0 + 2.0 * t - t * t + 0.5 * t * t * t; };
  auto df = [](double t) { return 2.0 - 2.0 * t + 1.5 * t * t; };
  auto ddf = [](double t) { return -2.0 + 3.0 * t; };
  const int n = 7;
  Eigen::VectorXd time(n);
  Eigen::MatrixXd q(n, 3), qd(n, 3);
  for (int i = 0; i < n; ++i) {
    time[i] = 5.0 + 0.3 * i + 0.01 * i * i;  // uneven steps, not starting at 0
    for (int j = 0; j < 3; ++j) {
      q(i, j) = (j + 1) * f(time[i] - 5.0);
      qd(i, j) = (j + 1) * df(time[i] - 5.0);
    }
  }
  const rcm::sim::SampledPath path(time, q, qd);
  for (double t : {0.05, 0.31, 0.77, 1.2, 1.9}) {
    const rcm::sim::ReferenceSample r = path.evaluate(t);
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(r.q[j], (j + 1) * f(t), 1e-12) << "t " << t;
      EXPECT_NEAR(r.qd[j], (j + 1) * df(t), 1e-11) << "t " << t;
      EXPECT_NEAR(r.qdd[j], (j + 1) * ddf(t), 1e-9) << "t " << t;
    }
  }
  const rcm::sim::ReferenceSample after = path.evaluate(100.0);
  EXPECT_EQ(after.q, q.row(n - 1).transpose());
  EXPECT_EQ(after.qd, Eigen::Vector3d::Zero());
  EXPECT_EQ(path.evaluate(-1.0).q, q.row(0).transpose());
}

TEST(ExciteCli, WritesACsvThatTheSimulatorPlays) {
  rcm::test::TempDir dir("rcm_test_excite_cli_");
  const auto csv = dir.path() / "excite.csv";
  std::string out;
  ASSERT_EQ(rcm::test::run_cli("excite --duration 6 --period 3 --harmonics 3 --max-iterations 20 --out " +
                                   csv.string() + " --json",
                               out, rcm::test::CliOutput::stdout_only),
            0)
      << out;
  const auto j = nlohmann::json::parse(out);
  EXPECT_TRUE(j["limits_satisfied"].get<bool>());
  EXPECT_GT(j["condition_number"].get<double>(), 1.0);
  ASSERT_EQ(j["joints"].size(), 3u);
  EXPECT_GE(j["joints"][0]["velocity_reversals"].get<int>(), 1);
  EXPECT_EQ(read_file(csv).substr(0, 20), "time,position_1,posi");
  const rcm::JointTrajectory trajectory = rcm::load_joint_trajectory(csv);
  EXPECT_EQ(trajectory.time.size(), 1201);
  // The text output names the condition number and the file.
  ASSERT_EQ(rcm::test::run_cli("excite --duration 6 --period 3 --harmonics 3 --max-iterations 5 --out " +
                                   (dir.path() / "b.csv").string(),
                               out),
            0)
      << out;
  EXPECT_NE(out.find("condition number"), std::string::npos) << out;
  EXPECT_NE(out.find("reversals"), std::string::npos) << out;

  // The simulator records its free space along it: a whole session, short.
  const auto session = dir.path() / "session";
  ASSERT_EQ(rcm::test::run_cli("simulate --free-space-trajectory " + csv.string() + " --out " + session.string() +
                                   " --trial-s 2 --calibration-s 2 --no-truth --json",
                               out, rcm::test::CliOutput::stdout_only),
            0)
      << out;
  const rcm::Recording free = rcm::load_recording(session / "free_space.csv");
  EXPECT_NEAR(free.time[free.time.size() - 1] - free.time[0], 6.0, 0.01);
  // It follows the file: the tracked positions stay near the trajectory's.
  const auto config = nlohmann::json::parse(read_file(session / "sim_config.json"));
  EXPECT_EQ(config["trajectory"]["free_space_path"], "file");
  double worst = 0.0;
  for (Eigen::Index t = 0; t < free.time.size(); t += 20) {
    const Eigen::Index k = std::min<Eigen::Index>(t, trajectory.time.size() - 1);
    worst = std::max(worst, std::abs(free.position(t, 0) - trajectory.position(k, 0)));
  }
  EXPECT_LT(worst, 0.02) << "yaw tracking error, rad";
}

TEST(ExciteCli, BadInputIsLocatedAndExitsNonZero) {
  rcm::test::TempDir dir("rcm_test_excite_bad_");
  const std::string out_flag = " --harmonics 3 --max-iterations 2 --out " + (dir.path() / "x.csv").string();
  std::string out;
  EXPECT_EQ(rcm::test::run_cli("excite --duration 0" + out_flag, out), 2) << out;
  EXPECT_NE(out.find("--duration"), std::string::npos) << out;
  EXPECT_NE(rcm::test::run_cli("excite --duration nan" + out_flag, out), 0) << out;
  EXPECT_NE(out.find("--duration"), std::string::npos) << out;
  EXPECT_EQ(rcm::test::run_cli("excite" + out_flag, out), 2) << out;
  EXPECT_NE(out.find("--duration"), std::string::npos) << out;
  EXPECT_EQ(rcm::test::run_cli("excite --duration 4 --q0 0,0,0.3" + out_flag, out), 2) << out;
  EXPECT_NE(out.find("--q0[2]"), std::string::npos) << out;
  EXPECT_EQ(rcm::test::run_cli("excite --duration 4 --harmonics 3 --max-iterations 2 --out " +
                                   (dir.path() / "missing" / "x.csv").string(),
                               out),
            2)
      << out;
  EXPECT_NE(out.find("x.csv"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "x.csv"));
  // The simulator names the file, line and column of a bad trajectory.
  const auto bad = dir.write("bad.csv",
                             "time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3\n"
                             "0,0,0,0.12,0,0,0\n0.005,0,x,0.12,0,0,0\n");
  EXPECT_EQ(rcm::test::run_cli("simulate --free-space-trajectory " + bad.string() + " --out " +
                                   (dir.path() / "s").string(),
                               out),
            2)
      << out;
  EXPECT_NE(out.find("bad.csv:3: column position_2"), std::string::npos) << out;
}
