#pragma once
// What `rcm run`, `rcm demo`, `rcm monitor` and `rcm dynamics fit` share: the
// free-space fitter available in this build and the study's flags.

#include "cli_options.hpp"
#include "rcm/estimation/study.hpp"

namespace rcm::cli {

// fit_torque_model of rcm::torch when built with LibTorch (it trains the
// networks too); otherwise the fitter of rcm::core alone (linear; the others
// are an error naming --model).
TorqueModelFitter get_torque_model_fitter();

// The free-space flags of the study's options that `rcm run`, `rcm demo` and
// `rcm monitor` share, each a field of StudyOptions' table: --model,
// --model-file (unless `model_file` is false), --seed (of the fit and of the
// joint method's bootstrap), --max-train-minutes, --dedupe.
void add_free_space_flags(CLI::App* cmd, OptionFlags<StudyOptions>& flags, bool model_file = true);

// `--options FILE`: a JSON object of StudyOptions fields, applied before the
// flags; the command's help lists every field.
void add_options_file_flag(CLI::App* cmd, std::string& path);

// The defaults, then the options file (when `path` is not empty), then the flags.
StudyOptions make_study_options(const OptionFlags<StudyOptions>& flags, const std::string& options_file = "");

}  // namespace rcm::cli
