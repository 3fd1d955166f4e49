// rcm setup (rcm/estimation/setup.hpp): ready on a sound simulated session, and
// on deliberately poor recordings the finding that says what is missing.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "rcm/dynamics/excitation.hpp"
#include "rcm/estimation/setup.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"
#include "run_cli.hpp"
#include "temp_dir.hpp"

namespace {

const std::filesystem::path kSession = std::filesystem::path(RCM_LIVE_TEST_DIR) / "session" / "session.json";

rcm::StudyOptions quiet_options() {
  rcm::StudyOptions o;
  o.verbose = false;
  o.fit.verbose = false;
  o.joint.calibration_bootstrap_replicates = 0;
  return o;
}

rcm::SetupReport run(const rcm::Session& session, const rcm::SetupOptions& options = {}) {
  return rcm::run_setup(session, quiet_options(), options, rcm::get_linear_torque_model_fitter({}));
}

const rcm::SetupFinding* find(const rcm::SetupReport& r, const std::string& check) {
  for (const auto& f : r.findings)
    if (f.check == check) return &f;
  return nullptr;
}

std::string missing_text(const rcm::SetupReport& r) {
  std::string out;
  for (const auto& f : r.findings)
    if (f.severity == rcm::SetupSeverity::missing) out += f.check + ": " + f.message + "\n";
  return out;
}

// The session with one of its recordings cut to its first `seconds`, in `dir`.
rcm::Session with_head(const rcm::Session& session, const std::filesystem::path& recording, double seconds,
                       const std::filesystem::path& dir) {
  const rcm::Recording r = rcm::load_recording(recording);
  Eigen::Index n = 0;
  while (n < r.time.size() && r.time[n] - r.time[0] < seconds) ++n;
  const std::filesystem::path out = dir / ("head_" + recording.filename().string());
  rcm::save_recording(out, rcm::get_recording_rows(r, 0, n));
  rcm::Session s = session;
  if (recording == session.calibration->recording) s.calibration->recording = out;
  else s.free_space = {out};
  return s;
}

TEST(SetupReversals, CountsSignChangesBeyondTheFloor) {
  // Three periods of a sine (+ - + - + -): five sign changes; a ripple at 1 %
  // of the peak around each crossing adds none above a 10 % floor, many at none.
  Eigen::MatrixXd v(3000, 1);
  for (Eigen::Index i = 0; i < v.rows(); ++i)
    v(i, 0) = std::sin(2 * M_PI * 3.0 * static_cast<double>(i) / 3000.0 + 0.1) + 0.01 * std::sin(977.0 * i);
  EXPECT_EQ(rcm::dynamics::count_velocity_reversals(v, 0.1).front(), 5);
  EXPECT_GT(rcm::dynamics::count_velocity_reversals(v, 0.0).front(), 5);
  EXPECT_EQ(rcm::dynamics::count_velocity_reversals(Eigen::MatrixXd::Zero(10, 1), 0.1).front(), 0);
}

TEST(SetupForceError, IsEquationSixOnEachJointsError) {
  const Eigen::Vector3d q0(0.0, 0.0, 0.12), q(0.349, 0.1, 0.13), sigma(0.05, 0.03, 0.2);
  const rcm::IncisionFrame incision = rcm::make_incision_frame(q0);
  const double D = 0.03;
  // Independently: f = J_D^-T dtau with J_D from the closed form, summed in quadrature.
  const Eigen::Matrix3d J = rcm::compute_incision_jacobian(q, rcm::compute_shaft_distance(incision, q, D));
  const Eigen::Matrix3d JinvT = J.transpose().inverse();
  const double expected = (JinvT * sigma.asDiagonal()).norm();
  EXPECT_NEAR(rcm::compute_force_error_rms(incision, q, D, sigma), expected, 1e-9 * expected);
}

TEST(SetupOptions, RefusesACurveThatDoesNotEndAtTheWhole) {
  rcm::SetupOptions o;
  o.curve_fractions = {0.5, 0.8};
  EXPECT_THROW(o.check(), std::invalid_argument);
  o.curve_fractions = {0.5, 0.25, 1.0};
  EXPECT_THROW(o.check(), std::invalid_argument);
  o.curve_fractions = {0.5, 1.0};
  EXPECT_NO_THROW(o.check());
}

TEST(Setup, ReadyOnTheSimulatedSession) {
  const rcm::Session session = rcm::load_session(kSession);
  const rcm::SetupReport r = run(session);
  EXPECT_TRUE(r.ready) << missing_text(r);
  EXPECT_NEAR(r.free_space_s, 120.0, 0.1);
  EXPECT_GT(r.calibration_s, 29.0);
  EXPECT_NEAR(r.get_robot_seconds(), r.free_space_s + r.baseline_s + r.calibration_s, 1e-12);
  ASSERT_EQ(r.joints.size(), 3u);
  EXPECT_EQ(r.joints[1].name, "outer_pitch");
  for (const auto& c : r.joints) {
    EXPECT_LE(c.position_min, c.wanted_min + 0.05 * (c.position_max - c.position_min)) << c.name;
    EXPECT_GE(c.reversals, 10) << c.name;
  }
  EXPECT_LT(r.force_error_n, 2.0);
  ASSERT_TRUE(r.calibration_error_m);
  EXPECT_LT(*r.calibration_error_m, 0.002);
  // The learning curve: one point per share, the last the fit itself.
  ASSERT_EQ(r.curve.size(), 3u);
  EXPECT_EQ(r.curve.back().fraction, 1.0);
  for (const auto& p : r.curve) EXPECT_EQ(p.errors.size(), 3u);
  const nlohmann::json j = r.to_json();
  EXPECT_TRUE(j.at("ready").get<bool>());
  EXPECT_EQ(j.at("joints").size(), 3u);
  EXPECT_EQ(j.at("learning_curve").size(), 3u);
  EXPECT_NE(r.to_text().find("ready"), std::string::npos);
}

TEST(Setup, RareTorqueSpikesAreANoteNotAForceError) {
  // The free space with a spike on yaw and pitch at 1 % of its samples (a
  // servo setpoint a period late, then two at once): the RMSE more than
  // doubles, the force error hardly moves, and a note says why.
  rcm::test::TempDir dir;
  const rcm::Session session = rcm::load_session(kSession);
  const rcm::SetupReport clean = run(session);
  rcm::Recording r = rcm::load_recording(session.free_space.front());
  for (Eigen::Index i = 0; i < r.effort.rows(); i += 100) {
    r.effort(i, 0) += (i % 200 == 0 ? 0.4 : -0.4);
    r.effort(i, 1) += (i % 200 == 0 ? -0.4 : 0.4);
  }
  const std::filesystem::path spiky_file = dir.path() / "spiky_free_space.csv";
  rcm::save_recording(spiky_file, r);
  rcm::Session spiky_session = session;
  spiky_session.free_space = {spiky_file};
  const rcm::SetupReport spiky = run(spiky_session);
  EXPECT_TRUE(spiky.ready) << missing_text(spiky);
  EXPECT_GT(spiky.free_space.errors[0].rmse, 2.0 * clean.free_space.errors[0].rmse);
  EXPECT_NEAR(spiky.force_error_n, clean.force_error_n, 0.15 * clean.force_error_n);
  const rcm::SetupFinding* note = find(spiky, "model.spikes");
  ASSERT_NE(note, nullptr);
  EXPECT_EQ(note->severity, rcm::SetupSeverity::note);
  EXPECT_EQ(find(clean, "model.spikes"), nullptr) << find(clean, "model.spikes")->message;
}

TEST(Setup, AShortFreeSpaceSaysHowMuchMore) {
  rcm::test::TempDir dir;
  const rcm::Session session = rcm::load_session(kSession);
  const rcm::SetupReport r = run(with_head(session, session.free_space.front(), 40.0, dir.path()));
  EXPECT_FALSE(r.ready);
  const rcm::SetupFinding* f = find(r, "free_space.duration");
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->severity, rcm::SetupSeverity::missing);
  EXPECT_NE(f->message.find("record 80 s more"), std::string::npos) << f->message;
}

