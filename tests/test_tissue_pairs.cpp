// Tissue-law data: pairs CSV (located errors, exact round trip), pairs from a
// calibration recording against a recording built from a known force, binning,
// and the `rcm tissue fit` command (--pairs, --session with --model / measured).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <nlohmann/json.hpp>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/tissue/tissue_fit.hpp"
#include "rcm/tissue/tissue_pairs.hpp"

namespace fs = std::filesystem;

namespace {

fs::path make_temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("rcm_test_tissue_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream(path) << text;
}

// ---------------------------------------------------------------------------
// CSV

TEST(TissuePairsCsv, ParsesAnyColumnOrderAndIgnoresOthers) {
  const auto p = rcm::parse_tissue_pairs("note,y,x\na,1.5,0.01\n\nb,3.0,0.02\n", "p.csv");
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p.x[1], 0.02);
  EXPECT_EQ(p.y[0], 1.5);
  EXPECT_EQ(p.origin[1], 4u);  // source line, blank line counted
}

TEST(TissuePairsCsv, ErrorsNameFileLineAndColumn) {
  auto expect_error = [](const std::string& text, std::size_t line, const std::string& field,
                         const std::string& needle) {
    try {
      rcm::parse_tissue_pairs(text, "pairs.csv");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const rcm::InputError& e) {
      EXPECT_EQ(e.where().file, "pairs.csv");
      EXPECT_EQ(e.where().line, line) << e.what();
      EXPECT_EQ(e.where().field, field) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error("x,y\n0.01,2\n0.02,abc\n", 3, "y", "'abc'");
  expect_error("x,y\n0.01,2\nnan,3\n", 3, "x", "finite");
  expect_error("x,y\n0.01,2\n0.02,inf\n", 3, "y", "finite");
  expect_error("x,y\n0.01,\n", 2, "y", "empty cell");
  expect_error("x,force\n0.01,2\n", 1, "y", "missing column");
  expect_error("x,y\n0.01,2,7\n", 2, "", "expected 2 cells");
  expect_error("x,y\n0.01,1e999\n", 2, "y", "1e999");
  EXPECT_THROW(rcm::parse_tissue_pairs("", "e.csv"), rcm::InputError);
  EXPECT_THROW(rcm::parse_tissue_pairs("x,y\n", "e.csv"), rcm::InputError);
}

TEST(TissuePairsCsv, SaveLoadRoundTripIsExact) {
  const fs::path dir = make_temp_dir("csv");
  rcm::TissuePairs p;
  p.x = Eigen::VectorXd::LinSpaced(50, 0.001, 0.03);
  p.y = p.x.array().sin() * 1234.5678 + 0.1;
  rcm::save_tissue_pairs(dir / "p.csv", p);
  const auto back = rcm::load_tissue_pairs(dir / "p.csv");
  ASSERT_EQ(back.size(), p.size());
  for (Eigen::Index i = 0; i < p.x.size(); ++i) {
    EXPECT_EQ(back.x[i], p.x[i]);
    EXPECT_EQ(back.y[i], p.y[i]);
  }
  EXPECT_THROW(rcm::load_tissue_pairs(dir / "missing.csv"), rcm::InputError);
  fs::remove_all(dir);
}

TEST(TissuePairs, BinningAveragesEqualCountGroups) {
  rcm::TissuePairs p;
  p.x = Eigen::VectorXd(6);
  p.y = Eigen::VectorXd(6);
  p.x << 5, 1, 3, 2, 6, 4;
  p.y << 50, 10, 30, 20, 60, 40;
  const auto b = rcm::compute_binned_pairs(p, 3);
  ASSERT_EQ(b.size(), 3u);
  EXPECT_DOUBLE_EQ(b.x[0], 1.5);
  EXPECT_DOUBLE_EQ(b.y[0], 15.0);
  EXPECT_DOUBLE_EQ(b.x[2], 5.5);
  EXPECT_DOUBLE_EQ(b.y[2], 55.0);
  const auto sorted = rcm::compute_binned_pairs(p, 0);
  EXPECT_DOUBLE_EQ(sorted.x[0], 1.0);
  EXPECT_DOUBLE_EQ(sorted.y[5], 60.0);
}

// ---------------------------------------------------------------------------
// Pairs from a recording

// A calibration sweep about q0 = [0, 0, 0.12]: q1, q2 trace a Lissajous figure
// up to ~0.6 rad, passing through q0 (theta = 0) at t = 0.
struct Sweep {
  rcm::Recording recording;
  Eigen::MatrixXd f_true;  // T x 3, the force on the tissue
};

Eigen::Vector3d tangential_direction(const Eigen::Vector3d& q) {
  // Any direction works for the identity f = J^-T J^T f; use one orthogonal to
  // the shaft as the stretched incision would.
  const Eigen::Vector3d z = rcm::compute_z3_base(q);
  Eigen::Vector3d u = z.cross(Eigen::Vector3d(0.3, 1.0, 0.2));
  return u.normalized();
}

Sweep make_sweep(int T, double D, const std::function<double(double)>& g,
                 const std::function<Eigen::Vector3d(int, const Eigen::Vector3d&)>& tau_fs_of) {
  Sweep s;
  rcm::Recording& r = s.recording;
  r.source = "calibration.csv";
  r.time = Eigen::VectorXd::LinSpaced(T, 0.0, (T - 1) / 1500.0);
  r.position.resize(T, 3);
  r.velocity.resize(T, 3);
  r.effort.resize(T, 3);
  s.f_true.resize(T, 3);
  const Eigen::Vector3d q0(0.0, 0.0, 0.12);
  const rcm::IncisionFrame inc = rcm::make_incision_frame(q0);
  for (int t = 0; t < T; ++t) {
    const double ph = 2.0 * M_PI * t / T;
    const Eigen::Vector3d q(0.6 * std::sin(ph), 0.5 * std::sin(2.0 * ph), 0.12 + 0.01 * std::sin(3.0 * ph));
    const Eigen::Vector3d qd(0.6 * std::cos(ph), 1.0 * std::cos(2.0 * ph), 0.03 * std::cos(3.0 * ph));
    r.position.row(t) = q.transpose();
    r.velocity.row(t) = qd.transpose() * (2.0 * M_PI / T * 1500.0);
    const double theta = rcm::compute_pivot_angle(inc, q);
    const Eigen::Vector3d f = g(D * std::tan(theta)) * tangential_direction(q);
    s.f_true.row(t) = f.transpose();
    const double sd = rcm::compute_shaft_distance(inc, q, D);
    const Eigen::Matrix3d J = rcm::compute_incision_jacobian(q, sd);
    r.effort.row(t) = (tau_fs_of(t, q) + J.transpose() * f).transpose();
  }
  rcm::validate_recording(r);
  return s;
}

TEST(TissuePairs, RecoverTheForceMagnitudeAndXFromTheRecording) {
  const double D = 0.03;
  auto g = [](double x) { return 788.0 * x; };
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0.0, 0.3);
  Eigen::MatrixXd tau_fs(600, 3);
  for (int t = 0; t < 600; ++t) tau_fs.row(t) << n(rng), n(rng), n(rng);
  const Sweep s = make_sweep(600, D, g, [&](int t, const Eigen::Vector3d&) {
    return Eigen::Vector3d(tau_fs.row(t).transpose());
  });
  const Eigen::Vector3d q0(0.0, 0.0, 0.12);
  const auto result = rcm::compute_tissue_pairs(s.recording, tau_fs, q0, D);
  EXPECT_EQ(result.report.samples, 600u);
  EXPECT_GT(result.report.dropped_small_theta, 0u);  // the sweep passes through q0
  EXPECT_EQ(result.report.kept + result.report.dropped_small_theta + result.report.dropped_singular +
                result.report.dropped_ill_conditioned + result.report.dropped_non_finite,
            600u);
  ASSERT_GT(result.report.kept, 400u);
  const rcm::IncisionFrame inc = rcm::make_incision_frame(q0);
  for (std::size_t i = 0; i < result.pairs.size(); ++i) {
    const std::size_t t = result.pairs.origin[i];  // in-memory: sample index
    const Eigen::Vector3d q = s.recording.position.row(static_cast<Eigen::Index>(t)).transpose();
    const double theta = rcm::compute_pivot_angle(inc, q);
    EXPECT_GE(theta, rcm::TissuePairOptions{}.min_theta_rad);
    EXPECT_NEAR(result.pairs.x[static_cast<Eigen::Index>(i)], D * std::tan(theta), 1e-15);
    EXPECT_NEAR(result.pairs.y[static_cast<Eigen::Index>(i)],
                s.f_true.row(static_cast<Eigen::Index>(t)).norm(), 1e-9);
  }
  // The fit on these exact pairs is the law.
  const auto fit = rcm::fit_tissue_law(result.pairs);
  EXPECT_EQ(fit.best().expression.get_skeleton(), "C*x");
  EXPECT_NEAR(fit.best().expression.get_leading_coefficient(), 788.0, 1e-6);

  // Measured-force pairs agree with the estimated ones.
  rcm::Recording with_force = s.recording;
  with_force.force = s.f_true;
  const auto measured = rcm::compute_tissue_pairs_from_measured_force(with_force, q0, D);
  EXPECT_EQ(measured.report.kept, result.report.kept);
  EXPECT_NEAR((measured.pairs.y - result.pairs.y).cwiseAbs().maxCoeff(), 0.0, 1e-9);
}

TEST(TissuePairs, RejectsMismatchedTorquesAndMissingOffset) {
  const Sweep s = make_sweep(100, 0.03, [](double x) { return x; },
                             [](int, const Eigen::Vector3d&) { return Eigen::Vector3d::Zero(); });
  const Eigen::Vector3d q0(0.0, 0.0, 0.12);
  EXPECT_THROW(rcm::compute_tissue_pairs(s.recording, Eigen::MatrixXd::Zero(99, 3), q0, 0.03), rcm::InputError);
  EXPECT_THROW(rcm::compute_tissue_pairs(s.recording, Eigen::MatrixXd::Zero(100, 2), q0, 0.03), rcm::InputError);
  Eigen::MatrixXd bad = Eigen::MatrixXd::Zero(100, 3);
  bad(7, 1) = std::nan("");
  try {
    rcm::compute_tissue_pairs(s.recording, bad, q0, 0.03);
    FAIL();
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().field, "tau_fs_2");
  }
  EXPECT_THROW(rcm::compute_tissue_pairs(s.recording, Eigen::MatrixXd::Zero(100, 3), q0, 0.0), rcm::InputError);
  EXPECT_THROW(rcm::compute_tissue_pairs_from_measured_force(s.recording, q0, 0.03), rcm::InputError);
}

