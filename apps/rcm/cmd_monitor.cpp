// rcm monitor: replay a recording as a stream through the online estimator
// (free-space model stepped with its state, bank of EKFs on the offsets, onset
// CUSUM, force alarm), printing the running estimate and the alarms.

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <iterator>
#include <memory>
#include <optional>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/io/session.hpp"
#include "study_cli.hpp"

namespace {
namespace cmd_monitor {

struct Options {
  std::string session, recording, out, options_file;
  rcm::cli::OptionFlags<rcm::StudyOptions> study;
  rcm::cli::OptionFlags<rcm::OnlineEstimatorOptions> online;  // over the options the joint method gives it
  rcm::cli::OptionFlags<rcm::CorrectionOptions> correction;
  rcm::cli::OptionFlags<rcm::OnlineReplayOptions> replay;
  double print_every_s = 1.0;
  bool json = false, quiet = false;
};

std::optional<Eigen::Vector3d> find_truth(const rcm::Session& session, const std::filesystem::path& recording) {
  std::error_code ec;
  const auto target = std::filesystem::weakly_canonical(recording, ec);
  for (const auto& t : session.trials)
    if (std::filesystem::weakly_canonical(t.recording, ec) == target) return t.truth_misalignment_m;
  return std::nullopt;
}

void run(const Options& o) {
  if (!(o.print_every_s >= 0)) throw rcm::InputError(rcm::cli::flag_location("--print-every"), "must be >= 0");
  // Every flag checked before the work: the online estimator's over its defaults here.
  rcm::OnlineEstimatorOptions online_flags_alone;
  o.online.apply(online_flags_alone);
  rcm::CorrectionOptions correction;
  o.correction.apply(correction);
  rcm::OnlineReplayOptions replay_options;
  o.replay.apply(replay_options);
  const rcm::StudyOptions options = rcm::cli::make_study_options(o.study, o.options_file);
  const rcm::Session session = rcm::load_session(o.session);
  // The recording streams through the pipeline a chunk at a time: memory does not grow with its length.
  const auto reader = rcm::open_recording(o.recording, options.read);
  rcm::Recording chunk;
  const bool any = reader->read_chunk(chunk);
  const rcm::MonitorSetup setup = rcm::prepare_monitor(session, options, rcm::cli::get_torque_model_fitter());
  const rcm::dynamics::TorqueModel& model = *setup.free_space.model;
  // The sampling-period check reads the first chunk (its median interval), not the whole recording.
  if (auto w = rcm::dynamics::check_sample_period(model, chunk); !w.empty()) std::cerr << "warning: " << w << "\n";

  rcm::OnlineEstimatorOptions online = rcm::make_online_options(setup.joint_options);
  o.online.apply(online);
  const rcm::OnlinePipeline pipeline(setup.free_space.model, rcm::OnlineEstimator(setup.incision, setup.tissue, online));
  // A replay: the recorded RCM never moved, so no software shift is in effect;
  // the correction says what the arm would be told at each sample.
  const rcm::RcmCorrector corrector(setup.incision, correction);
  rcm::RcmCorrector::Workspace correction_ws = corrector.create_workspace();
  nlohmann::json correction_events = nlohmann::json::array();
  std::cerr << fmt::format("[rcm] tissue model ({}): k1 {:.1f} N/m, k3 {:.3g} N/m^3, c {:.2f} N s/m, F {:.2f} N\n",
                           setup.tissue.family, setup.tissue.parameters[0], setup.tissue.parameters[1],
                           setup.tissue.parameters[2], setup.tissue.parameters[3]);
  if (setup.free_space.model->get_output_delay_s() > 0)
    std::cerr << fmt::format("[rcm] free-space model {}: its torque, and so each estimate, trails the stream by "
                             "{:.3f} s (the time column says which sample an estimate is for)\n",
                             rcm::dynamics::to_string(setup.free_space.model->kind()),
                             setup.free_space.model->get_output_delay_s());

  // Printing happens in the callback: events at once, the estimate at a cadence.
  const double first_time = any ? chunk.time(0) : 0.0;
  double next_print = first_time;
  // --out: a line per estimate into the file's temporary, renamed when the replay is complete.
  std::optional<rcm::AtomicFileWriter> trace;
  std::string csv;
  if (!o.out.empty()) {
    trace.emplace(o.out);
    trace->append(
        "time,dr_x,dr_y,D,sd_dr_x,sd_dr_y,sd_D,force_x,force_y,force_z,force_norm,cusum,onset,alarm,at_rest,"
        "hypothesis,out_of_regime,regime_flags,action,move_x,move_y,move_z,step_x,step_y,step_z\n");
  }
  bool onset_printed = false;
  double next_regime_print = first_time;
  std::uint32_t regime_since_print = 0;
  if (!o.json && !o.quiet)
    std::cout << fmt::format("{:>9} {:>8} {:>8} {:>8}   {:>6} {:>6} {:>6}  {:>7}  {}\n", "time (s)", "dr_x", "dr_y", "D",
                             "sd_x", "sd_y", "sd_D", "|f| (N)", "(mm)");
  auto on_sample = [&](const rcm::OnlineOutput& out) {
    const rcm::CorrectionOutput& c = corrector.compute_correction(correction_ws, out);
    if (trace) {
      csv.clear();
      fmt::format_to(std::back_inserter(csv), "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", out.time,
                         out.misalignment_m[0], out.misalignment_m[1], out.misalignment_m[2], out.sd_m[0], out.sd_m[1],
                         out.sd_m[2], out.f_inc_base[0], out.f_inc_base[1], out.f_inc_base[2], out.force_norm_n,
                         out.cusum, out.onset ? 1 : 0, out.alarm ? 1 : 0, out.at_rest ? 1 : 0, out.hypothesis,
                         out.out_of_regime ? 1 : 0, out.regime_flags, rcm::to_string(c.action), c.move_base[0],
                         c.move_base[1], c.move_base[2], c.step_base[0], c.step_base[1], c.step_base[2]);
      trace->append(csv);
    }
    if (c.changed) {
      const std::string advice = rcm::describe_correction(c, corrector);
      correction_events.push_back({{"time_s", out.time}, {"action", rcm::to_string(c.action)}, {"advice", advice}});
      if (!o.json) std::cout << fmt::format("{:9.3f}  ADVICE {}\n", out.time, advice);
    }
    if (o.json) return;
    // Leaving the regime is an event, printed at most once per second of recording.
    regime_since_print |= out.regime_flags;
    if (out.out_of_regime && out.time >= next_regime_print) {
      std::cout << fmt::format("{:9.3f}  OUT OF REGIME: {} beyond the free-space model's training data\n", out.time,
                               rcm::dynamics::describe_regime_flags(out.regime_flags));
      next_regime_print = out.time + 1.0;
    }
    if (out.onset && !onset_printed) {
      onset_printed = true;
      std::cout << fmt::format("{:9.3f}  ONSET of a misalignment detected\n", out.time);
    }
    if (out.alarm_raised)
      std::cout << fmt::format("{:9.3f}  ALARM: incision force {:.1f} N above {:.1f} N\n", out.time, out.force_norm_n,
                               online.alarm_force_n);
    if (out.alarm_cleared) std::cout << fmt::format("{:9.3f}  alarm cleared ({:.1f} N)\n", out.time, out.force_norm_n);
    if (!o.quiet && o.print_every_s > 0 && out.time >= next_print) {
      next_print = out.time + o.print_every_s;
      const Eigen::Vector3d p = out.misalignment_m * 1e3, sd = out.sd_m * 1e3;
      std::cout << fmt::format("{:9.3f} {:8.2f} {:8.2f} {:8.2f}   {:6.2f} {:6.2f} {:6.2f}  {:7.2f}{}{}{}\n", out.time, p[0],
                               p[1], p[2], sd[0], sd[1], sd[2], out.force_norm_n, out.onset ? "" : "  (no onset yet)",
                               out.alarm ? "  ALARM" : "", regime_since_print ? "  (out of regime)" : "");
      regime_since_print = 0;
    }
  };
  rcm::OnlineReplayer replayer(pipeline, replay_options, on_sample);
  double last_time = first_time;
  for (bool more = any; more; more = reader->read_chunk(chunk)) {
    replayer.add(chunk);
    last_time = chunk.time(chunk.time.size() - 1);
  }
  const rcm::OnlineReplay replay = replayer.finish();
  if (trace) trace->commit();

  const rcm::OnlineOutput& final_out = replay.final_output;
  const rcm::CorrectionOutput& final_correction = correction_ws.output;
  const std::string final_advice = rcm::describe_correction(final_correction, corrector);
  const rcm::AlignmentCheck alignment = rcm::check_alignment(final_out, setup.incision, correction);
  const auto truth = find_truth(session, o.recording);
  const double mean_us = 1e6 * replay.mean_update_s;
  const auto T = static_cast<Eigen::Index>(replay.samples);
  auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };

