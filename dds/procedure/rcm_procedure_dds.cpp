// rcm_procedure_dds: docking to the first estimate, in one command, on an arm
// that speaks CRTK over ROS 2 (a dVRK, or rcm_sim_psm_dds with --simulator):
//
//   excitation   `rcm excite` designs it (or --excitation FILE); played in free
//                space, measured_js recorded: free_space.csv
//   baseline     a hold at q0, docked and aligned: baseline.csv
//   calibration  at the known coaxial offset D*, the arm teleoperated (or
//                --calibration-trajectory played): calibration.csv
//   setup        `rcm setup` on session.json: ready, or what is missing
//   live         rcm_monitor_dds with the setup's model; against the simulator
//                a check at a known misalignment (the estimate against the
//                truth), then with --software-rcm and --incision-motion the loop
//                closed across processes; on an arm, the live monitor
//
// The phases play and record in this process (rcm::TrajectoryPlayer,
// dds/support/crtk_client.hpp); `rcm excite`, `rcm setup` and rcm_monitor_dds
// run as child processes, the same programs a team runs by hand. Every
// recording, session.json (rcm-session/1, for `rcm run`), the setup's folder,
// the monitors' logs and procedure.json land in --out. docs/howto-procedure.md.

#include <CLI/CLI.hpp>
#include <dds/dds.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <thread>

#include "support/program_main.hpp"
#include "support/child_process.hpp"
#include "support/crtk_client.hpp"
#include "live_observer.hpp"
#include "procedure.hpp"
#include "rcm/common/command_line.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"

