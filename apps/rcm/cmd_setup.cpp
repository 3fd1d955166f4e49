// rcm setup: between docking and the first estimate, is the arm ready? Checks
// the session's free space and calibration, fits the free-space model and the
// tissue model, saves them for `rcm monitor` and the nodes, and says "ready" or what is
// missing. Exit status 3 when not ready (the report is written either way).
#include <filesystem>
#include <iostream>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/estimation/joint_tissue_file.hpp"
#include "rcm/estimation/setup.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/session.hpp"
#include "study_cli.hpp"

namespace {
namespace cmd_setup {

struct Options {
  std::string session, out = "rcm-setup", options_file;
  rcm::cli::OptionFlags<rcm::StudyOptions> study;
  rcm::cli::OptionFlags<rcm::SetupOptions> setup;
  bool json = false;
};

void run(const Options& o) {
  rcm::SetupOptions setup_options;
  o.setup.apply(setup_options);
  rcm::StudyOptions study = rcm::cli::make_study_options(o.study, o.options_file);
  const rcm::Session session = rcm::load_session(o.session);
  const rcm::SetupReport report = rcm::run_setup(session, study, setup_options, rcm::cli::get_torque_model_fitter());
  const std::filesystem::path out(o.out);
  std::filesystem::create_directories(out);
  // The model is saved whether or not the arm is ready: a team that accepts a
  // finding can still monitor with it.
  const std::filesystem::path model_file = study.model_file ? *study.model_file : out / "free_space_model.json";
  if (!study.model_file) rcm::dynamics::save_torque_model(model_file, *report.free_space.model);
  // The tissue model identified on the calibration with that model: the
  // monitor and the nodes load it (--tissue-model-file) rather than identify it again.
  if (report.tissue)
    rcm::save_joint_tissue_model(out / "tissue_model.json", *report.tissue,
                                 rcm::get_tissue_model_origin(session, model_file));
  rcm::save_json_file(out / "setup.json", report.to_json());
  if (o.json) {
    rcm::cli::print_json(report.to_json());
  } else {
    std::cout << report.to_text();
    if (!study.model_file)
      std::cout << "model: " << (out / "free_space_model.json").string() << " (rcm monitor --model-file)\n";
    if (report.tissue)
      std::cout << "tissue model: " << (out / "tissue_model.json").string() << " (rcm monitor --tissue-model-file)\n";
    std::cout << "report: " << (out / "setup.json").string() << "\n";
  }
  if (!report.ready) throw rcm::cli::ExitStatus{3};
}

const bool registered = rcm::cli::register_command({"setup", 55, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "setup",
      "Is the arm ready to estimate? Checks the free space and the calibration, fits the free-space and tissue models "
      "(free_space_model.json, tissue_model.json), writes setup.json; exit 3 when not ready, with what is missing");
  cmd->add_option("SESSION", o->session, "rcm-session/1 manifest (free space, q0, calibration)")->required();
  cmd->add_option("--out", o->out, "output folder (default rcm-setup)");
  rcm::cli::add_free_space_flags(cmd, o->study);
  o->setup.add(cmd, "--min-free-space", {"min_free_space_s"});
  o->setup.add(cmd, "--workspace", {"workspace_half_range"});
  o->setup.add(cmd, "--min-reversals", {"min_reversals"});
  o->setup.add(cmd, "--min-calibration", {"min_calibration_s"});
  o->setup.add(cmd, "--min-pivot", {"min_calibration_pivot_rad"});
  o->setup.add(cmd, "--max-outside-regime", {"max_outside_regime_fraction"});
  o->setup.add(cmd, "--max-force-error", {"max_force_error_n"});
  o->setup.add(cmd, "--max-calibration-error", {"max_calibration_error_m"});
  rcm::cli::add_options_file_flag(cmd, o->options_file);
  cmd->add_flag("--json", o->json, "print the report (setup.json) on stdout");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_setup
}  // namespace
