#include "study_cli.hpp"

#include "rcm/common/error.hpp"
#include "rcm/dynamics/linear_model.hpp"
#if RCM_HAVE_TORCH
#include "rcm/dynamics/training.hpp"
#endif

namespace rcm::cli {

TorqueModelFitter get_torque_model_fitter() {
  return [](dynamics::TorqueModelKind kind, const std::vector<Recording>& recordings,
            const dynamics::FitOptions& options) {
#if RCM_HAVE_TORCH
    return dynamics::fit_torque_model(kind, recordings, options);
#else
    if (kind != dynamics::TorqueModelKind::linear) {
      InputLocation where;
      where.file = "--model";
      throw InputError(where, "this build has no LibTorch (RCM_WITH_TORCH=OFF): only the linear model can be fitted");
    }
    return dynamics::fit_linear_torque_model(recordings, options);
#endif
  };
}

dynamics::TorqueModelKind get_default_model_kind() {
#if RCM_HAVE_TORCH
  // Linear-in-parameters dynamics with a friction state plus an LSTM on its
  // residual (Yang et al. [19]): the most accurate free-space model on the
  // simulated bench and a few minutes to fit; the pure LSTM of the paper is
  // --model lstm.
  return dynamics::TorqueModelKind::hybrid;
#else
  return dynamics::TorqueModelKind::linear;
#endif
}

StudyOptions make_study_options(const FreeSpaceFlags& f) {
  StudyOptions options;
  options.model_kind = f.model.empty() ? get_default_model_kind() : dynamics::parse_torque_model_kind(f.model, "--model");
  if (!f.model_file.empty()) options.model_file = f.model_file;
  options.fit.seed = f.seed;
  options.fit.max_minutes = f.max_minutes;
  options.joint.seed = f.seed;
  options.read.dedupe = f.dedupe;
  return options;
}

}  // namespace rcm::cli