// ---------------------------------------------------------------------------
// CLI

struct CommandResult {
  int status = 0;
  std::string out, err;
};

CommandResult run_cli(const std::string& args, const fs::path& dir) {
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string cmd =
      std::string(RCM_CLI_PATH) + " " + args + " > " + out.string() + " 2> " + err.string();
  const int raw = std::system(cmd.c_str());
  CommandResult r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  std::ifstream fo(out), fe(err);
  r.out.assign(std::istreambuf_iterator<char>(fo), {});
  r.err.assign(std::istreambuf_iterator<char>(fe), {});
  return r;
}

TEST(TissueCli, FitsPairsAndPrintsTheContractJson) {
  const fs::path dir = make_temp_dir("cli_pairs");
  std::string csv = "x,y\n";
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n(0.0, 0.5);
  for (int i = 0; i < 400; ++i) {
    const double x = 0.002 + 0.028 * i / 399.0;
    csv += std::to_string(x) + "," + std::to_string(788.0 * x + n(rng)) + "\n";
  }
  write_text(dir / "pairs.csv", csv);
  const auto r = run_cli("tissue fit --pairs " + (dir / "pairs.csv").string() +
                             " --offset 0.03 --out " + (dir / "law.json").string() + " --json",
                         dir);
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);  // exactly one JSON object
  ASSERT_TRUE(j.contains("front") && j["front"].is_array() && !j["front"].empty());
  for (const auto& e : j["front"]) {
    for (const char* key : {"complexity", "loss", "score", "expression"}) EXPECT_TRUE(e.contains(key)) << key;
  }
  EXPECT_EQ(j["best"]["complexity"], 3);
  EXPECT_NE(j["best"]["expression"].get<std::string>().find("*x"), std::string::npos);
  EXPECT_NEAR(j["sensitivity"]["leading_coefficient_min"].get<double>(), 788.0 * 0.03 / 0.033, 10.0);
  EXPECT_NEAR(j["sensitivity"]["leading_coefficient_max"].get<double>(), 788.0 * 0.03 / 0.027, 12.0);
  EXPECT_TRUE(fs::exists(dir / "law.json"));

  // Human output has the table and the three exports.
  const auto text = run_cli("tissue fit --pairs " + (dir / "pairs.csv").string(), dir);
  ASSERT_EQ(text.status, 0) << text.err;
  EXPECT_NE(text.out.find("<- best"), std::string::npos);
  EXPECT_NE(text.out.find("latex"), std::string::npos);
  fs::remove_all(dir);
}

