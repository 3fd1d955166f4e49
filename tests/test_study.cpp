// The whole study (rcm run) against the simulator's ground truth: signs,
// accuracy, the results contract, the report, and CLI errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/common/text_file.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"
#include "test_dynamics_synthetic.hpp"
#include "statistical_test.hpp"

namespace fs = std::filesystem;

namespace {

// A small bench: 3 min of free space and the paper's protocol on 40 s trials at
// D = 20 and 40 mm, with and without a radial offset.
// The small bench: tests/data/study_bench_config.json over the defaults.
rcm::sim::SimConfig make_small_config() {
  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  const fs::path file = fs::path(RCM_SOURCE_DIR) / "tests" / "data" / "study_bench_config.json";
  rcm::sim::apply_config_json(config, rcm::load_json_file(file), file.string());
  return config;
}

struct Bench {
  fs::path dir;
  rcm::Session session;
};

// The small bench: the ctest fixture's (study_test_session, simulated once per
// run), or simulated here when the program runs on its own. `dir` is this
// process's own folder for what the tests write.
const Bench& bench() {
  static const Bench b = [] {
    Bench out;
    std::random_device rd;
    out.dir = fs::temp_directory_path() / ("rcm_test_study_" + std::to_string(rd()));
    static const fs::path cleanup_dir = out.dir;
    std::atexit([] {
      std::error_code ec;
      fs::remove_all(cleanup_dir, ec);
    });
    const fs::path fixture = fs::path(RCM_STUDY_TEST_DIR) / "session.json";
    if (fs::exists(fixture)) {
      fs::create_directories(out.dir);
      out.session = rcm::load_session(fixture);
    } else {
      out.session = rcm::load_session(rcm::sim::simulate_session(make_small_config(), out.dir).manifest);
    }
    return out;
  }();
  return b;
}

// The paper's method alone; the tests of the joint method ask for it.
rcm::StudyOptions linear_options() {
  rcm::StudyOptions o;
  o.method = "three-step";
  o.model_kind = rcm::dynamics::TorqueModelKind::linear;
  o.verbose = false;
  o.fit.verbose = false;
  return o;
}

// The joint method with fewer bootstrap replicates and no D* +- 3 mm tissue refits.
rcm::StudyOptions quick_joint_options() {
  rcm::StudyOptions o = linear_options();
  o.method = "joint";
  o.joint.bootstrap_replicates = 20;
  o.joint.calibration_bootstrap_replicates = 10;
  o.tissue_sensitivity_delta_m = 0.0;
  return o;
}

rcm::TorqueModelFitter linear_fitter() { return rcm::get_linear_torque_model_fitter(); }

const rcm::StudyResult& study() {
  static const rcm::StudyResult r = rcm::run_study(bench().session, linear_options(), linear_fitter());
  return r;
}

// The fitter of rcm::core alone (what a program without rcm::torch passes to
// run_study): the linear model, exactly as fit_linear_torque_model fits it, and
// an InputError naming StudyOptions::model_kind for the networks.
TEST(Study, LinearFitterFitsTheLinearModelAndRefusesTheNetworks) {
  rcm::test::SyntheticArmOptions arm;
  arm.duration_s = 30.0;
  const std::vector<rcm::Recording> recordings{rcm::test::make_synthetic_free_space(arm)};
  rcm::dynamics::FitOptions options;
  options.verbose = false;
  const rcm::TorqueModelFitter fitter = rcm::get_linear_torque_model_fitter();
  const rcm::dynamics::FitResult fit = fitter(rcm::dynamics::TorqueModelKind::linear, recordings, options);
  ASSERT_TRUE(fit.model);
  EXPECT_EQ(fit.model->kind(), rcm::dynamics::TorqueModelKind::linear);
  const rcm::dynamics::FitResult direct = rcm::dynamics::fit_linear_torque_model(recordings, options);
  // The same parameters (the file's "training" part records the fit's duration too).
  EXPECT_EQ(rcm::dynamics::torque_model_to_json(*fit.model)["parameters"].dump(),
            rcm::dynamics::torque_model_to_json(*direct.model)["parameters"].dump());
  for (const auto kind : {rcm::dynamics::TorqueModelKind::lstm, rcm::dynamics::TorqueModelKind::mlp,
                          rcm::dynamics::TorqueModelKind::hybrid}) {
    try {
      fitter(kind, recordings, options);
      ADD_FAILURE() << rcm::dynamics::to_string(kind) << " was fitted";
    } catch (const rcm::InputError& e) {
      EXPECT_EQ(e.where().field, "model_kind");
      EXPECT_NE(std::string(e.what()).find(rcm::dynamics::to_string(kind)), std::string::npos) << e.what();
    }
  }
}

TEST(Study, RecoversSimulatedMisalignmentsWithTheRightSigns) {
  const rcm::StudyResult& r = study();
  ASSERT_EQ(r.trials.size(), 4u);
  for (const auto& t : r.trials) {
    ASSERT_TRUE(t.truth_m);
    const Eigen::Vector3d truth = *t.truth_m, est = t.estimate.misalignment_m;
    EXPECT_TRUE(t.estimate.solver.converged) << t.name << ": " << t.estimate.solver.brief_report();
    // The paper's bound for D > 20 mm is 4.2 +- 2.1 mm on average; the radial
    // part must point the right way (a flipped sign would miss by ~36 mm).
    const double bound = truth[2] > 0.030 ? 0.004 : 0.010;
    EXPECT_LT((est - truth).norm(), bound) << t.name << ": " << est.transpose();
    if (truth.head<2>().norm() > 0) EXPECT_GT(est.head<2>().dot(truth.head<2>()), 0.5 * truth.head<2>().squaredNorm()) << t.name;
    ASSERT_TRUE(t.force_rmse);
  }
  // The tissue law found on the calibration is the simulator's linear law.
  EXPECT_EQ(r.tissue.best().expression.get_skeleton(), "C*x");
}

// Beyond the paper: all three offsets in torque space, with intervals.
TEST(Study, JointMethodRecoversOffsetsWithCoveringIntervals) {
  rcm::StudyOptions o = quick_joint_options();
  o.static_step = rcm::StaticStep::last_hold;  // the paper's three-step, to compare with
  const rcm::StudyResult r = rcm::run_study(bench().session, o, linear_fitter());
  ASSERT_TRUE(r.joint_tissue);
  EXPECT_EQ(r.joint_tissue->family, "linear");
  int covered = 0;
  for (const auto& t : r.trials) {
    ASSERT_TRUE(t.joint && t.truth_m);
    const Eigen::Vector3d e = t.joint->misalignment_m - *t.truth_m;
    EXPECT_LT(e.norm(), 0.0015) << t.name << ": " << t.joint->misalignment_m.transpose();
    EXPECT_LT(e.norm(), *t.get_three_step_error_m()) << t.name;  // beats the paper's method on the same data
    EXPECT_TRUE((t.joint->ci_low.array() < t.joint->ci_high.array()).all());
    covered += ((t.truth_m->array() >= t.joint->ci_low.array()) && (t.truth_m->array() <= t.joint->ci_high.array())).all();
  }
  EXPECT_GE(covered, 3);
  const nlohmann::json j = r.to_json();
  EXPECT_EQ(j["method"], "joint");
  EXPECT_TRUE(j["trials"][0]["joint"]["ci95_low_m"].is_array());
  EXPECT_TRUE(j["trials"][0]["three_step"]["misalignment_m"].is_array());
}

// The online estimator on the same trials, streamed sample by sample: it must
// find what the batch finds, settle early, and stay quiet in free space.
TEST(Study, OnlineEstimatorTracksEveryTrialAndStaysQuietInFreeSpace) {
  const rcm::MonitorSetup setup = rcm::prepare_monitor(bench().session, linear_options(), linear_fitter());
  const rcm::OnlinePipeline pipeline(setup.free_space.model, rcm::OnlineEstimator(setup.incision, setup.tissue,
                                                                                  rcm::make_online_options(setup.joint_options)));
  auto stream = [&](const rcm::Recording& r, std::vector<Eigen::Vector3d>* trace) {
    auto ws = pipeline.create_workspace();
    for (Eigen::Index t = 0; t < r.time.size(); ++t) {
      const Eigen::VectorXd q = r.position.row(t), qd = r.velocity.row(t), e = r.effort.row(t);
      const rcm::OnlineOutput& out = pipeline.compute_sample(ws, r.time(t), q.data(), qd.data(), e.data());
      if (trace) trace->push_back(out.misalignment_m);
    }
    return rcm::get_online_output(ws.estimator);
  };
  for (const auto& spec : bench().session.trials) {
    const rcm::Recording r = rcm::load_recording(spec.recording);
    std::vector<Eigen::Vector3d> trace;
    const rcm::OnlineOutput out = stream(r, &trace);
    ASSERT_TRUE(spec.truth_misalignment_m);
    EXPECT_LT((out.misalignment_m - *spec.truth_misalignment_m).norm(), 0.0015)
        << spec.name << ": " << out.misalignment_m.transpose();
    EXPECT_TRUE(out.onset) << spec.name;
    // Within 5 mm of the final value from 20 s of motion on (the trials move from their start).
    for (Eigen::Index t = 0; t < r.time.size(); ++t)
      if (r.time(t) - r.time(0) >= 20.0) {
        ASSERT_LT((trace[static_cast<std::size_t>(t)] - out.misalignment_m).norm(), 0.005) << spec.name << " at " << r.time(t);
      }
  }
  const rcm::OnlineOutput free = stream(rcm::load_recording(bench().session.free_space.front()), nullptr);
  EXPECT_FALSE(free.onset) << "cusum " << free.cusum;
  EXPECT_LT(free.misalignment_m.head<2>().norm(), 0.003) << free.misalignment_m.transpose();
}

// The default bench (the real preset's friction, each trial its own
// teleoperation) on two seeds and the three tissue laws of the worst-case
// tables (docs/validation.md): the joint estimator's mean error per seed and
// law, on the worst of them, within the targets of the 15-minute bench (0.5 mm
// for D > 20 mm, 1.0 mm below) on this 3-minute one, online within 1.5 mm, the
// stiffening law found as such and the sliding law's axial friction, and the
// intervals covering.
TEST(Study, JointMethodWorstSeedOverTheTissueLaws) {
  RCM_STATISTICAL_TEST();
  int covered = 0, trials = 0;
  double worst_far = 0.0, worst_near = 0.0;
  for (const std::uint64_t seed : {21u, 22u}) {
    for (const std::string preset : {"linear", "stiffening", "sliding"}) {
      std::random_device rd;
      const fs::path dir = fs::temp_directory_path() / ("rcm_test_study_" + preset + std::to_string(rd()));
      rcm::sim::SimConfig config = make_small_config();
      ASSERT_EQ(config.friction_preset, "real");
      rcm::sim::apply_tissue_preset(config.tissue, preset);
      config.seed = seed;
      config.protocol.coaxial_offsets_m = {0.015, 0.040};
      const auto written = rcm::sim::simulate_session(config, dir);
      const rcm::StudyResult r = rcm::run_study(rcm::load_session(written.manifest), quick_joint_options(),
                                                linear_fitter());
      ASSERT_TRUE(r.joint_tissue);
      if (preset == "stiffening") EXPECT_EQ(r.joint_tissue->family, "stiffening") << seed;
      if (preset == "sliding") EXPECT_GT(r.joint_tissue->parameters[3], 0.1) << seed << ": axial friction, N";
      double far = 0.0, near = 0.0;
      int n_far = 0, n_near = 0;
      for (const auto& t : r.trials) {
        ASSERT_TRUE(t.joint && t.online && t.truth_m);
        const double e = (t.joint->misalignment_m - *t.truth_m).norm();
        ((*t.truth_m)[2] > 0.020 ? far : near) += e;
        ++((*t.truth_m)[2] > 0.020 ? n_far : n_near);
        EXPECT_LT((t.online->final_output.misalignment_m - *t.truth_m).norm(), 0.0015) << preset << " " << t.name;
        const bool inside =
            ((t.truth_m->array() >= t.joint->ci_low.array()) && (t.truth_m->array() <= t.joint->ci_high.array())).all();
        covered += inside;
        ++trials;
        if (!inside)
          std::cerr << seed << " " << preset << " " << t.name << ": truth outside " << t.joint->ci_low.transpose()
                    << " .. " << t.joint->ci_high.transpose() << "\n";
      }
      worst_far = std::max(worst_far, far / n_far);
      worst_near = std::max(worst_near, near / n_near);
      std::cerr << "seed " << seed << ", " << preset << ": mean e " << 1e3 * far / n_far << " / "
                << 1e3 * near / n_near << " mm\n";
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  }
  EXPECT_LT(worst_far, 0.0005);
  EXPECT_LT(worst_near, 0.0010);
  // 95 % intervals on 24 trials: 20 or fewer inside would happen with honest
  // intervals less than 3 % of the time.
  EXPECT_GE(covered, 21) << "of " << trials;
}

// A bench whose joints hold whatever friction their last motion left (the
// hysteretic preset, the real Classic PSM's band), on a handful of seeds: the
// joint method stays accurate with intervals that cover the truth, and the
// balanced static step beats the paper's last hold on the same fitted model.
TEST(Study, HystereticFrictionJointIntervalsCoverAndBalancedHoldsBeatTheLastHold) {
  RCM_STATISTICAL_TEST();
  int trials = 0;
  Eigen::Vector3i covered = Eigen::Vector3i::Zero();
  double e_balanced = 0.0, e_last = 0.0, e_joint_max = 0.0;
  for (const std::uint64_t seed : {11u, 12u, 13u}) {
    std::random_device rd;
    const fs::path dir = fs::temp_directory_path() / ("rcm_test_study_hysteretic_" + std::to_string(rd()));
    rcm::sim::SimConfig config = make_small_config();
    rcm::sim::apply_friction_preset(config, "hysteretic");
    config.seed = seed;
    config.protocol.static_approaches = 2;
    const rcm::Session session = rcm::load_session(rcm::sim::simulate_session(config, dir).manifest);
    rcm::StudyOptions o = quick_joint_options();
    const rcm::StudyResult joint = rcm::run_study(session, o, linear_fitter());
    o.method = "three-step";
    o.static_step = rcm::StaticStep::last_hold;
    const rcm::StudyResult last = rcm::run_study(session, o, linear_fitter());
    ASSERT_EQ(joint.trials.size(), last.trials.size());
    for (std::size_t i = 0; i < joint.trials.size(); ++i) {
      const rcm::TrialOutcome& t = joint.trials[i];
      ASSERT_TRUE(t.joint && t.truth_m && t.hold);
      EXPECT_EQ(t.hold->holds.size(), 2u) << t.name;
      EXPECT_TRUE(t.hold->direction_balanced[0] && t.hold->direction_balanced[1]) << t.name;
      e_joint_max = std::max(e_joint_max, *t.get_error_m());
      e_balanced += *t.get_three_step_error_m();
      e_last += *last.trials[i].get_three_step_error_m();
      for (int a = 0; a < 3; ++a)
        covered[a] += (*t.truth_m)[a] >= t.joint->ci_low[a] && (*t.truth_m)[a] <= t.joint->ci_high[a];
      ++trials;
    }
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::cerr << "hysteretic bench, " << trials << " trials: joint max e " << 1e3 * e_joint_max
            << " mm; three-step mean e balanced " << 1e3 * e_balanced / trials << " mm, last hold "
            << 1e3 * e_last / trials << " mm; covered " << covered.transpose() << "\n";
  EXPECT_LT(e_joint_max, 0.001);
  // Beats it, not by more: the default model's slow pitch and insertion states
  // span an eighth of their travel (the real arm's friction builds over the
  // stroke), which the short approaches of the holds leave unsettled and the
  // simulated arm's friction does not have.
  EXPECT_LT(e_balanced, 0.85 * e_last) << "mean three-step error, balanced " << 1e3 * e_balanced / trials
                                      << " mm, last hold " << 1e3 * e_last / trials << " mm";
  // 12 trials per axis: with honest 95 % intervals 10 or more are inside 98 % of the time.
  for (int a = 0; a < 3; ++a) EXPECT_GE(covered[a], 10) << "axis " << a << " of " << trials;
}

// A free-space model off its regime: the free-space recording is of the arm
// without the 200 g that the instrument carries when docked. Without the
// calibration's correction, the aligned baseline shows the missing weight along
// the shaft at q0, and the joint intervals on D grow with the error it causes
// instead of staying as narrow as on the matched bench. (The payload's gravity
// torque on yaw and pitch grows with the pivot angle and is zero at q0: the
// baseline cannot see that part.) With it (the default), the calibration takes
// part of the missing weight as the model's torque offset on the insertion and
// no estimate gets worse; the rest grows with the pivot as the tissue's torque
// does, and a calibration at one offset cannot tell it from the tissue law
// (docs/methods.md, "Correcting the free-space model's bias").
TEST(Study, JointIntervalsWidenWhenTheFreeSpaceModelMissesAPayload) {
  RCM_STATISTICAL_TEST();  // three studies: the code paths of the tests above, the coverage of a bench
  std::random_device rd;
  const fs::path dir = fs::temp_directory_path() / ("rcm_test_study_payload_" + std::to_string(rd()));
  rcm::sim::SimConfig config = make_small_config();
  const rcm::Session matched = rcm::load_session(rcm::sim::simulate_session(config, dir / "light").manifest);
  config.arm.insertion_stage.mass_kg += 0.2;
  rcm::Session payload = rcm::load_session(rcm::sim::simulate_session(config, dir / "heavy").manifest);
  payload.free_space = matched.free_space;
  rcm::StudyOptions o = quick_joint_options();
  o.joint.fit_torque_offset = false;
  const rcm::StudyResult r_matched = rcm::run_study(matched, o, linear_fitter());
  const rcm::StudyResult r = rcm::run_study(payload, o, linear_fitter());
  ASSERT_TRUE(r.baseline_hold) << r.baseline_message;
  // 0.2 kg x 9.81 m/s^2 along the vertical shaft at q0, against the insertion axis.
  EXPECT_NEAR(r.baseline_hold->get_dtau()[2], -0.2 * 9.81, 0.3);
  ASSERT_TRUE(r_matched.baseline_hold);
  EXPECT_LT(std::abs(r_matched.baseline_hold->get_dtau()[2]), 0.2);
  double worst_D_error = 0.0;
  int covered_D = 0;
  for (std::size_t i = 0; i < r.trials.size(); ++i) {
    const rcm::TrialOutcome &t = r.trials[i], &m = r_matched.trials[i];
    ASSERT_TRUE(t.joint && m.joint && t.truth_m);
    const double truth_D = (*t.truth_m)[2];
    worst_D_error = std::max(worst_D_error, std::abs(t.joint->misalignment_m[2] - truth_D));
    covered_D += truth_D >= t.joint->ci_low[2] && truth_D <= t.joint->ci_high[2];
    EXPECT_TRUE(truth_D >= m.joint->ci_low[2] && truth_D <= m.joint->ci_high[2]) << "matched " << m.name;
    // Several times wider: the matched bench's own intervals hold its held-out
    // self-check, and the baseline sees the payload only at q0.
    EXPECT_GT(t.joint->ci_high[2] - t.joint->ci_low[2], 5.0 * (m.joint->ci_high[2] - m.joint->ci_low[2])) << t.name;
  }
  EXPECT_GT(worst_D_error, 0.002) << "the payload must matter for this test to mean anything";
  EXPECT_GE(covered_D, 2) << "of " << r.trials.size();
  // The streamed trials say the torque residual is not what the models explain.
  int residual_flagged = 0;
  for (std::size_t i = 0; i < r.trials.size(); ++i) {
    const std::size_t bit = rcm::dynamics::kResidualRegimeBit;
    residual_flagged += r.trials[i].regime.counts[bit] > 0;
    EXPECT_EQ(r_matched.trials[i].regime.counts[bit], 0u) << r_matched.trials[i].name;
  }
  EXPECT_GE(residual_flagged, 3) << "of " << r.trials.size();

  // The default: the torque offset identified on the calibration takes part of
  // the missing weight off every residual (its constant part on the insertion),
  // and no estimate gets worse than without it.
  o.joint.fit_torque_offset = true;
  const rcm::StudyResult corrected = rcm::run_study(payload, o, linear_fitter());
  ASSERT_TRUE(corrected.joint_tissue);
  EXPECT_LT(corrected.joint_tissue->torque_offset[2], -0.5);
  EXPECT_GT(corrected.joint_tissue->torque_offset[2], -0.2 * 9.81 - 0.3);
  EXPECT_EQ(corrected.joint_tissue->calibration_check, "held-out halves");
  ASSERT_EQ(corrected.trials.size(), r.trials.size());
  for (std::size_t i = 0; i < r.trials.size(); ++i) {
    const rcm::TrialOutcome &t = corrected.trials[i], &u = r.trials[i];
    ASSERT_TRUE(t.joint && u.joint && t.truth_m);
    EXPECT_LT((t.joint->misalignment_m - *t.truth_m).norm(), (u.joint->misalignment_m - *t.truth_m).norm() + 5e-4)
        << t.name;
  }
  std::error_code ec;
  fs::remove_all(dir, ec);
}

TEST(Study, ResultsFollowTheContract) {
  const nlohmann::json j = study().to_json();
  EXPECT_EQ(j["format"], "rcm-results/1");
  EXPECT_EQ(j["method"], "three-step");
  EXPECT_TRUE(j["tissue_model"]["expression"].is_string());
  EXPECT_TRUE(j["tissue_model"]["complexity"].is_number_integer());
  EXPECT_TRUE(j["tissue_model"]["loss"].is_number());
  ASSERT_EQ(j["trials"].size(), 4u);
  for (const auto& t : j["trials"]) {
    EXPECT_TRUE(t["name"].is_string());
    ASSERT_EQ(t["misalignment_m"].size(), 3u);
    EXPECT_NEAR(t["error_m"].get<double>(),
                (Eigen::Vector3d(t["misalignment_m"][0], t["misalignment_m"][1], t["misalignment_m"][2]) -
                 Eigen::Vector3d(t["truth_m"][0], t["truth_m"][1], t["truth_m"][2]))
                    .norm(),
                1e-12);
  }
}

TEST(Study, WritesResultsReportAndFigures) {
  const fs::path out = bench().dir / "report";
  const fs::path report = rcm::write_study_report(study(), bench().session, out);
  EXPECT_TRUE(fs::exists(report));
  EXPECT_EQ(rcm::load_json_file(out / "results.json")["format"], "rcm-results/1");
  const std::string md = rcm::read_text_file(report);
  for (const char* needle : {"Table II", "Table III", "Table IV", "D40_r10_15", "Solver summaries"})
    EXPECT_NE(md.find(needle), std::string::npos) << needle;
  if (rcm::is_gnuplot_available()) EXPECT_TRUE(fs::exists(out / "figures" / "fig4a_force.png"));
}

// Runs the CLI; captures stdout, and stderr too unless stdout_only.
int run_cli(const std::string& args, std::string* err = nullptr, bool stdout_only = false) {
  const std::string cmd = std::string(RCM_CLI_PATH) + " " + args + (stdout_only ? " 2>/dev/null" : " 2>&1");
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  std::string out;
  char buf[4096];
  while (std::size_t n = fread(buf, 1, sizeof buf, pipe.get())) out.append(buf, n);
  if (err) *err = out;
  const int status = pclose(pipe.release());
  return WEXITSTATUS(status);
}

TEST(StudyCli, LocatedErrors) {
  const fs::path manifest = bench().session.manifest;
  std::string err;
  EXPECT_EQ(run_cli("run " + manifest.string() + " --method both --out " + (bench().dir / "x").string(), &err), 2);
  EXPECT_NE(err.find("--method"), std::string::npos) << err;
  // A session without a calibration cannot run the three-step method.
  rcm::Session s = bench().session;
  s.calibration.reset();
  const fs::path no_cal = bench().dir / "no_calibration.json";
  rcm::save_session(no_cal, s);
  EXPECT_EQ(run_cli("run " + no_cal.string() + " --model linear --out " + (bench().dir / "y").string(), &err), 2);
  EXPECT_NE(err.find("no_calibration.json: field calibration"), std::string::npos) << err;
  EXPECT_EQ(run_cli("run /nonexistent/session.json", &err), 2);
  EXPECT_NE(err.find("/nonexistent/session.json: file not found"), std::string::npos) << err;
  // A NaN in the last trial stops the run before the free-space fit, not after
  // the fit and the trials before it.
  rcm::Session bad = bench().session;
  ASSERT_FALSE(bad.trials.empty());
  ASSERT_EQ(bad.trials.back().recording.extension(), ".csv");
  std::istringstream lines(rcm::read_text_file(bad.trials.back().recording));
  std::ostringstream corrupted;
  std::string line;
  for (int n = 1; std::getline(lines, line); ++n) {
    if (n == 50) line = "nan" + line.substr(line.find(','));  // the time column
    corrupted << line << '\n';
  }
  const fs::path bad_trial = bench().dir / "bad_last_trial.csv";
  std::ofstream(bad_trial) << corrupted.str();
  bad.trials.back().recording = bad_trial;
  const fs::path bad_manifest = bench().dir / "bad_last_trial.json";
  rcm::save_session(bad_manifest, bad);
  const fs::path bad_out = bench().dir / "bad_last_trial_run";
  EXPECT_EQ(run_cli("run " + bad_manifest.string() + " --model linear --out " + bad_out.string(), &err), 2);
  EXPECT_NE(err.find("bad_last_trial.csv:50: column time"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(bad_out / "free_space_model.json")) << err;
}

TEST(StudyCli, RunWritesTheContractJson) {
  std::string out;
  const fs::path dir = bench().dir / "cli_run";
  // The three-step method alone: the contract is the same, the joint method has its tests above.
  ASSERT_EQ(run_cli("run " + bench().session.manifest.string() + " --model linear --method three-step --json --out " +
                        dir.string(),
                    &out, true),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j["format"], "rcm-results/1");
  EXPECT_TRUE(fs::exists(dir / "report.md"));
}

TEST(StudyCli, MonitorReplaysATrial) {
  const auto& trial = bench().session.trials.back();
  std::string out;
  const fs::path trace = bench().dir / "monitor.csv";
  ASSERT_EQ(run_cli("monitor --session " + bench().session.manifest.string() + " " + trial.recording.string() +
                        " --model linear --json --out " + trace.string(),
                    &out, true),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  ASSERT_TRUE(j["final"]["misalignment_m"].is_array());
  EXPECT_LT(j["error_m"].get<double>(), 0.0015);
  EXPECT_TRUE(j["onset_s"].is_number());
  EXPECT_TRUE(j["alarms"].is_array());
  EXPECT_GT(j["update_us"]["mean"].get<double>(), 0.0);
  EXPECT_TRUE(fs::exists(trace));
  // The correction: the move to the incision is the estimate; a misalignment
  // beyond the 10 mm software limit ends in re-docking advice, in words.
  const auto& c = j["correction"];
  const Eigen::Vector3d truth = trial.truth_misalignment_m.value();
  ASSERT_GT(truth.norm(), 0.015) << "the last trial is the largest misalignment";
  for (int i = 0; i < 3; ++i)
    EXPECT_DOUBLE_EQ(c["move_inc_m"][i].get<double>(), j["final"]["misalignment_m"][i].get<double>());
  EXPECT_NEAR(Eigen::Vector3d(c["move_base_m"][0], c["move_base_m"][1], c["move_base_m"][2]).norm(), truth.norm(), 0.002);
  EXPECT_EQ(c["action"], "reposition") << c.dump();
  EXPECT_NE(c["advice"].get<std::string>().find("re-dock, move the RCM"), std::string::npos) << c.dump();
  ASSERT_FALSE(c["changes"].empty());
  EXPECT_EQ(c["changes"].back()["action"], "reposition");
  EXPECT_FALSE(j["alignment"]["aligned"].get<bool>());
  EXPECT_NE(j["alignment"]["message"].get<std::string>().find("remain"), std::string::npos) << j["alignment"].dump();
  const std::string trace_text = rcm::read_text_file(trace);
  EXPECT_EQ(trace_text.substr(0, trace_text.find('\n')).substr(trace_text.find("action")),
            "action,move_x,move_y,move_z,step_x,step_y,step_z");
  std::string err;
  EXPECT_EQ(run_cli("monitor --session " + bench().session.manifest.string() + " /nonexistent.csv --model linear", &err), 2);
  EXPECT_NE(err.find("/nonexistent.csv"), std::string::npos) << err;
}

TEST(StudyCli, ForceSeriesAgainstTheSensor) {
  const fs::path model = bench().dir / "force_model.json";
  std::string out;
  ASSERT_EQ(run_cli("dynamics fit --model linear --out " + model.string() + " " +
                        bench().session.free_space.front().string(),
                    &out),
            0)
      << out;
  const auto& trial = bench().session.trials.back();  // D = 40 mm with a radial offset
  const fs::path series = bench().dir / "force.csv";
  ASSERT_EQ(run_cli("force --model " + model.string() + " --offset " + std::to_string((*trial.truth_misalignment_m)[2]) +
                        " --q0 " + std::to_string(bench().session.q0[0]) + "," + std::to_string(bench().session.q0[1]) +
                        "," + std::to_string(bench().session.q0[2]) + " " + trial.recording.string() + " --json --out " +
                        series.string(),
                    &out, true),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  ASSERT_TRUE(j["rmse"].is_object()) << out;
  // Table III's order of magnitude: a few newtons at most per axis.
  for (const char* axis : {"x", "y", "z"}) EXPECT_LT(j["rmse"][axis].get<double>(), 4.0) << axis;
  EXPECT_GT(j["samples"].get<int>(), 1000);
  const std::string csv = rcm::read_text_file(series);
  EXPECT_EQ(csv.rfind("time,force_x,force_y,force_z,theta,condition,status\n", 0), 0u);
  std::string err;
  EXPECT_EQ(run_cli("force --model " + model.string() + " --offset 0.03 --q0 0,0 " + trial.recording.string(), &err), 2);
  EXPECT_NE(err.find("--q0"), std::string::npos) << err;
}

}  // namespace