TEST(Setup, AFreeSpaceHeldAtRestSaysWhereToMove) {
  // The baseline (an approach to q0 and a hold) as the free space: too short,
  // too narrow on every joint, no reversals; each said with what to do.
  const rcm::Session session = rcm::load_session(kSession);
  rcm::Session poor = session;
  poor.free_space = {*session.baseline};
  const rcm::SetupReport r = run(poor);
  EXPECT_FALSE(r.ready);
  for (const char* joint : {"outer_yaw", "outer_pitch", "outer_insertion"}) {
    const rcm::SetupFinding* position = find(r, std::string("free_space.position.") + joint);
    ASSERT_NE(position, nullptr) << joint;
    EXPECT_EQ(position->severity, rcm::SetupSeverity::missing) << position->message;
    const rcm::SetupFinding* reversals = find(r, std::string("free_space.reversals.") + joint);
    ASSERT_NE(reversals, nullptr) << joint;
    EXPECT_EQ(reversals->severity, rcm::SetupSeverity::missing) << reversals->message;
  }
  const std::string pitch = find(r, "free_space.position.outer_pitch")->message;
  EXPECT_NE(pitch.find("move the instrument further toward outer_pitch"), std::string::npos) << pitch;
  const std::string insertion = find(r, "free_space.position.outer_insertion")->message;
  EXPECT_NE(insertion.find("withdraw the instrument"), std::string::npos) << insertion;
  EXPECT_NE(insertion.find("insert the instrument deeper"), std::string::npos) << insertion;
  // The calibration then leaves the model's regime.
  const rcm::SetupFinding* regime = find(r, "calibration.regime");
  ASSERT_NE(regime, nullptr);
  EXPECT_EQ(regime->severity, rcm::SetupSeverity::missing) << regime->message;
}