TEST(TissueCli, BadInputGivesALocatedMessageAndExitTwo) {
  const fs::path dir = make_temp_dir("cli_bad");
  write_text(dir / "bad.csv", "x,y\n0.01,1\n0.02,oops\n");
  const auto r = run_cli("tissue fit --pairs " + (dir / "bad.csv").string(), dir);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("bad.csv:3"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("'oops'"), std::string::npos) << r.err;
  const auto none = run_cli("tissue fit", dir);
  EXPECT_NE(none.status, 0);
  fs::remove_all(dir);
}

// A session whose calibration effort is a known free-space model's prediction
// plus J_D*^T f for f = g(D* tan theta) u: --session --model must find g.
TEST(TissueCli, FitsFromASessionWithAFreeSpaceModel) {
  const fs::path dir = make_temp_dir("cli_session");
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 1.0 / 1500.0;
  rcm::dynamics::LinearTorqueParameters p;
  p.gravity = Eigen::VectorXd::LinSpaced(rcm::dynamics::LinearTorqueModel::kGravityTerms, -0.2, 0.3);
  p.armature = Eigen::Vector3d(0.01, 0.02, 0.5);
  p.viscous = Eigen::Vector3d(0.05, 0.04, 1.0);
  p.coulomb = Eigen::Vector3d(0.02, 0.03, 0.4);
  p.offset = Eigen::Vector3d(0.01, -0.01, 0.2);
  p.dahl_displacement = Eigen::Vector3d(0.01, 0.01, 0.001);
  const rcm::dynamics::LinearTorqueModel model(info, p);
  rcm::dynamics::save_torque_model(dir / "model.json", model);

  const double D = 0.03;
  auto g = [](double x) { return 2.0 * (std::exp(80.0 * x) - 1.0); };
  Sweep s = make_sweep(3000, D, g, [](int, const Eigen::Vector3d&) { return Eigen::Vector3d::Zero(); });
  const Eigen::MatrixXd tau_fs = rcm::dynamics::predict_torque(model, s.recording);
  s.recording.effort += tau_fs.leftCols(3);
  s.recording.force = s.f_true;
  rcm::save_recording(dir / "calibration.csv", s.recording);
  rcm::save_recording(dir / "free.csv", s.recording);
  write_text(dir / "session.json", R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic",
    "q0": [0.0, 0.0, 0.12], "free_space": ["free.csv"],
    "calibration": {"recording": "calibration.csv", "coaxial_offset_m": 0.03}})");

  const auto r = run_cli("tissue fit --session " + (dir / "session.json").string() + " --model " +
                             (dir / "model.json").string() + " --delta 0 --json --write-pairs " +
                             (dir / "pairs.csv").string(),
                         dir);
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["best"]["complexity"], 8) << j["best"]["expression"];
  const auto& terms = j["law"]["model"]["terms"];
  ASSERT_EQ(terms.size(), 1u);
  EXPECT_EQ(terms[0]["kind"], "exp(b*x)");
  EXPECT_NEAR(terms[0]["scale"].get<double>(), 80.0, 1e-3);
  EXPECT_NEAR(terms[0]["coefficient"].get<double>(), 2.0, 1e-4);
  EXPECT_GT(j["pairs"]["dropped_small_theta"].get<int>(), 0);
  EXPECT_EQ(rcm::load_tissue_pairs(dir / "pairs.csv").size(), j["pairs"]["kept"].get<std::size_t>());

  // The sensor reference path gives the same law.
  const auto m = run_cli("tissue fit --session " + (dir / "session.json").string() +
                             " --force-source measured --delta 0 --json",
                         dir);
  ASSERT_EQ(m.status, 0) << m.err;
  EXPECT_EQ(nlohmann::json::parse(m.out)["best"]["complexity"], 8);

  // Without a model the estimated path says what is missing.
  const auto missing = run_cli("tissue fit --session " + (dir / "session.json").string(), dir);
  EXPECT_EQ(missing.status, 2);
  EXPECT_NE(missing.err.find("--model"), std::string::npos) << missing.err;
  fs::remove_all(dir);
}

}  // namespace
