// rcm demo: simulate the default bench, run the whole study, print Table IV.
#include <chrono>
#include <iostream>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/io/session.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"
#include "study_cli.hpp"

namespace {
namespace cmd_demo {

struct Options {
  std::string out = "demo-out";
  rcm::cli::OptionFlags<rcm::StudyOptions> study;  // --model, --method
  unsigned seed = 1;
  bool quick = false, json = false;
  double max_minutes = 0.0;
};

void run(const Options& o) {
  const auto start = std::chrono::steady_clock::now();
  rcm::StudyOptions options = rcm::cli::make_study_options(o.study);  // bad flags stop before the simulation
  const std::filesystem::path out(o.out);
  const std::filesystem::path bench_dir = out / "bench";
  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  config.seed = o.seed;
  if (o.quick) {
    // Smoke-test size: the same protocol, shorter recordings.
    config.protocol.free_space_s = 150.0;
    config.protocol.calibration_s = 30.0;
    config.protocol.trial_s = 30.0;
    config.protocol.static_hold_s = 4.0;
    config.protocol.baseline_hold_s = 4.0;
  }
  rcm::install_interrupt_handlers();
  std::cerr << "[rcm] simulating the phantom bench into " << bench_dir.string() << std::endl;
  const rcm::sim::SessionWriteSummary written =
      rcm::sim::simulate_session(config, bench_dir, [](const std::string& m) { std::cerr << "[rcm]   " << m << std::endl; });
  // Fig. 3 sweep, referenced from the session so that the report draws it.
  rcm::sim::ForceAngleResult sweep;
  try {
    sweep = rcm::sim::run_force_angle_experiment(config);
  } catch (const rcm::Interrupted& e) {
    throw rcm::Interrupted(std::string(e.what()) + "; the simulated session in " + bench_dir.string() +
                           " was kept, no report written");
  }
  rcm::sim::save_force_angle_csv(bench_dir / "force_angle.csv", sweep);
  rcm::Session session = rcm::load_session(written.manifest);
  session.extra["force_angle"] = "force_angle.csv";
  rcm::save_session(written.manifest, session);
  session = rcm::load_session(written.manifest);

  options.fit.seed = options.joint.seed = o.seed;
  options.fit.max_minutes = o.max_minutes > 0 ? o.max_minutes : (o.quick ? 0.75 : 5.0);
  if (o.quick) {
    options.joint.bootstrap_replicates = 20;
    options.joint.calibration_bootstrap_replicates = 10;
  }
  rcm::StudyResult result;
  try {
    result = rcm::run_study(session, options, rcm::cli::get_torque_model_fitter());
  } catch (const rcm::Interrupted& e) {
    throw rcm::Interrupted(std::string(e.what()) + "; the simulated session in " + bench_dir.string() +
                           " was kept, no report written");
  }
  const auto report = rcm::write_study_report(result, session, out / "report");
  if (result.interrupted)
    throw rcm::Interrupted("interrupted after " + std::to_string(result.trials.size()) + " of " +
                           std::to_string(result.trials_planned) + " trials; " + report.string() +
                           " and results.json cover them, figures not drawn; the simulated session in " +
                           bench_dir.string() + " was kept");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (o.json) {
    nlohmann::json j = result.to_json();
    j["demo_seconds"] = seconds;
    j["report"] = report.string();
    rcm::cli::print_json(j);
    return;
  }
  std::cout << "\nTable IV -- misalignment estimates on the simulated bench (" << rcm::dynamics::to_string(result.model_kind)
            << " free-space model)\n"
            << rcm::format_table_iv(result) << "\nreport:  " << report.string() << "\nsession: "
            << written.manifest.string() << "\n"
            << "done in " << static_cast<int>(seconds) << " s\n";
}

const bool registered = rcm::cli::register_command({"demo", 5, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("demo", "Simulate the default phantom bench, run the whole study, print Table IV and write the report");
  cmd->add_option("--out", o->out, "output folder (default demo-out): bench/ (the session) and report/");
  cmd->add_flag("--quick", o->quick, "shorter recordings and training, for a smoke test");
  cmd->add_option("--seed", o->seed, "seed of the simulation and of the model fit");
  o->study.add(cmd, "--model", {"model_kind"},
               "free-space model: lstm, mlp, linear or hybrid (unset: " +
                   rcm::dynamics::to_string(rcm::dynamics::get_default_model_kind()) + ")");
  o->study.add(cmd, "--method", {"method"});
  cmd->add_option("--max-train-minutes", o->max_minutes, "budget of the free-space fit (default 5, --quick 0.75)");
  cmd->add_flag("--json", o->json, "print results.json (plus demo_seconds) on stdout");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_demo
}  // namespace