namespace {

rcm::InputLocation flag(const std::string& name) { return rcm::InputLocation::plain("command line", name); }

Eigen::Vector3d parse_vector(const std::string& text, const std::string& name) {
  Eigen::Vector3d v;
  char c1 = 0, c2 = 0;
  int used = 0;
  if (std::sscanf(text.c_str(), "%lf%c%lf%c%lf%n", &v[0], &c1, &v[1], &c2, &v[2], &used) < 5 || c1 != ',' ||
      c2 != ',' || used != static_cast<int>(text.size()) || !v.allFinite())
    throw rcm::InputError(flag(name), "expected three numbers separated by commas, got '" + text + "'");
  return v;
}

int run(int argc, char** argv) {
  rcm::dds_node::ProcedureOptions o;
  std::string q0_text = "0,0,0.12", check_text = "0.005,0.010,0.025", setup_args, excite_args;
  std::optional<double> tolerance, limit, rate;
  CLI::App app{"rcm_procedure_dds: docking to the first estimate on a CRTK arm over ROS 2 (DDS): excitation, baseline, "
               "calibration, rcm setup, then the live monitor"};
  app.add_option("--out", o.out, "folder of every recording, session.json, setup/ and procedure.json")
      ->capture_default_str();
  app.add_option("--arm", o.arm, "arm namespace: /<arm>/measured_js, /<arm>/servo_jp, ...")->capture_default_str();
  app.add_flag("--simulator", o.simulator,
               "the arm is rcm_sim_psm_dds: place the incision through /<arm>/sim/incision_command, no prompts");
  app.add_flag("--power", o.power, "enable and home the arm first (state_command enable, home)");
  app.add_flag("--yes", o.yes, "on an arm: do not wait for Enter before each docking step");
  app.add_option("--q0", q0_text, "the docking pose: joints 1-3 (rad, rad, m)")->capture_default_str();
  app.add_option("--robot", o.robot, "robot description of the session")->capture_default_str();
  app.add_option("--excitation", o.excitation, "a joint trajectory to play in free space (default: rcm excite designs one)");
  app.add_option("--excite-duration", o.excite_duration_s, "length of the excitation rcm excite designs (s)")
      ->capture_default_str();
  app.add_option("--seed", o.seed, "seed of rcm excite's design and of the monitor")->capture_default_str();
  app.add_option("--baseline-s", o.baseline_s, "the baseline hold at q0 (s of the arm's time)")->capture_default_str();
  app.add_option("--calibration-offset-m", o.calibration_offset_m, "the known coaxial offset D* of the calibration (m)")
      ->capture_default_str();
  app.add_option("--calibration-s", o.calibration_s, "the calibration's length (s of the arm's time)")->capture_default_str();
  app.add_option("--calibration-trajectory", o.calibration_trajectory,
                 "play this trajectory for the calibration (default: record while the arm is teleoperated)");
  app.add_option("--setup-args", setup_args, "more flags for rcm setup, one string (e.g. \"--min-free-space 60\")");
  app.add_option("--excite-args", excite_args, "more flags for rcm excite, one string (e.g. \"--max-iterations 20\")");
  app.add_option("--check-offset", check_text,
                 "simulator: the incision's misalignment of the check, dr_x,dr_y,D (m)")->capture_default_str();
  app.add_option("--check-s", o.check_s, "simulator: the check's length (s of the arm's time; 0: no check)")
      ->capture_default_str();
  app.add_option("--live-s", o.live_s, "on an arm: how long the live monitor runs and records (s; 0: until Ctrl-C)")
      ->capture_default_str();
  app.add_flag("--software-rcm", o.software_rcm,
               "the monitor closes the loop: it commands the software RCM shift (the simulator's --software-rcm)");
  app.add_option("--incision-motion", o.incision_motion,
                 "simulator, with --software-rcm: the loop segment's incision motion (step, drift, breathing, large_step)");
  app.add_option("--loop-s", o.loop_s, "the loop segment's length (s of the arm's time)")->capture_default_str();
  app.add_option("--jump-threshold", o.jump_threshold,
                 "the loop segment's change-point test (the monitor's --jump-threshold, nats)")->capture_default_str();
  app.add_option("--tolerance-m", tolerance, "the monitor's --tolerance-m (m; default: the monitor's)");
  app.add_option("--compensate-limit-m", limit, "the monitor's --compensate-limit-m (m; default: the motion's, else the monitor's)");
  app.add_option("--max-shift-rate-m-per-s", rate, "the monitor's --max-shift-rate-m-per-s (m/s; default: the motion's, else the monitor's)");
  app.add_option("--max-tracking-error", o.max_tracking_error_text,
                 "players: stop beyond this |measured - setpoint| per joint, comma separated (rad or m)");
  app.add_option("--measured-timeout-s", o.player.measured_timeout_s, "players: stop when no measured_js came for this long (s, wall)")
      ->capture_default_str();
  app.add_option("--stall-s", o.player.stall_s,
                 "players: pause the file on measured_js this late (s, arm's time; 0: never)")
      ->capture_default_str();
  app.add_option("--session", o.session,
                 "with --model-file: a setup made before; go straight to the live phase (rcm-session/1)");
  app.add_option("--model-file", o.model_file, "with --session: its free-space model (free_space_model.json)");
  app.add_option("--tissue-model-file", o.tissue_model_file,
                 "with --session: its tissue_model.json (default: identified again)");
  app.add_option("--rcm", o.rcm, "the rcm program (default: beside this one)");
  app.add_option("--monitor", o.monitor, "the rcm_monitor_dds program (default: beside this one)");
  app.add_option("--domain", o.domain, "DDS domain (default: ROS_DOMAIN_ID, else 0)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return rcm::exit_on_parse_error(app, e);
  }
  o.q0 = parse_vector(q0_text, "--q0");
  o.check_offset_m = parse_vector(check_text, "--check-offset");
  o.tolerance_m = tolerance;
  o.compensate_limit_m = limit;
  o.max_shift_rate_m_per_s = rate;
  auto split = [](const std::string& text, std::vector<std::string>& words) {
    for (std::size_t start = 0; start < text.size();) {
      const std::size_t end = std::min(text.find(' ', start), text.size());
      if (end > start) words.push_back(text.substr(start, end - start));
      start = end + 1;
    }
  };
  split(setup_args, o.setup_args);
  split(excite_args, o.excite_args);
  o.check(flag);
  o.domain = rcm::dds_node::get_domain(o.domain, "command line");

  rcm::dds_node::Procedure procedure(o, [] { return rcm::dds_node::is_stop_requested(); });
  return procedure.run();
}

}  // namespace

int main(int argc, char** argv) { return rcm::dds_node::run_program("rcm_procedure_dds", argc, argv, run); }
