#pragma once
// What `rcm run` and `rcm demo` share: the free-space fitter available in this
// build and the study's progress/summary printing.

#include "rcm/estimation/study.hpp"

namespace rcm::cli {

// fit_torque_model of rcm::torch when built with LibTorch; otherwise only the
// linear model (the others raise a clear error).
TorqueModelFitter get_torque_model_fitter();
// The default kind: hybrid with LibTorch, linear without.
dynamics::TorqueModelKind get_default_model_kind();

// The free-space part of the study options from the flags that `rcm run`,
// `rcm demo` and `rcm monitor` share (--model, --model-file, --seed,
// --max-train-minutes, --dedupe).
struct FreeSpaceFlags {
  std::string model, model_file;
  unsigned seed = 1;
  double max_minutes = 10.0;
  bool dedupe = false;
};
StudyOptions make_study_options(const FreeSpaceFlags& flags);

}  // namespace rcm::cli
