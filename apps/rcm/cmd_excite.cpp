// `rcm excite`: an excitation trajectory for free-space data collection
// (docs/howto-record-free-space.md).

#include <fmt/format.h>

#include <iostream>
#include <memory>
#include <string>

#include "cli_options.hpp"
#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/excitation.hpp"
#include "rcm/io/joint_trajectory.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace {
namespace cmd_excite {

struct ExciteArgs {
  std::string out;
  std::string robot = "dvrk-psm-classic";
  bool json = false;
  rcm::cli::OptionFlags<rcm::dynamics::ExcitationOptions> options;
};

void run_excite(const ExciteArgs& a) {
  using namespace rcm::dynamics;
  if (!a.options.given("--duration"))
    throw rcm::InputError(rcm::cli::flag_location("--duration"), "required: the trajectory's length in seconds");
  ExcitationOptions o;
  a.options.apply(o);
  const rcm::PsmModel robot = rcm::load_robot_model(a.robot, "--robot");
  // q0 against the robot's limits before the work, naming the flag.
  check_excitation_start(get_excitation_limits(robot, o), o.q0,
                         rcm::InputLocation::plain("command line", a.options.given("--q0") ? "--q0" : "q0 (default)"));
  const ExcitationTrajectory r = design_excitation(robot, o);

  rcm::JointTrajectory file;
  file.source = a.out;
  file.time = r.time;
  file.position = r.position;
  file.velocity = r.velocity;
  rcm::save_joint_trajectory(a.out, file);

  const ExcitationSummary& s = r.summary;
  if (a.json) {
    nlohmann::json joints = nlohmann::json::array();
    for (int j = 0; j < 3; ++j)
      joints.push_back({{"index", j + 1},
                        {"position_min", r.position.col(j).minCoeff()},
                        {"position_max", r.position.col(j).maxCoeff()},
                        {"velocity_max_abs", r.velocity.col(j).cwiseAbs().maxCoeff()},
                        {"acceleration_max_abs", r.acceleration.col(j).cwiseAbs().maxCoeff()},
                        {"velocity_reversals", r.reversals[static_cast<std::size_t>(j)]}});
    rcm::cli::print_json({{"file", a.out},
                          {"samples", r.time.size()},
                          {"duration_s", r.time[r.time.size() - 1]},
                          {"rate_hz", o.rate_hz},
                          {"periods", s.periods},
                          {"period_s", s.period_s},
                          {"harmonics", o.harmonics},
                          {"seed", o.seed},
                          {"q0", rcm::cli::to_json(o.q0)},
                          {"condition_number", s.condition_number},
                          {"initial_condition_number", s.initial_condition_number},
                          {"converged", s.converged},
                          {"termination", s.termination},
                          {"iterations", s.iterations},
                          {"limits_satisfied", s.limits_satisfied},
                          {"limit_scale", rcm::cli::to_json(s.limit_scale)},
                          {"seconds", s.seconds},
                          {"joints", joints}});
    return;
  }
  std::cout << fmt::format("excitation: {} samples at {:g} Hz, {} period(s) of {:.4g} s, {} harmonics, seed {}\n",
                           r.time.size(), o.rate_hz, s.periods, s.period_s, o.harmonics, o.seed);
  std::cout << fmt::format("regressor condition number {:.4g} (random start {:.4g}); {}\n\n", s.condition_number,
                           s.initial_condition_number, s.brief_report());
  const char* units[3] = {"rad", "rad", "m"};
  std::vector<std::vector<std::string>> rows;
  for (int j = 0; j < 3; ++j)
    rows.push_back({std::to_string(j + 1), units[j], fmt::format("{:.4f}", r.position.col(j).minCoeff()),
                    fmt::format("{:.4f}", r.position.col(j).maxCoeff()),
                    fmt::format("{:.4f}", r.velocity.col(j).cwiseAbs().maxCoeff()),
                    fmt::format("{:.4f}", r.acceleration.col(j).cwiseAbs().maxCoeff()),
                    std::to_string(r.reversals[static_cast<std::size_t>(j)])});
  std::cout << rcm::cli::format_table({"joint", "unit", "min", "max", "|qd| max", "|qdd| max", "reversals"}, rows);
  std::cout << fmt::format("\nwrote {}\n", a.out);
}

const bool registered = rcm::cli::register_command({"excite", 25, [](CLI::App& app) {
  auto args = std::make_shared<ExciteArgs>();
  auto* cmd = app.add_subcommand(
      "excite",
      "Design a free-space excitation: a Fourier path per joint from rest at q0 to rest, within the limits, "
      "optimised for the linear model; writes time,position_1..3,velocity_1..3");
  cmd->add_option("--out", args->out, "output CSV file")->required();
  args->options.add(cmd, "--duration", {"duration_s"},
                    "required here (the default is ExcitationOptions'): the whole trajectory, from rest at q0 to rest at q0");
  args->options.add(cmd, "--rate", {"rate_hz"});
  args->options.add(cmd, "--harmonics", {"harmonics"});
  args->options.add(cmd, "--period", {"period_s"});
  args->options.add(cmd, "--seed", {"seed"});
  args->options.add(cmd, "--q0", {"q0"});
  args->options.add(cmd, "--velocity-max", {"velocity_max"});
  args->options.add(cmd, "--acceleration-max", {"acceleration_max"});
  args->options.add(cmd, "--position-margin", {"position_margin"});
  args->options.add(cmd, "--min-reversals", {"min_reversals"});
  args->options.add(cmd, "--position-coverage", {"position_coverage"});
  args->options.add(cmd, "--speed-coverage", {"speed_coverage"});
  args->options.add(cmd, "--max-iterations", {"max_iterations"});
  cmd->add_option("--robot", args->robot, "built-in robot name or rcm-robot/1 JSON file (its joint limits)");
  cmd->add_flag("--json", args->json, "print the summary as one JSON object");
  cmd->callback([args] { run_excite(*args); });
}});

}  // namespace cmd_excite
}  // namespace
