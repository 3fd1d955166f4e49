// rcm_play_dds: plays a joint trajectory on an arm that speaks CRTK over ROS 2
// (a dVRK, or rcm_sim_psm_dds) and records its measured_js, without ROS 2. What
// it decides per message is rcm::TrajectoryPlayer (include/rcm/live/); this
// file reads the flags, talks to the arm (dds/support/crtk_client.hpp) and
// writes the recording. docs/howto-procedure.md.
//
//   rcm_play_dds excitation.csv --out free_space.csv [--arm PSM1]
//   rcm_play_dds --hold 10 --q0 0,0,0.12 --out baseline.csv
//   rcm_play_dds --record 30 --out calibration.csv
//
// Exit status: 0 played; 2 bad input; 3 the arm refused or could not be
// reached (not ENABLED, not homed, silent); 4 a safety stop mid-play (the
// recording up to the stop is written).

#include <CLI/CLI.hpp>
#include <dds/dds.h>
#include <fmt/format.h>

#include <cstdio>
#include <iostream>
#include <string>

#include "support/program_main.hpp"
#include "support/crtk_client.hpp"
#include "rcm/common/command_line.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/joint_trajectory.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/live/trajectory_player.hpp"

namespace {

using namespace rcm::dds_node;

rcm::InputLocation flag(const std::string& name) { return rcm::InputLocation::plain("command line", name); }

int run(int argc, char** argv) {
  CLI::App app{"rcm_play_dds: play a joint trajectory on a CRTK arm over ROS 2 (DDS) and record its measured_js"};
  std::string trajectory_file, out, arm = "PSM1", q0_text, max_error_text, tolerance_text, json_file;
  double hold_s = 0, record_s = 0, hold_rate_hz = 100.0;
  bool power = false;
  int domain = -1;
  rcm::PlayerOptions o;
  app.add_option("TRAJECTORY", trajectory_file, "joint trajectory CSV (time, position_i, velocity_i; rcm excite writes one)");
  app.add_option("--out", out, "the recording of measured_js (rcm CSV; time: the arm's header stamps, s)")->required();
  app.add_option("--arm", arm, "arm namespace: /<arm>/measured_js, /<arm>/servo_jp, ...")->capture_default_str();
  app.add_option("--hold", hold_s, "instead of a file: hold at --q0 for this long (s of the arm's time): the baseline");
  app.add_option("--q0", q0_text, "the pose of --hold: joints 1..N, comma separated (rad, rad, m, ...)");
  app.add_option("--hold-rate", hold_rate_hz, "servo_jp rows per second of --hold (Hz)")->capture_default_str();
  app.add_option("--record", record_s, "instead of a file: record this long (s of the arm's time) without commanding");
  app.add_option("--max-tracking-error", max_error_text,
                 "stop beyond this |measured - setpoint| per joint, comma separated (rad or m; the last for the rest; "
                 "default 0.05,0.05,0.005,0.2)");
  app.add_option("--goal-tolerance", tolerance_text,
                 "the first row is reached within this per joint (rad or m; default 0.01,0.01,0.001,0.01)");
  app.add_option("--measured-timeout-s", o.measured_timeout_s, "stop when no measured_js came for this long (s, wall)")
      ->capture_default_str();
  app.add_option("--start-timeout-s", o.start_timeout_s, "give up when the arm is not heard within this (s, wall)")
      ->capture_default_str();
  app.add_option("--move-timeout-s", o.move_timeout_s, "give up when the first row is not reached within this (s of the arm's time)")
      ->capture_default_str();
  app.add_option("--settle-s", o.settle_s, "record this long after the last row (s of the arm's time)")->capture_default_str();
  app.add_option("--stall-s", o.stall_s,
                 "pause the file on measured_js this late (s, arm's time; 0: never)")
      ->capture_default_str();
  app.add_flag("--power", power, "enable and home the arm first (state_command enable, home)");
  app.add_option("--json", json_file, "write the summary as JSON to this file");
  app.add_option("--domain", domain, "DDS domain (default: ROS_DOMAIN_ID, else 0)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return rcm::exit_on_parse_error(app, e);
  }
  const int sources = !trajectory_file.empty() + (hold_s > 0) + (record_s > 0);
  if (sources != 1)
    throw rcm::InputError(flag("TRAJECTORY"), "give exactly one of a trajectory file, --hold S or --record S");
  if (hold_s < 0) throw rcm::InputError(flag("--hold"), "must be > 0");
  if (record_s < 0) throw rcm::InputError(flag("--record"), "must be > 0");
  if (!max_error_text.empty()) o.max_tracking_error = rcm::parse_number_list(max_error_text, flag("--max-tracking-error"));
  if (!tolerance_text.empty()) o.goal_tolerance = rcm::parse_number_list(tolerance_text, flag("--goal-tolerance"));
  o.check([](const std::string& name) { return flag(rcm::get_flag_name(name)); });
  if (!(hold_rate_hz > 0)) throw rcm::InputError(flag("--hold-rate"), "must be > 0");
  const int d = get_domain(domain, "command line");

  std::optional<rcm::TrajectoryPlayer> player;
  if (!trajectory_file.empty()) {
    player.emplace(rcm::load_joint_trajectory(trajectory_file), o);
  } else if (hold_s > 0) {
    if (q0_text.empty()) throw rcm::InputError(flag("--q0"), "required with --hold: the pose to hold");
    const std::vector<double> q = rcm::parse_number_list(q0_text, flag("--q0"));
    player.emplace(rcm::make_hold_trajectory(Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<Eigen::Index>(q.size())),
                                             hold_s, hold_rate_hz),
                   o);
  } else {
    player.emplace(record_s, o);
  }

