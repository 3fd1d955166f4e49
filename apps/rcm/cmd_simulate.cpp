// `rcm simulate`: the simulated phantom bench (docs/simulator.md).

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <memory>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/joint_trajectory.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/session.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/closed_loop.hpp"
#include "rcm/sim/sim_config.hpp"
#include "study_cli.hpp"

namespace {
namespace cmd_simulate {

struct SimulateOptions {
  std::string out;
  std::string experiment = "session";
  std::string tissue;
  std::string friction;
  std::string arm;
  std::string config_file;
  std::string free_space_trajectory;
  std::uint64_t seed = 0;
  bool seed_given = false;
  bool quick = false;
  bool json = false;
  bool print_config = false;
  bool no_truth = false;
  bool no_plot = false;
  bool exact_sensors = false;
  double free_space_s = -1, trial_s = -1, calibration_s = -1;
  int threads = 0;
  rcm::cli::OptionFlags<rcm::StudyOptions> free_space;  // closed-loop: the estimator's free-space model
  rcm::cli::OptionFlags<rcm::CorrectionOptions> correction;  // closed-loop: the corrector's gates, every scenario
  rcm::cli::OptionFlags<rcm::OnlineEstimatorOptions> online;  // closed-loop: over the bench's estimator options
  rcm::cli::OptionFlags<rcm::sim::ClosedLoopOptions> loop;    // closed-loop: the loop across processes, modelled
  std::string motions;                                         // closed-loop: these motions only
};

// The flags that only the closed-loop bench reads.
const char* const kClosedLoopFlags[] = {"--model",          "--model-file",     "--tolerance",
                                        "--compensate-limit", "--max-shift-rate", "--correlation-time",
                                        "--stream-rate",      "--loop-delay",     "--teleop-stream", "--motions"};

std::string config_help() {
  const rcm::sim::SimConfig defaults = rcm::sim::make_default_config();
  std::string text =
      "\nConfiguration (--config FILE: a JSON object; nested keys as below, any subset;\n"
      "unknown keys and wrong types are errors). Defaults:\n";
  for (const auto& f : rcm::sim::describe_config(defaults))
    text += fmt::format("  {:<46} {:<24} {}\n", f.path, f.value, f.help);
  text += "\nOrder of precedence: defaults < --tissue, --arm, --friction < --config < command-line flags.\n";
  return text;
}

nlohmann::json vec_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

// The closed-loop bench: a session to prepare the estimator on (free space,
// calibration, one trial), then every incision motion open and closed loop.
void run_closed_loop(const SimulateOptions& o, const rcm::CorrectionOptions& correction,
                     const rcm::sim::SimConfig& config, const std::filesystem::path& out_dir) {
  using namespace rcm::sim;
  // The loop's options and motions first: a bad one is told before the session is made.
  ClosedLoopOptions options;
  o.loop.apply(options);
  std::vector<IncisionMotion> motions = make_default_incision_motions();
  if (!o.motions.empty()) {
    std::vector<IncisionMotion> chosen;
    std::vector<std::string> names;
    for (std::size_t from = 0; from <= o.motions.size();) {
      const std::size_t end = std::min(o.motions.find(',', from), o.motions.size());
      names.push_back(o.motions.substr(from, end - from));
      from = end + 1;
    }
    for (const std::string& name : names) {
      const auto it = std::find_if(motions.begin(), motions.end(), [&](const auto& m) { return m.name == name; });
      if (it == motions.end()) {
        rcm::InputLocation loc;
        loc.file = "--motions";
        throw rcm::InputError(loc, "unknown motion '" + name + "'; known: step, drift, breathing, large_step");
      }
      chosen.push_back(*it);
    }
    motions = chosen;
  }
  const auto start = std::chrono::steady_clock::now();
  SimConfig session_config = config;
  session_config.protocol.coaxial_offsets_m = {config.protocol.calibration_offset_m};
  session_config.protocol.radial_offsets_m = {Eigen::Vector2d::Zero()};
  std::cerr << fmt::format("simulate: closed-loop bench, seed {}, tissue {}; the session the estimator is prepared "
                           "on ({:.0f} s free space)\n",
                           config.seed, config.tissue.preset, config.protocol.free_space_s);
  const SessionWriteSummary written = simulate_session(
      session_config, out_dir / "session", [](const std::string& msg) { std::cerr << "simulate: " << msg << "\n"; });
  const rcm::Session session = rcm::load_session(written.manifest);
  rcm::StudyOptions study = rcm::cli::make_study_options(o.free_space);
  study.verbose = true;
  // The loop moves the RCM on the estimate: a model whose torque trails by its
  // zero-phase half window would act on where the incision was that long
  // before, which a breathing incision has left (docs/howto-correction.md).
  study.fit.live_zero_phase = false;
  const rcm::MonitorSetup setup = rcm::prepare_monitor(session, study, rcm::cli::get_torque_model_fitter());
  rcm::OnlineEstimatorOptions online = make_closed_loop_online_options(setup.joint_options);
  o.online.apply(online);
  const rcm::OnlinePipeline pipeline(setup.free_space.model,
                                     rcm::OnlineEstimator(setup.incision, setup.tissue, online));

  options.correction = correction;
  // A limit or a rate given on the command line is the arm's in every
  // scenario, the large step's own included.
  for (IncisionMotion& m : motions) {
    if (o.correction.given("--compensate-limit")) m.compensate_limit_m = 0.0;
    if (o.correction.given("--max-shift-rate")) m.max_rate_m_per_s = 0.0;
  }
  std::cerr << fmt::format("simulate: {} motions, {:.0f} s each, open and closed loop ({} free-space model)\n",
                           motions.size(), options.duration_s,
                           rcm::dynamics::to_string(setup.free_space.model->kind()));
  const std::vector<ClosedLoopScenario> scenarios = run_closed_loop_experiment(config, pipeline, motions, options);
  nlohmann::json j = to_json(scenarios, options);
  j["seed"] = config.seed;
  j["tissue"] = config.tissue.preset;
  j["free_space_model"] = rcm::dynamics::to_string(setup.free_space.model->kind());
  j["online"] = {{"correlation_time_s", online.correlation_time_s},
                 {"jump_threshold", online.jump_threshold},
                 {"drift_sd_m_per_sqrt_s", online.drift_sd_m_per_sqrt_s}};
  j["session"] = written.manifest.string();
  const std::string table = format_closed_loop_table(scenarios);
  // The model the estimator ran on, for `rcm monitor --model-file` and `rcm dynamics eval`.
  if (!study.model_file) {
    rcm::dynamics::save_torque_model(out_dir / "free_space_model.json", *setup.free_space.model);
    j["free_space_model_file"] = (out_dir / "free_space_model.json").string();
  }
  rcm::save_json_file(out_dir / "closed_loop.json", j);
  rcm::write_file_atomic(out_dir / "closed_loop.md", "# Closed-loop bench\n\n" + table);
  rcm::save_json_file(out_dir / "sim_config.json", config_to_json(config));
  std::vector<std::string> figures;
  if (config.force_angle.plot)
    for (const auto& sc : scenarios)
      for (const auto& f : save_closed_loop_plots(out_dir / ("closed_loop_" + sc.motion.name), sc))
        figures.push_back(f.png.string());
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (o.json) {
    j["figures"] = figures;
    j["elapsed_s"] = elapsed;
    rcm::cli::print_json(j);
    return;
  }
  std::cout << table;
  for (const auto& sc : scenarios) {
    std::cout << fmt::format("\n{} (closed loop) advice:\n", sc.motion.name);
    for (const auto& [t, words] : sc.closed.advice) std::cout << fmt::format("  {:7.2f} s  {}\n", t, words);
  }
  std::cout << fmt::format("\nwrote {} and {} figures in {:.1f} s\n", (out_dir / "closed_loop.json").string(),
                           figures.size(), elapsed);
}

// The speed experiment: fast.csv and slow.csv (and their truth), the same
// excitation path at full speed and slowed down.
void run_speed(const SimulateOptions& o, const rcm::sim::SimConfig& config, const std::filesystem::path& out_dir) {
  using namespace rcm::sim;
  const auto start = std::chrono::steady_clock::now();
  std::cerr << fmt::format("simulate: speed experiment, seed {}, {} arm, {} friction; excitation period {:g} s, "
                           "{:g} s at full speed and x{} slower\n",
                           config.seed, config.arm.preset, config.friction_preset, config.speed.period_s,
                           config.speed.duration_s, config.speed.slowdown);
  SpeedExperimentResult r;
  try {
    r = run_speed_experiment(config);
  } catch (const rcm::Interrupted& e) {
    throw rcm::Interrupted(std::string(e.what()) + "; nothing written");
  }
  std::filesystem::create_directories(out_dir);
  rcm::save_json_file(out_dir / "sim_config.json", config_to_json(config));
  nlohmann::json recs = nlohmann::json::array();
  std::vector<std::vector<std::string>> rows;
  for (const SimulatedRecording* rec : {&r.fast, &r.slow}) {
    RecordingFileInfo info = summarize_simulated_recording(*rec);
    info.file = out_dir / (rec->name + ".csv");
    rcm::save_recording(info.file, rec->recording);
    if (config.protocol.write_truth) {
      info.truth_file = out_dir / (rec->name + "_truth.csv");
      save_truth_csv(info.truth_file, *rec);
    }
    const Eigen::Vector3d velocity_rms =
        (rec->recording.velocity.array().square().colwise().mean()).sqrt().transpose();
    const double rate = info.duration_s > 0 ? static_cast<double>(info.samples - 1) / info.duration_s : 0.0;
    recs.push_back({{"name", rec->name},
                    {"file", info.file.string()},
                    {"truth_file", info.truth_file.string()},
                    {"samples", info.samples},
                    {"duration_s", info.duration_s},
                    {"rate_hz", rate},
                    {"velocity_rms", vec_json(velocity_rms)},
                    {"effort_min", vec_json(info.effort_min)},
                    {"effort_max", vec_json(info.effort_max)},
                    {"effort_noise_hf", vec_json(info.effort_noise_hf)}});
    rows.push_back({rec->name, std::to_string(info.samples), fmt::format("{:.1f}", info.duration_s),
                    fmt::format("{:.0f}", rate),
                    fmt::format("{:.2f} / {:.2f} / {:.3f}", velocity_rms[0], velocity_rms[1], velocity_rms[2]),
                    fmt::format("{:.2f}..{:.2f}", info.effort_min[0], info.effort_max[0]),
                    fmt::format("{:.2f}..{:.2f}", info.effort_min[1], info.effort_max[1]),
                    fmt::format("{:.2f}..{:.2f}", info.effort_min[2], info.effort_max[2])});
  }
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const nlohmann::json summary = {{"experiment", "speed"},
                                  {"seed", config.seed},
                                  {"arm", config.arm.preset},
                                  {"friction", config.friction_preset},
                                  {"period_s", config.speed.period_s},
                                  {"slowdown", config.speed.slowdown},
                                  {"elapsed_s", elapsed},
                                  {"recordings", recs}};
  rcm::save_json_file(out_dir / "speed.json", summary);
  if (o.json) {
    rcm::cli::print_json(summary);
    return;
  }
  std::cout << rcm::cli::format_table({"recording", "samples", "s", "Hz", "qd RMS (rad/s, rad/s, m/s)",
                                       "effort_1 N m", "effort_2 N m", "effort_3 N"},
                                      rows);
  std::cout << fmt::format("\nwrote {} and {} in {:.1f} s\n", (out_dir / "fast.csv").string(),
                           (out_dir / "slow.csv").string(), elapsed);
}

void run_simulate(const SimulateOptions& o) {
  using namespace rcm::sim;
  SimConfig config = make_default_config();
  if (!o.tissue.empty()) {
    try {
      apply_tissue_preset(config.tissue, o.tissue);
    } catch (const rcm::InputError& e) {
      rcm::InputLocation loc;
      loc.file = "--tissue";
      throw rcm::InputError(loc, e.reason());
    }
  }
  // The speed experiment puts the motors behind their cables unless told otherwise:
  // its question is how the transmission's physics meets a rigid-body model.
  const std::string arm = !o.arm.empty() ? o.arm : (o.experiment == "speed" ? "cable" : "");
  if (!arm.empty()) {
    try {
      apply_arm_preset(config, arm);
    } catch (const rcm::InputError& e) {
      rcm::InputLocation loc;
      loc.file = "--arm";
      throw rcm::InputError(loc, e.reason());
    }
  }
  if (!o.friction.empty()) {
    try {
      apply_friction_preset(config, o.friction);
    } catch (const rcm::InputError& e) {
      rcm::InputLocation loc;
      loc.file = "--friction";
      throw rcm::InputError(loc, e.reason());
    }
  }
  if (!o.config_file.empty())
    apply_config_json(config, rcm::load_json_file(o.config_file), o.config_file);
  if (o.seed_given) config.seed = o.seed;
  if (o.quick) {
    config.protocol.free_space_s = 120.0;
    config.protocol.calibration_s = 30.0;
    config.protocol.trial_s = 30.0;
    config.protocol.static_hold_s = 5.0;
  }
  if (!o.free_space_trajectory.empty()) {
    // Read here for its length (errors name the file, line and column): each
    // free-space file plays the whole trajectory unless --free-space-s says otherwise.
    const rcm::JointTrajectory trajectory = rcm::load_joint_trajectory(o.free_space_trajectory);
    config.trajectory.free_space_path = "file";
    config.trajectory.free_space_file = o.free_space_trajectory;
    config.protocol.free_space_s =
        (trajectory.time[trajectory.time.size() - 1] - trajectory.time[0]) * std::max(1, config.protocol.free_space_files);
  }
  if (o.free_space_s > 0) config.protocol.free_space_s = o.free_space_s;
  if (o.trial_s > 0) config.protocol.trial_s = o.trial_s;
  if (o.calibration_s > 0) config.protocol.calibration_s = o.calibration_s;
  if (o.threads > 0) config.threads = o.threads;
  if (o.no_truth) config.protocol.write_truth = false;
  if (o.no_plot) config.force_angle.plot = false;
  if (o.exact_sensors) config.sensors.noise = false;
  const std::string source = o.config_file.empty() ? "command line" : o.config_file;
  validate_config(config, source);
  if (o.experiment == "speed") validate_speed_experiment(config, source);

  if (o.experiment != "closed-loop")
    for (const char* flag : kClosedLoopFlags)
      if (o.free_space.given(flag) || o.correction.given(flag) || o.online.given(flag) || o.loop.given(flag) ||
          (std::string(flag) == "--motions" && !o.motions.empty())) {
        rcm::InputLocation loc;
        loc.file = flag;
        throw rcm::InputError(loc, "only --experiment closed-loop reads it");
      }
  rcm::CorrectionOptions correction;
  o.correction.apply(correction);  // a bad gate is an error before anything is simulated
  rcm::OnlineEstimatorOptions online_flags_alone;
  o.online.apply(online_flags_alone);  // so is a bad estimator option
  if (o.print_config) {
    rcm::cli::print_json(config_to_json(config));
    return;
  }
  if (o.out.empty()) {
    rcm::InputLocation loc;
    loc.file = "--out";
    throw rcm::InputError(loc, "an output directory is required");
  }
  const std::filesystem::path out_dir = o.out;
  rcm::install_interrupt_handlers();

  if (o.experiment == "session") {
    auto progress = [&](const std::string& msg) { std::cerr << "simulate: " << msg << "\n"; };
    std::cerr << fmt::format("simulate: session, seed {}, tissue {}, {} friction, {:.0f} s free space + {} trials\n",
                             config.seed, config.tissue.preset, config.friction_preset, config.protocol.free_space_s,
                             config.protocol.coaxial_offsets_m.size() * config.protocol.radial_offsets_m.size());
    const SessionWriteSummary s = simulate_session(config, out_dir, progress);
    if (o.json) {
      nlohmann::json recs = nlohmann::json::array();
      for (const auto& r : s.recordings)
        recs.push_back({{"name", r.name},
                        {"file", r.file.string()},
                        {"truth_file", r.truth_file.string()},
                        {"samples", r.samples},
                        {"duration_s", r.duration_s},
                        {"effort_min", vec_json(r.effort_min)},
                        {"effort_max", vec_json(r.effort_max)},
                        {"effort_noise_hf", vec_json(r.effort_noise_hf)},
                        {"force_max_n", r.force_max_n},
                        {"theta_max_rad", r.theta_max_rad}});
      rcm::cli::print_json({{"experiment", "session"},
                            {"session", s.manifest.string()},
                            {"seed", config.seed},
                            {"tissue", config.tissue.preset},
                            {"friction", config.friction_preset},
                            {"elapsed_s", s.elapsed_s},
                            {"recordings", recs}});
      return;
    }
    std::vector<std::vector<std::string>> rows;
    for (const auto& r : s.recordings)
      rows.push_back({r.name, std::to_string(r.samples), fmt::format("{:.1f}", r.duration_s),
                      fmt::format("{:.2f}..{:.2f}", r.effort_min[0], r.effort_max[0]),
                      fmt::format("{:.2f}..{:.2f}", r.effort_min[1], r.effort_max[1]),
                      fmt::format("{:.2f}..{:.2f}", r.effort_min[2], r.effort_max[2]),
                      fmt::format("{:.1f}", r.theta_max_rad * 180.0 / M_PI),
                      fmt::format("{:.1f}", r.force_max_n)});
    std::cout << rcm::cli::format_table({"recording", "samples", "s", "effort_1 N m", "effort_2 N m",
                                         "effort_3 N", "theta max deg", "|f| max N"},
                                        rows);
    std::cout << fmt::format("\nsession: {}\nwritten in {:.1f} s\n", s.manifest.string(), s.elapsed_s);
  } else if (o.experiment == "force-angle") {
    const auto start = std::chrono::steady_clock::now();
    std::cerr << fmt::format("simulate: force-angle sweep, seed {}, tissue {}\n", config.seed,
                             config.tissue.preset);
    ForceAngleResult r;
    try {
      r = run_force_angle_experiment(config);
    } catch (const rcm::Interrupted& e) {
      throw rcm::Interrupted(std::string(e.what()) + "; nothing written");
    }
    std::filesystem::create_directories(out_dir);
    const auto csv = out_dir / "force_angle.csv";
    save_force_angle_csv(csv, r);
    rcm::save_json_file(out_dir / "sim_config.json", config_to_json(config));
    rcm::PlotFiles plot;
    if (config.force_angle.plot) plot = save_force_angle_plot(out_dir / "force_angle", r);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (o.json) {
      nlohmann::json pts = nlohmann::json::array();
      for (const auto& p : r.points)
        pts.push_back({{"offset_m", p.offset_m},
                       {"theta_rad", p.theta_rad},
                       {"force_n", p.force_n},
                       {"force_std_n", p.force_std_n},
                       {"force_true_n", p.force_true_n},
                       {"force_law_n", p.force_law_n}});
      rcm::cli::print_json({{"experiment", "force-angle"},
                            {"csv", csv.string()},
                            {"png", plot.png.string()},
                            {"svg", plot.svg.string()},
                            {"seed", config.seed},
                            {"tissue", config.tissue.preset},
                            {"friction", config.friction_preset},
                            {"elapsed_s", elapsed},
                            {"points", pts}});
      return;
    }
    // Table: one row per offset, one column per angle (mean |f| in N).
    std::vector<std::string> header{"D mm"};
    for (double a : config.force_angle.angles_deg) header.push_back(fmt::format("{:g} deg", a));
    std::vector<std::vector<std::string>> rows;
    const std::size_t na = config.force_angle.angles_deg.size();
    for (std::size_t d = 0; d < config.force_angle.offsets_m.size(); ++d) {
      std::vector<std::string> row{fmt::format("{:g}", config.force_angle.offsets_m[d] * 1000)};
      for (std::size_t i = 0; i < na; ++i) row.push_back(fmt::format("{:.1f}", r.points[d * na + i].force_n));
      rows.push_back(row);
    }
    std::cout << "|f| at the incision (N), ATI mean over the hold:\n"
              << rcm::cli::format_table(header, rows);
    std::cout << fmt::format("\nwrote {}", csv.string());
    if (config.force_angle.plot) std::cout << fmt::format(", {}, {}", plot.png.string(), plot.svg.string());
    std::cout << fmt::format(" in {:.1f} s\n", elapsed);
  } else if (o.experiment == "closed-loop") {
    run_closed_loop(o, correction, config, out_dir);
  } else if (o.experiment == "speed") {
    run_speed(o, config, out_dir);
  } else {
    rcm::InputLocation loc;
    loc.file = "--experiment";
    throw rcm::InputError(loc,
                          "unknown experiment '" + o.experiment + "'; known: session, force-angle, closed-loop, speed");
  }
}

const bool registered = rcm::cli::register_command({"simulate", 20, [](CLI::App& app) {
  auto opts = std::make_shared<SimulateOptions>();
  auto* cmd = app.add_subcommand(
      "simulate",
      "Simulated phantom bench (closed-loop dVRK Classic PSM, friction identified on a real one, tissue pad, "
      "sensors): write a session (rcm-session/1, with ground truth), the Fig. 3 sweep, the closed loop or the "
      "speed pair");
  cmd->add_option("--out", opts->out, "output directory");
  cmd->add_option("--seed", opts->seed, "random seed (default 1, or the config's)")
      ->each([opts](const std::string&) { opts->seed_given = true; });
  cmd->add_option("--experiment", opts->experiment,
                  "session (default) | force-angle | closed-loop (the correction against a moving incision, "
                  "closed and open loop) | speed (fast.csv, slow.csv: one free-space path at full speed and "
                  "slowed down by speed.slowdown)");
  opts->free_space.add(cmd, "--model", {"model_kind"},
                       "closed-loop: the estimator's free-space model, fitted on the session's free space (unset: "
                       "as rcm monitor)");
  opts->free_space.add(cmd, "--model-file", {"model_file"}, "closed-loop: a saved free-space model instead");
  opts->correction.add(cmd, "--tolerance", {"tolerance_m"}, "closed-loop: the corrector's tolerance");
  opts->correction.add(cmd, "--compensate-limit", {"compensate_limit_m"},
                       "closed-loop: the software shift the arm allows, in every scenario (unset: the large step "
                       "allows 50 mm)");
  opts->correction.add(cmd, "--max-shift-rate", {"max_rate_m_per_s"},
                       "closed-loop: how fast the arm shifts its RCM, in every scenario (unset: the large step "
                       "shifts at 20 mm/s)");
  opts->loop.add(cmd, "--stream-rate", {"stream_rate_hz"},
                 "closed-loop: the rate the estimator reads the arm (0: sensors.log_rate_hz)");
  opts->loop.add(cmd, "--loop-delay", {"loop_delay_s"},
                 "closed-loop: from a sample to its RCM shift taking effect on the arm, as across processes");
  opts->loop.add(cmd, "--teleop-stream", {"teleoperation_stream"},
                 "closed-loop: the surgeon's motion's draw (teleop:n: the simulated PSM's n-th)");
  cmd->add_option("--motions", opts->motions,
                  "closed-loop: these motions only (step,drift,breathing,large_step; default all)");
  opts->online.add(cmd, "--correlation-time", {"correlation_time_s"},
                   "closed-loop: the free-space model error's correlation time the estimator assumes (the "
                   "measurement variance is sigma^2 times it per second; unset: the study's)");
  cmd->add_option("--tissue", opts->tissue, "tissue preset: linear (default), stiffening, viscoelastic, sliding");
  cmd->add_option("--friction", opts->friction,
                  "joint friction preset: hysteretic (default: rate-independent, the real PSM's band), smooth");
  cmd->add_option("--arm", opts->arm,
                  "arm preset: rigid (default; speed: cable), cable (motors drive the links through compliant "
                  "cables, friction on both sides)");
  cmd->add_option("--config", opts->config_file, "JSON file overriding any parameter (keys below)");
  cmd->add_flag("--quick", opts->quick, "short session: 120 s free space, 30 s calibration and trials");
  cmd->add_option("--free-space-s", opts->free_space_s,
                  "free-space duration, s (default 900; with --free-space-trajectory the file's)");
  cmd->add_option("--free-space-trajectory", opts->free_space_trajectory,
                  "record free space along this joint trajectory CSV (time, position_1..N, velocity_1..N; rcm "
                  "excite writes one) instead of the random teleoperation");
  cmd->add_option("--trial-s", opts->trial_s, "duration of each trial, s (default 60)");
  cmd->add_option("--calibration-s", opts->calibration_s, "calibration duration, s (default 60)");
  cmd->add_option("--threads", opts->threads, "worker threads (default 2)");
  cmd->add_flag("--no-truth", opts->no_truth, "do not write *_truth.csv");
  cmd->add_flag("--no-plot", opts->no_plot, "force-angle, closed-loop: skip the gnuplot figures");
  cmd->add_flag("--exact-sensors", opts->exact_sensors, "no sensor noise or quantization");
  cmd->add_flag("--print-config", opts->print_config, "print the resolved configuration as JSON and exit");
  cmd->add_flag("--json", opts->json, "print the summary as one JSON object");
  cmd->footer(config_help());
  cmd->callback([opts] { run_simulate(*opts); });
}});

}  // namespace cmd_simulate
}  // namespace
