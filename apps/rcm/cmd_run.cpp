// rcm run: the whole study on a session (results.json, report.md, figures/).
#include <iostream>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/session.hpp"
#include "study_cli.hpp"

namespace {
namespace cmd_run {

struct Options {
  std::string session, out = "rcm-run", options_file;
  rcm::cli::OptionFlags<rcm::StudyOptions> study;
  bool json = false;
};

void run(const Options& o) {
  rcm::StudyOptions options = rcm::cli::make_study_options(o.study, o.options_file);
  const rcm::Session session = rcm::load_session(o.session);
  rcm::check_study_inputs(session, options);
  rcm::install_interrupt_handlers();
  rcm::check_study_recordings(session, options);
  const std::filesystem::path out(o.out);
  rcm::FreeSpaceModelStep free_space;
  try {
    free_space = rcm::fit_free_space_step(session, options, rcm::cli::get_torque_model_fitter());
  } catch (const rcm::Interrupted& e) {
    throw rcm::Interrupted(std::string(e.what()) + "; nothing saved");
  }
  // Saved at once, so that `rcm monitor --model-file` and later runs can reuse
  // the fit even if the rest of the study is interrupted.
  std::filesystem::create_directories(out);
  const std::filesystem::path model_path = out / "free_space_model.json";
  rcm::dynamics::save_torque_model(model_path, *free_space.model);
  rcm::StudyResult result;
  try {
    result = rcm::run_study(session, options, std::move(free_space));
  } catch (const rcm::Interrupted& e) {
    throw rcm::Interrupted(std::string(e.what()) + "; saved " + model_path.string() +
                           "; results.json, report.md and figures not written");
  }
  const auto report = rcm::write_study_report(result, session, out);
  if (o.json) {
    rcm::cli::print_json(result.to_json());
  } else {
    std::cout << "Table IV -- misalignment estimates\n" << rcm::format_table_iv(result);
    std::cout << "report: " << report.string() << "\n";
  }
  if (!result.interrupted && rcm::is_interrupt_requested())
    throw rcm::Interrupted("interrupted after every trial was estimated; saved results.json, report.md and "
                           "free_space_model.json in " + out.string() +
                           "; figures drawn before the signal are listed in report.md");
  if (result.interrupted) {
    std::string done, left;
    for (const auto& t : result.trials) done += (done.empty() ? "" : ", ") + t.name;
    for (std::size_t i = result.trials.size(); i < session.trials.size(); ++i)
      left += (left.empty() ? "" : ", ") + session.trials[i].name;
    throw rcm::Interrupted("interrupted after " + std::to_string(result.trials.size()) + " of " +
                           std::to_string(result.trials_planned) + " trials; saved results.json and report.md of " +
                           done + ", and free_space_model.json, in " + out.string() + "; not estimated: " + left +
                           "; figures not drawn");
  }
}

const bool registered = rcm::cli::register_command({"run", 60, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("run", "The whole study on a session: free-space model, tissue law, every trial; "
                                            "writes results.json, report.md and figures/");
  cmd->add_option("SESSION", o->session, "rcm-session/1 manifest")->required();
  cmd->add_option("--out", o->out, "output folder (default rcm-run)");
  o->study.add(cmd, "--method", {"method"});
  o->study.add(cmd, "--static-step", {"static_step"});
  rcm::cli::add_free_space_flags(cmd, o->study);
  o->study.add(cmd, "--D0", {"three_step.D_initial"}, "initial guess of D (unset: the middle of its bounds)");
  o->study.add(cmd, "--export-problems", {"export_problems_dir"});
  rcm::cli::add_options_file_flag(cmd, o->options_file);
  cmd->add_flag("--json", o->json, "print results.json on stdout");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_run
}  // namespace
