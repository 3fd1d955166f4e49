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

struct Options {
  std::string session, out = "rcm-run", method = rcm::StudyOptions{}.method, export_problems;
  std::string static_step = rcm::to_string(rcm::StudyOptions{}.static_step);
  rcm::cli::FreeSpaceFlags free_space;
  double D0 = std::numeric_limits<double>::quiet_NaN();
  bool json = false;
};

void run(const Options& o) {
  if (o.method != "three-step" && o.method != "joint")
    throw rcm::InputError(rcm::cli::flag_location("--method"), "expected three-step or joint, got '" + o.method + "'");
  const rcm::Session session = rcm::load_session(o.session);
  rcm::StudyOptions options = rcm::cli::make_study_options(o.free_space);
  options.method = o.method;
  try {
    options.static_step = rcm::parse_static_step(o.static_step);
  } catch (const std::invalid_argument& e) {
    throw rcm::InputError(rcm::cli::flag_location("--static-step"), e.what());
  }
  if (!std::isnan(o.D0)) options.three_step.D_initial = o.D0;
  if (!o.export_problems.empty()) options.export_problems_dir = o.export_problems;
  try {
    options.three_step.check();
  } catch (const std::invalid_argument& e) {
    throw rcm::InputError(rcm::cli::flag_location("--D0"), e.what());
  }
  rcm::check_study_inputs(session, options);
  rcm::install_interrupt_handlers();
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
  cmd->add_option("--method", o->method,
                  "joint (default: all offsets in torque space, with 95 % intervals; three-step beside it) or "
                  "three-step (paper Algorithm 1 alone)");
  cmd->add_option("--static-step", o->static_step,
                  "how the three-step method reads the static file: balanced (default: every hold at q0, those "
                  "approached from above and from below averaged apart, so hysteretic friction cancels) or "
                  "last-hold (the paper's)");
  cmd->add_option("--model", o->free_space.model, "free-space model to fit: hybrid (default with LibTorch), lstm, mlp, linear");
  cmd->add_option("--model-file", o->free_space.model_file, "use a saved free-space model instead of fitting one");
  cmd->add_option("--seed", o->free_space.seed, "seed of the model fit");
  cmd->add_option("--D0", o->D0, "initial guess of D in m (default: middle of [-0.020, 0.070])");
  cmd->add_option("--max-train-minutes", o->free_space.max_minutes, "wall-clock budget of the free-space fit (default 10)");
  cmd->add_option("--export-problems", o->export_problems,
                  "write every trial's coaxial least-squares problem as JSON into this folder (solver cross-checks)");
  cmd->add_flag("--dedupe", o->free_space.dedupe, "drop repeated rows of every recording");
  cmd->add_flag("--json", o->json, "print results.json on stdout");
  cmd->callback([o] { run(*o); });
}});

}  // namespace