  if (o.json) {
    nlohmann::json j;
    j["recording"] = reader->source();
    j["samples"] = T;
    j["estimates"] = replay.estimates;
    j["output_delay_s"] = model.get_output_delay_s();
    j["duration_s"] = last_time - first_time;
    j["free_space_model"] = rcm::dynamics::to_string(model.kind());
    j["tissue"] = {{"family", setup.tissue.family},
                   {"k1", setup.tissue.parameters[0]},
                   {"k3", setup.tissue.parameters[1]},
                   {"damping", setup.tissue.parameters[2]},
                   {"axial_friction_n", setup.tissue.parameters[3]}};
    j["final"] = {{"misalignment_m", rcm::cli::to_json(final_out.misalignment_m)},
                  {"sd_m", rcm::cli::to_json(final_out.sd_m)},
                  {"fit_cost", final_out.fit_cost},
                  {"hypothesis", final_out.hypothesis}};
    if (truth) {
      j["truth_m"] = rcm::cli::to_json(*truth);
      j["error_m"] = (final_out.misalignment_m - *truth).norm();
    }
    j["motion_start_s"] = opt(replay.motion_start_s);
    j["onset_s"] = opt(replay.onset_s);
    j["settled_after_s"] = opt(replay.settled_after_s);
    j["settle_band_m"] = replay_options.settle_band_m;
    j["alarm_force_n"] = online.alarm_force_n;
    j["peak_force_n"] = replay.peak_force_n;
    nlohmann::json events = nlohmann::json::array();
    for (const auto& a : replay.alarms)
      events.push_back({{"raised_s", a.raised_s}, {"cleared_s", opt(a.cleared_s)}, {"peak_force_n", a.peak_force_n}});
    j["alarms"] = events;
    j["update_us"] = {{"mean", mean_us}, {"max", 1e6 * replay.max_update_s}};
    j["regime"] = replay.regime.to_json();
    j["correction"] = {{"action", rcm::to_string(final_correction.action)},
                       {"reason", rcm::to_string(final_correction.reason)},
                       {"move_base_m", rcm::cli::to_json(final_correction.move_base)},
                       {"move_inc_m", rcm::cli::to_json(final_correction.move_inc)},
                       {"distance_m", final_correction.distance_m},
                       {"distance_low_m", final_correction.distance_low_m},
                       {"distance_high_m", final_correction.distance_high_m},
                       {"advice", final_advice},
                       {"changes", correction_events},
                       {"tolerance_m", correction.tolerance_m},
                       {"compensate_limit_m", correction.compensate_limit_m},
                       {"max_rate_m_per_s", correction.max_rate_m_per_s}};
    j["alignment"] = {{"aligned", alignment.aligned},
                      {"confident", alignment.confident},
                      {"within_m", alignment.within_m},
                      {"message", alignment.message}};
    j["trace"] = o.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(o.out);
    rcm::cli::print_json(j);
    return;
  }
  const Eigen::Vector3d p = final_out.misalignment_m * 1e3, sd = final_out.sd_m * 1e3;
  std::cout << fmt::format("final      dr_x {:.2f} +- {:.2f}, dr_y {:.2f} +- {:.2f}, D {:.2f} +- {:.2f} mm\n", p[0],
                           1.96 * sd[0], p[1], 1.96 * sd[1], p[2], 1.96 * sd[2]);
  if (truth)
    std::cout << fmt::format("truth      dr_x {:.2f}, dr_y {:.2f}, D {:.2f} mm; e = {:.2f} mm\n", (*truth)[0] * 1e3,
                             (*truth)[1] * 1e3, (*truth)[2] * 1e3, (final_out.misalignment_m - *truth).norm() * 1e3);
  std::cout << fmt::format("onset      {}\n",
                           replay.onset_s ? fmt::format("{:.3f} s", *replay.onset_s) : std::string("not detected"));
  if (replay.settled_after_s)
    std::cout << fmt::format("settled    within {:.0f} mm of the final estimate {:.1f} s after the first motion\n",
                             replay_options.settle_band_m * 1e3, *replay.settled_after_s);
  std::cout << fmt::format("alarms     {} (threshold {:.1f} N), peak model force {:.1f} N\n", replay.alarms.size(),
                           online.alarm_force_n, replay.peak_force_n);
  std::cout << fmt::format("advice     {}\n", final_advice);
  std::cout << fmt::format("alignment  {}\n", alignment.message);
  std::cout << fmt::format("regime     {}\n", replay.regime.to_text());
  std::cout << fmt::format("update     {:.2f} us per sample on average (free-space model + estimator), max {:.1f} us\n",
                           mean_us, 1e6 * replay.max_update_s);
}

const bool registered = rcm::cli::register_command({"monitor", 70, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "monitor", "Replay a recording as a stream through the online estimator: running estimate of all three offsets, "
                 "onset of the misalignment and incision-force alarms; streams in constant memory");
  cmd->add_option("--session", o->session, "rcm-session/1 manifest (free-space data, q0, calibration)")->required();
  cmd->add_option("RECORDING", o->recording, "recording to replay (CSV, bag, rosbag2 directory, .db3 or .mcap)")->required();
  rcm::cli::add_free_space_flags(cmd, o->study);
  o->study.add(cmd, "--tissue-model-file", {"tissue_model_file"},
               "tissue_model.json of rcm setup, made with --model-file");
  cmd->add_option("--print-every", o->print_every_s, "seconds of recording between printed estimates (default 1; 0: none)");
  o->online.add(cmd, "--alarm-force", {"alarm_force_n"});
  o->online.add(cmd, "--onset-threshold", {"onset_threshold"});
  o->replay.add(cmd, "--settle-band", {"settle_band_m"});
  o->correction.add(cmd, "--tolerance", {"tolerance_m"});
  o->correction.add(cmd, "--compensate-limit", {"compensate_limit_m"});
  o->correction.add(cmd, "--max-shift-rate", {"max_rate_m_per_s"});
  cmd->add_option("--out", o->out, "write the running estimate and correction of every sample as CSV");
  rcm::cli::add_options_file_flag(cmd, o->options_file);
  cmd->add_flag("--quiet", o->quiet, "print only events and the summary");
  cmd->add_flag("--json", o->json, "print one JSON object at the end");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_monitor
}  // namespace
