#include "study_cli.hpp"

#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#if RCM_HAVE_TORCH
#include "training_loader.hpp"
#endif

namespace rcm::cli {

TorqueModelFitter get_torque_model_fitter() {
#if RCM_HAVE_TORCH
  // A linear fit does not open the training module.
  return TorqueModelFitter(
      [](dynamics::TorqueModelKind kind, const std::vector<Recording>& recordings, const dynamics::FitOptions& options) {
        if (kind == dynamics::TorqueModelKind::linear)
          return dynamics::fit_torque_model_without_networks(kind, recordings, options, flag_location("--model"));
        return get_training_functions().fit_torque_model(kind, recordings, options);
      },
      true);
#else
  return get_linear_torque_model_fitter(flag_location("--model"));
#endif
}

void add_free_space_flags(CLI::App* cmd, OptionFlags<StudyOptions>& flags, bool model_file) {
  const std::string only =
      get_torque_model_fitter().trains_networks() ? "" : "; this build, without LibTorch, fits no other";
  flags.add(cmd, "--model", {"model_kind"},
            "free-space model to fit: lstm, mlp, linear or hybrid (unset: " +
                dynamics::to_string(dynamics::get_default_model_kind()) + only + ")");
  if (model_file)
    flags.add(cmd, "--model-file", {"model_file"},
              "use a saved free-space model (e.g. free_space_model.json of `rcm run`) instead of fitting one");
  flags.add(cmd, "--seed", {"fit.seed", "joint.seed"}, "seed of the model fit and of the joint method's bootstrap");
  flags.add(cmd, "--max-train-minutes", {"fit.max_minutes"}, "wall-clock budget of the free-space fit");
  flags.add(cmd, "--dedupe", {"read.dedupe"}, "drop repeated rows of every recording");
}

void add_options_file_flag(CLI::App* cmd, std::string& path) {
  cmd->add_option("--options", path,
                  "JSON file of study options (any subset of the fields below; the flags override it)");
  cmd->footer(describe_options_file<StudyOptions>(
      "Study options (--options FILE: a JSON object; nested keys as below, any subset):"));
}

StudyOptions make_study_options(const OptionFlags<StudyOptions>& flags, const std::string& options_file) {
  StudyOptions options;
  if (!options_file.empty()) {
    apply_options_json(options, load_json_file(options_file), options_file);
    check_options(options, options_file);
  }
  flags.apply(options);
  return options;
}

}  // namespace rcm::cli