TEST(Setup, AWorkspaceBeyondTheFreeSpaceIsMissing) {
  const rcm::Session session = rcm::load_session(kSession);
  rcm::SetupOptions o;
  o.workspace_half_range = Eigen::Vector3d(0.0, 1.2, 0.0);  // pitch +-1.2 rad around q0
  const rcm::SetupReport r = run(session, o);
  EXPECT_FALSE(r.ready);
  const std::string pitch = find(r, "free_space.position.outer_pitch")->message;
  EXPECT_NE(pitch.find("toward outer_pitch -1.20 rad and 1.20 rad"), std::string::npos) << pitch;
  EXPECT_EQ(find(r, "free_space.position.outer_yaw")->severity, rcm::SetupSeverity::ok);
}

TEST(Setup, AShortOrNarrowCalibrationIsMissing) {
  rcm::test::TempDir dir;
  const rcm::Session session = rcm::load_session(kSession);
  const rcm::SetupReport r = run(with_head(session, session.calibration->recording, 5.0, dir.path()));
  EXPECT_FALSE(r.ready);
  EXPECT_EQ(find(r, "calibration.duration")->severity, rcm::SetupSeverity::missing);
  rcm::SetupOptions o;
  o.min_calibration_pivot_rad = 1.2;  // more than the session's teleoperation pivots
  const rcm::SetupReport narrow = run(session, o);
  EXPECT_EQ(find(narrow, "calibration.pivot")->severity, rcm::SetupSeverity::missing);
  rcm::Session none = session;
  none.calibration.reset();
  const rcm::SetupReport without = run(none);
  EXPECT_FALSE(without.ready);
  EXPECT_EQ(find(without, "calibration")->severity, rcm::SetupSeverity::missing);
}

TEST(SetupCli, ExitStatusFilesAndJson) {
  rcm::test::TempDir dir;
  std::string out;
  const std::string quiet = " --options " + dir.write("o.json", R"({"joint": {"calibration_bootstrap_replicates": 0}})").string();
  ASSERT_EQ(rcm::test::run_cli("setup " + kSession.string() + " --out " + (dir.path() / "ok").string() + quiet +
                                   " --json",
                               out, rcm::test::CliOutput::stdout_only),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_TRUE(j.at("ready").get<bool>());
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "ok" / "free_space_model.json"));
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "ok" / "setup.json"));
  // Not ready: exit 3, the report written all the same.
  EXPECT_EQ(rcm::test::run_cli("setup " + kSession.string() + " --out " + (dir.path() / "poor").string() + quiet +
                                   " --min-free-space 600",
                               out),
            3)
      << out;
  EXPECT_NE(out.find("not ready: 1 thing missing"), std::string::npos) << out;
  EXPECT_NE(out.find("record 480 s more"), std::string::npos) << out;
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "poor" / "setup.json"));
  // Bad input: exit 2, located.
  EXPECT_EQ(rcm::test::run_cli("setup " + (dir.path() / "absent.json").string(), out), 2) << out;
  EXPECT_NE(out.find("absent.json"), std::string::npos) << out;
  EXPECT_EQ(rcm::test::run_cli("setup " + kSession.string() + " --min-reversals -1", out), 2) << out;
  EXPECT_NE(out.find("--min-reversals"), std::string::npos) << out;
}

}  // namespace