  const dds_entity_t participant =
      check(dds_create_participant(static_cast<dds_domainid_t>(d), nullptr, nullptr), "create participant");
  CrtkClient client(participant, arm);
  std::string why;
  const auto interrupted = [] { return rcm::dds_node::is_stop_requested(); };
  if (!wait_for_arm(client, power, o.start_timeout_s + (power ? 30.0 : 0.0), interrupted, why)) {
    std::fprintf(stderr, "rcm_play_dds: refused: %s\n", why.c_str());
    dds_delete(participant);
    return 3;
  }
  std::fprintf(stderr, "rcm_play_dds: the arm on /%s/ is %s%s\n", arm.c_str(), client.get_state().state.c_str(),
               client.get_state().homed ? ", homed" : ", not homed");
  run_player(client, *player, interrupted, [&](const rcm::TrajectoryPlayer& p, std::int64_t) {
    const rcm::PlayerSummary& s = p.summary();
    std::fprintf(stderr, "rcm_play_dds: %s: %.1f / %.1f s of the arm's time, %zu rows sent, %zu samples recorded\n",
                 rcm::to_string(p.phase()), s.recorded_span_s, s.file_duration_s, s.rows_sent, s.samples_recorded);
  });
  if (!player->finished()) player->compute_tick(get_steady_ns());
  dds_delete(participant);

  const rcm::PlayerSummary& s = player->summary();
  const std::string message = rcm::dds_node::is_stop_requested() && !player->finished() ? "interrupted" : s.message;
  if (s.samples_recorded > 0) rcm::save_recording(out, player->get_recording(out));
  std::cout << format_player_summary(s, player->joint_names());
  if (s.samples_recorded > 0) std::cout << "  wrote " << out << "\n";
  if (!json_file.empty()) {
    nlohmann::json j = rcm::to_json(s, player->joint_names());
    j["phase"] = rcm::to_string(player->phase());
    j["recording"] = s.samples_recorded > 0 ? nlohmann::json(out) : nlohmann::json(nullptr);
    rcm::save_json_file(json_file, j);
  }
  if (player->phase() == rcm::PlayerPhase::refused) {
    std::fprintf(stderr, "rcm_play_dds: refused: %s\n", message.c_str());
    return 3;
  }
  if (player->phase() != rcm::PlayerPhase::done) {
    std::fprintf(stderr, "rcm_play_dds: stopped: %s\n", message.c_str());
    return 4;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcm::dds_node::run_program("rcm_play_dds", argc, argv, run); }
