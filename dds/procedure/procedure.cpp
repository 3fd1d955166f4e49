// The phases of rcm_procedure_dds (procedure.hpp).

#include "procedure.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <thread>

#include "rcm/common/command_line.hpp"
#include "rcm/io/joint_trajectory.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/closed_loop.hpp"
#include "ros2_msgs.h"

namespace rcm::dds_node {

namespace fs = std::filesystem;

namespace {

std::string vec(const Eigen::Vector3d& v, double scale = 1.0, int digits = 3) {
  return fmt::format("{:.{}f}, {:.{}f}, {:.{}f}", scale * v[0], digits, scale * v[1], digits, scale * v[2], digits);
}

std::string num(double v) { return fmt::format("{:.17g}", v); }

Eigen::Matrix3d get_incision_rotation(const Eigen::Vector3d& q0) {
  const ShaftDirections f = compute_shaft_directions(q0);
  Eigen::Matrix3d R;
  R << f.x3, f.y3, f.z3;
  return R;
}

}  // namespace

void ProcedureOptions::check(const std::function<InputLocation(const std::string&)>& flag) {
  if (!(excite_duration_s > 0)) throw InputError(flag("--excite-duration"), "must be > 0");
  if (!(baseline_s > 0)) throw InputError(flag("--baseline-s"), "must be > 0");
  if (!(calibration_s > 0)) throw InputError(flag("--calibration-s"), "must be > 0");
  if (!(std::abs(calibration_offset_m) > 0 && std::abs(calibration_offset_m) <= 0.1))
    throw InputError(flag("--calibration-offset-m"), "must be a coaxial offset of at most 0.1 m, not 0");
  if (!(check_s >= 0)) throw InputError(flag("--check-s"), "must be >= 0");
  if (!(live_s >= 0)) throw InputError(flag("--live-s"), "must be >= 0");
  if (!(loop_s > 20.0)) throw InputError(flag("--loop-s"), "must be > 20 s (the bench's motions start at 20 s)");
  if (!(jump_threshold >= 0)) throw InputError(flag("--jump-threshold"), "must be >= 0");
  if (!incision_motion.empty()) {
    const auto motions = sim::make_default_incision_motions();
    if (std::none_of(motions.begin(), motions.end(), [&](const auto& m) { return m.name == incision_motion; }))
      throw InputError(flag("--incision-motion"), "unknown motion '" + incision_motion +
                                                      "'; known: step, drift, breathing, large_step");
    if (!simulator || !software_rcm)
      throw InputError(flag("--incision-motion"), "needs --simulator and --software-rcm (the loop across processes)");
  }
  load_robot_model(robot, "--robot").check_within_limits(q0, flag("--q0"));
  if (!max_tracking_error_text.empty())
    player.max_tracking_error = parse_number_list(max_tracking_error_text, flag("--max-tracking-error"));
  player.check([&](const std::string& name) { return flag(get_flag_name(name)); });
  if (session.empty() != model_file.empty())
    throw InputError(flag(session.empty() ? "--session" : "--model-file"),
                     "--session and --model-file go together: a setup made before");
  if (!tissue_model_file.empty() && session.empty())
    throw InputError(flag("--tissue-model-file"), "goes with --session and --model-file: a setup made before");
  const fs::path here = get_program_directory();
  if (rcm.empty()) rcm = (here / "rcm").string();
  if (monitor.empty()) monitor = (here / "rcm_monitor_dds").string();
  for (const auto& [path, name] : {std::pair{rcm, "--rcm"}, std::pair{monitor, "--monitor"}})
    if (::access(path.c_str(), X_OK) != 0) throw InputError(flag(name), "not an executable program: " + path);
}

Procedure::Procedure(const ProcedureOptions& options, std::function<bool()> interrupted)
    : o_(options), interrupted_(std::move(interrupted)) {}

Procedure::~Procedure() {
  monitor_.reset();
  if (participant_ > 0) dds_delete(participant_);
}

void Procedure::say(const std::string& line) {
  std::printf("[%6.1f s] %s\n", static_cast<double>(get_steady_ns() - start_ns_) * 1e-9, line.c_str());
}

void Procedure::sim_command(const std::string& text) {
  if (!o_.simulator) return;
  crtk_msgs_msg_dds__StringStamped_ m{};
  std::string copy = text;
  m.header = make_header(get_wall_ns());
  m.string = copy.data();
  check(dds_write(incision_writer_, &m), "sim/incision_command");
  say("simulator: incision " + text);
}

bool Procedure::confirm(const std::string& what) {
  say(what);
  if (o_.simulator || o_.yes) return true;
  std::printf("           press Enter when done (Ctrl-C stops)\n");
  std::string line;
  return static_cast<bool>(std::getline(std::cin, line)) && !interrupted_();
}

bool Procedure::play(const std::string& name, TrajectoryPlayer& player, const std::string& file) {
  const std::int64_t wall0 = get_steady_ns();
  const double total = player.summary().file_duration_s;
  run_player(*arm_, player, interrupted_, [&](const TrajectoryPlayer& p, std::int64_t) {
    const PlayerSummary& s = p.summary();
    const double done = s.recorded_span_s, wall = static_cast<double>(get_steady_ns() - wall0) * 1e-9;
    std::string line = fmt::format("{}: {} {:.1f} / {:.1f} s of the arm's time", name, to_string(p.phase()), done, total);
    if (done > 0 && wall > 0) line += fmt::format(", about {:.0f} s left", (total - done) * wall / done);
    line += fmt::format("; {} rows sent, {} samples recorded", s.rows_sent, s.samples_recorded);
    if (live_segment_) {
      observer_->poll();
      if (observer_->last_estimate())
        line += fmt::format("; estimate {} mm", vec(*observer_->last_estimate(), 1e3, 1));
      if (observer_->last_truth())
        line += fmt::format(" (truth {} mm, |f| {:.1f} N)", vec(*observer_->last_truth(), 1e3, 1),
                            observer_->last_force_n());
    }
    say(line);
  });
  if (!player.finished()) player.compute_tick(get_steady_ns());
  const PlayerSummary& s = player.summary();
  if (!file.empty()) {
    if (s.samples_recorded > 0) save_recording(o_.out / file, player.get_recording(file));
    nlohmann::json j = to_json(s, player.joint_names());
    j["name"] = name;
    j["recording"] = s.samples_recorded > 0 ? nlohmann::json(file) : nlohmann::json(nullptr);
    j["status"] = interrupted_() && !player.finished() ? "interrupted" : to_string(player.phase());
    j["wall_s"] = static_cast<double>(get_steady_ns() - wall0) * 1e-9;
    report_["phases"].push_back(j);
    std::string text = format_player_summary(s, player.joint_names());
    if (!text.empty() && text.back() == '\n') text.pop_back();
    say(fmt::format("{}: {}{}", name, text, s.samples_recorded > 0 ? "\n           wrote " + file : ""));
  }
  if (player.phase() != PlayerPhase::done && !interrupted_())
    say(fmt::format("{}: {}: {}", name, to_string(player.phase()), s.message));
  return player.phase() == PlayerPhase::done;
}

bool Procedure::move_to_q0() {
  TrajectoryPlayer hold(make_hold_trajectory(o_.q0, 0.2, 100.0), o_.player);
  return play("to q0", hold, "");
}

void Procedure::write_session() {
  save_session(o_.out / "session.json", session_);
}

bool Procedure::start_monitor(const std::string& segment, bool loop) {
  const bool given = !o_.session.empty();
  std::vector<std::string> args = {o_.monitor,
                                   "--session", given ? o_.session : (o_.out / "session.json").string(),
                                   "--model-file",
                                   given ? o_.model_file : (o_.out / "setup" / "free_space_model.json").string(),
                                   "--arm", o_.arm,
                                   "--domain", std::to_string(o_.domain),
                                   "--seed", std::to_string(o_.seed),
                                   "--status-period-s", "5"};
  // The tissue model rcm setup identified: the monitor comes up in about a
  // second rather than identifying it again.
  const std::string tissue = given ? o_.tissue_model_file : (o_.out / "setup" / "tissue_model.json").string();
  if (!tissue.empty()) args.insert(args.end(), {"--tissue-model-file", tissue});
  CorrectionOptions gates;
  if (loop) {
    for (const auto& m : sim::make_default_incision_motions())
      if (m.name == o_.incision_motion) gates = m.get_correction_options(gates);
    args.insert(args.end(), {"--software-rcm", "--jump-threshold", num(o_.jump_threshold)});
  }
  if (o_.compensate_limit_m) gates.compensate_limit_m = *o_.compensate_limit_m;
  if (o_.max_shift_rate_m_per_s) gates.max_rate_m_per_s = *o_.max_shift_rate_m_per_s;
  if (o_.tolerance_m) args.insert(args.end(), {"--tolerance-m", num(*o_.tolerance_m)});
  if (loop || o_.compensate_limit_m) args.insert(args.end(), {"--compensate-limit-m", num(gates.compensate_limit_m)});
  if (loop || o_.max_shift_rate_m_per_s)
    args.insert(args.end(), {"--max-shift-rate-m-per-s", num(gates.max_rate_m_per_s)});
  monitor_log_ = "monitor_" + segment + ".log";
  say(fmt::format("{}: starting rcm_monitor_dds{} (log {})", segment, loop ? " with the software RCM" : "",
                  monitor_log_));
  monitor_ = std::make_unique<Child>(args, o_.out / monitor_log_);
  const std::string matched = "publisher(s) matched on rt/" + o_.arm + "/measured_js";
  const std::int64_t start = get_steady_ns();
  while (!interrupted_()) {
    const std::string log = monitor_->log();
    if (log.find("listening on") != std::string::npos && log.find(matched) != std::string::npos) return true;
    if (!monitor_->alive() || get_steady_ns() - start > 300LL * 1000000000) {
      say(fmt::format("{}: the monitor did not come up (exit {}):\n{}", segment, monitor_->stop(std::chrono::seconds(2)),
                      log));
      return false;
    }
    arm_->discard_pending();  // the arm's stream goes on meanwhile
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

int Procedure::stop_monitor() {
  if (!monitor_) return 0;
  const int code = monitor_->stop(std::chrono::seconds(10));
  monitor_.reset();
  return code;
}

bool Procedure::run_check() {
  live_segment_ = true;
  if (!move_to_q0()) return false;
  sim_command(fmt::format("place {} {} {}", num(o_.check_offset_m[0]), num(o_.check_offset_m[1]),
                          num(o_.check_offset_m[2])));
  if (!start_monitor("check", false)) return false;
  observer_->start(std::nullopt);
  TrajectoryPlayer record(o_.check_s, o_.player);
  const bool ok = play("check", record, "check.csv");
  observer_->poll();
  const int code = stop_monitor();
  nlohmann::json check = {{"recording", "check.csv"}, {"monitor_log", monitor_log_}, {"monitor_exit", code},
                          {"truth_m", {o_.check_offset_m[0], o_.check_offset_m[1], o_.check_offset_m[2]}}};
  if (observer_->last_estimate()) {
    const Eigen::Vector3d e = *observer_->last_estimate();
    const Eigen::Vector3d truth = observer_->last_truth().value_or(o_.check_offset_m);
    check["estimate_m"] = {e[0], e[1], e[2]};
    check["estimates"] = observer_->estimates();
    report_["estimate_error_m"] = (e - truth).norm();
    say(fmt::format("check: the live estimate {} mm against the simulator's truth {} mm: error {:.2f} mm",
                    vec(e, 1e3, 2), vec(truth, 1e3, 2), 1e3 * (e - truth).norm()));
  } else {
    say("check: no estimate came from the monitor");
  }
  report_["check"] = check;
  if (ok) session_.trials.push_back({"check", o_.out / "check.csv", std::nullopt, o_.check_offset_m});
  live_segment_ = false;
  return ok && observer_->last_estimate().has_value();
}

bool Procedure::run_loop() {
  live_segment_ = true;
  if (!move_to_q0()) return false;
  sim_command("place 0 0 0");
  if (!start_monitor("loop", true)) return false;
  sim::IncisionMotion motion;
  for (const auto& m : sim::make_default_incision_motions())
    if (m.name == o_.incision_motion) motion = m;
  sim_command("motion " + motion.name);
  sim::ClosedLoopOptions options;
  options.duration_s = o_.loop_s;
  observer_->start(sim::ClosedLoopMeter(motion.onset_s, o_.loop_s, options));
  TrajectoryPlayer record(o_.loop_s, o_.player);
  const bool ok = play("loop", record, "loop.csv");
  observer_->poll();
  const int code = stop_monitor();
  const sim::ClosedLoopRun r = observer_->get_figures();
  report_["closed_loop"] = {
      {"motion", motion.name},
      {"recording", "loop.csv"},
      {"monitor_log", monitor_log_},
      {"monitor_exit", code},
      {"truth_samples", observer_->truth_samples()},
      {"peak_force_n", r.peak_force_n},
      {"time_to_below_2n_s", r.time_to_below_s ? nlohmann::json(*r.time_to_below_s) : nlohmann::json(nullptr)},
      {"rms_force_after_settle_n", r.rms_force_after_settle_n},
      {"residual_misalignment_m", r.residual_misalignment_m},
      {"moves", r.moves},
      {"wrong_direction_moves", r.wrong_direction_moves}};
  session_.extra["procedure"]["loop"] = "loop.csv";
  say(fmt::format("loop ({}): peak force {:.1f} N, force below 2 N for good {} after the onset, RMS force after "
                  "settling {:.2f} N, residual misalignment {:.1f} mm, {} moves, {} in the wrong direction",
                  motion.name, r.peak_force_n,
                  r.time_to_below_s ? fmt::format("{:.1f} s", *r.time_to_below_s) : std::string("never"),
                  r.rms_force_after_settle_n, 1e3 * r.residual_misalignment_m, r.moves, r.wrong_direction_moves));
  live_segment_ = false;
  return ok;
}

bool Procedure::run_live() {
  if (!confirm("live: align the RCM on the incision again; the live monitor starts and the arm is recorded"))
    return false;
  if (!start_monitor("live", o_.software_rcm)) return false;
  TrajectoryPlayer record(o_.live_s > 0 ? o_.live_s : 86400.0, o_.player);
  play("live", record, "live.csv");
  const int code = stop_monitor();
  report_["live"] = {{"recording", "live.csv"}, {"monitor_log", monitor_log_}, {"monitor_exit", code}};
  if (record.summary().samples_recorded > 0) session_.trials.push_back({"live", o_.out / "live.csv", std::nullopt, std::nullopt});
  return true;
}

int Procedure::run_phases() {
  // 1. Excitation, in free space.
  std::string excitation = o_.excitation;
  if (excitation.empty()) {
    excitation = (o_.out / "excitation_trajectory.csv").string();
    say(fmt::format("excitation: rcm excite --duration {:g} --rate {:g}, the arm's (log excite.log)",
                    o_.excite_duration_s, std::round(arm_->get_measured_rate_hz())));
    // At the arm's own rate: servo_jp is a setpoint its controller takes as
    // it comes, so a slower file would move the arm in steps.
    const double rate = std::round(arm_->get_measured_rate_hz());
    std::vector<std::string> args = {o_.rcm, "excite", "--duration", num(o_.excite_duration_s), "--q0",
                                     fmt::format("{},{},{}", num(o_.q0[0]), num(o_.q0[1]), num(o_.q0[2])), "--seed",
                                     std::to_string(o_.seed), "--rate", num(rate > 0 ? rate : 1000.0), "--out",
                                     excitation};
    args.insert(args.end(), o_.excite_args.begin(), o_.excite_args.end());
    const int code = run_child(args, o_.out / "excite.log", interrupted_);
    if (interrupted_()) return 4;
    if (code != 0) throw std::runtime_error(fmt::format("rcm excite exited {}; see {}", code, (o_.out / "excite.log").string()));
  }
  const JointTrajectory trajectory = load_joint_trajectory(excitation);
  sim_command("free_space");
  if (!confirm("excitation: the instrument in free space, nothing within its reach")) return 4;
  TrajectoryPlayer excite(trajectory, o_.player);
  if (!play("excitation", excite, "free_space.csv")) return excite.phase() == PlayerPhase::refused ? 3 : 4;

  // 2. Baseline: docked, the RCM on the incision, held at q0.
  sim_command("place 0 0 0");
  if (!confirm(fmt::format("baseline: dock the arm with the RCM on the incision; it holds q0 for {:g} s", o_.baseline_s)))
    return 4;
  TrajectoryPlayer baseline(make_hold_trajectory(o_.q0, o_.baseline_s, 100.0), o_.player);
  if (!play("baseline", baseline, "baseline.csv")) return 4;

  // 3. Calibration at the known coaxial offset D*.
  if (!move_to_q0()) return 4;
  sim_command(fmt::format("place 0 0 {}", num(o_.calibration_offset_m)));
  if (!confirm(fmt::format("calibration: set the RCM {:.0f} mm off the incision along the instrument (D*), then {}",
                           1e3 * o_.calibration_offset_m,
                           o_.calibration_trajectory.empty()
                               ? fmt::format("teleoperate for {:g} s, pivoting about the RCM", o_.calibration_s)
                               : "the calibration trajectory plays")))
    return 4;
  std::optional<TrajectoryPlayer> calibration;
  if (o_.calibration_trajectory.empty()) calibration.emplace(o_.calibration_s, o_.player);
  else calibration.emplace(load_joint_trajectory(o_.calibration_trajectory), o_.player);
  if (!play("calibration", *calibration, "calibration.csv")) return 4;

  // 4. rcm setup on what was recorded.
  session_.robot = o_.robot;
  session_.q0 = o_.q0;
  session_.free_space = {o_.out / "free_space.csv"};
  session_.baseline = o_.out / "baseline.csv";
  session_.calibration = CalibrationSpec{o_.out / "calibration.csv", o_.calibration_offset_m};
  session_.joint_topic = "/" + o_.arm + "/measured_js";
  session_.extra["procedure"] = {{"generator", "rcm_procedure_dds"}, {"excitation", fs::path(excitation).filename().string()}};
  write_session();
  // The free-space model predicts the joints the estimate reads, 1-3: the
  // wrist's joints would multiply the fit's time and serve nothing here.
  save_json_file(o_.out / "setup_options.json", {{"fit", {{"num_outputs", 3}}}});
  std::vector<std::string> args = {o_.rcm, "setup", (o_.out / "session.json").string(), "--out",
                                   (o_.out / "setup").string(), "--options", (o_.out / "setup_options.json").string()};
  args.insert(args.end(), o_.setup_args.begin(), o_.setup_args.end());
  say("setup: rcm setup session.json (log setup.log)");
  const int code = run_child(args, o_.out / "setup.log", interrupted_);
  if (interrupted_()) return 4;
  const fs::path setup_json = o_.out / "setup" / "setup.json";
  if ((code != 0 && code != 3) || !fs::exists(setup_json))
    throw std::runtime_error(fmt::format("rcm setup exited {}; see {}", code, (o_.out / "setup.log").string()));
  const nlohmann::json setup = load_json_file(setup_json);
  nlohmann::json missing = nlohmann::json::array();
  for (const auto& f : setup["findings"])
    if (f["severity"] == "missing") missing.push_back(f["check"].get<std::string>() + ": " + f["message"].get<std::string>());
  report_["setup"] = {{"ready", setup["ready"]}, {"exit", code}, {"missing", missing}, {"report", "setup/setup.json"},
                      {"force_error_n", setup["model"].value("force_error_n", nlohmann::json(nullptr))}};
  if (!setup["ready"].get<bool>()) {
    std::string text;
    for (const auto& m : missing) text += "\n             " + m.get<std::string>();
    say("setup: NOT READY:" + text);
    return 3;
  }
  say(fmt::format("setup: ready (the model's force error {:.2f} N; setup/setup.json)",
                  setup["model"].value("force_error_n", 0.0)));

  return run_live_phase();
}

int Procedure::run_live_phase() {
  bool ok = true;
  if (o_.simulator) {
    if (o_.check_s > 0) ok = run_check() && ok;
    if (!interrupted_() && !o_.incision_motion.empty()) ok = run_loop() && ok;
  } else {
    ok = run_live();
  }
  if (o_.session.empty()) write_session();
  return ok || interrupted_() ? 0 : 4;
}

int Procedure::run() {
  start_ns_ = get_steady_ns();
  fs::create_directories(o_.out);
  report_ = {{"format", "rcm-procedure/1"}, {"arm", o_.arm}, {"simulator", o_.simulator},
             {"phases", nlohmann::json::array()}, {"setup", nullptr}, {"estimate_error_m", nullptr},
             {"closed_loop", nullptr}};
  participant_ = check(dds_create_participant(static_cast<dds_domainid_t>(o_.domain), nullptr, nullptr),
                       "create participant");
  arm_ = std::make_unique<CrtkClient>(participant_, o_.arm);
  observer_ = std::make_unique<LiveObserver>(participant_, o_.arm, get_incision_rotation(o_.q0));
  if (o_.simulator)
    incision_writer_ = make_writer(participant_, &crtk_msgs_msg_dds__StringStamped__desc,
                                   "/" + o_.arm + "/sim/incision_command", 100);
  say(fmt::format("waiting for the arm on /{}/ (domain {}){}", o_.arm, o_.domain, o_.power ? "; enabling and homing it" : ""));
  std::string why;
  int status = 3;
  if (!wait_for_arm(*arm_, o_.power, o_.player.start_timeout_s + (o_.power ? 30.0 : 0.0), interrupted_, why)) {
    say("refused: " + why);
  } else {
    say(fmt::format("the arm is {}{}", arm_->get_state().state, arm_->get_state().homed ? ", homed" : ", not homed"));
    if (o_.session.empty()) {
      status = run_phases();
    } else {
      say(fmt::format("live only, on the setup of {} and {}", o_.session, o_.model_file));
      status = run_live_phase();
    }
  }
  stop_monitor();
  report_["exit"] = status;
  report_["wall_s"] = static_cast<double>(get_steady_ns() - start_ns_) * 1e-9;
  save_json_file(o_.out / "procedure.json", report_);
  say(fmt::format("wrote {}", (o_.out / "procedure.json").string()));
  return status;
}

}  // namespace rcm::dds_node
