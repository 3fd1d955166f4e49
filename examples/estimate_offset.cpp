// The RCM misalignment [dr_x, dr_y, D] of every trial of a session.
//
//   estimate_offset SESSION.json [--model MODEL.json] [TRIAL ...]
//
// SESSION.json is an rcm-session/1 manifest (docs/formats.md): free-space
// recordings, a calibration at a known coaxial offset D*, and the trials.
// MODEL.json is a saved free-space torque model of any kind (`rcm dynamics
// fit`); without it the linear model is fitted here on the free-space
// recordings. TRIAL names restrict the study to those trials.
//
// The same as `rcm run SESSION.json --model-file MODEL.json`, without the
// report; examples/estimate_offset.py is this program in Python.

#include <algorithm>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/session.hpp"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SESSION.json [--model MODEL.json] [TRIAL ...]\n", argv[0]);
    return 2;
  }
  try {
    rcm::Session session = rcm::load_session(argv[1]);

    rcm::StudyOptions options;
    options.verbose = false;
    options.fit.verbose = false;
    // rcm::core fits the linear model by itself; the networks (lstm, mlp,
    // hybrid) need LibTorch to fit and arrive here as a saved file instead.
    options.model_kind = rcm::dynamics::TorqueModelKind::linear;
    std::vector<std::string> names;
    for (int i = 2; i < argc; ++i) {
      const std::string arg = argv[i];
      if (arg == "--model" && i + 1 < argc)
        options.model_file = argv[++i];
      else
        names.push_back(arg);
    }

    if (!names.empty()) {
      std::vector<rcm::TrialSpec> chosen;
      for (const std::string& name : names) {
        const auto trial = std::find_if(session.trials.begin(), session.trials.end(),
                                        [&](const rcm::TrialSpec& t) { return t.name == name; });
        if (trial == session.trials.end()) {
          std::fprintf(stderr, "%s: no trial named '%s'\n", argv[1], name.c_str());
          return 2;
        }
        chosen.push_back(*trial);
      }
      session.trials = chosen;
    }

    // The default method is "joint": all three offsets at once in torque
    // space over the whole motion, so the friction the joints hold at rest
    // barely moves it. The paper's three-step estimate comes beside it.
    const rcm::StudyResult result = rcm::run_study(session, options, rcm::get_linear_torque_model_fitter());

    std::printf("free-space model: %s, held-out RMSE", rcm::dynamics::to_string(result.model->kind()).c_str());
    for (const rcm::dynamics::JointTorqueError& e : result.free_space_errors)
      std::printf(" joint %d %.3f", e.index, e.rmse);
    std::printf("\ntissue model: %s, k1 %.0f N/m\n", result.joint_tissue->family.c_str(),
                result.joint_tissue->parameters[0]);
    std::printf("%-12s %-30s %-40s %s\n", "trial", "estimate [dr_x, dr_y, D], mm", "95 % intervals, mm",
                "three-step, mm");
    for (const rcm::TrialOutcome& trial : result.trials) {
      // joint is set whenever the method is "joint"; a solver that did not
      // converge is reported, not thrown.
      const rcm::JointEstimate& joint = *trial.joint;
      const Eigen::Vector3d p = 1e3 * joint.misalignment_m, lo = 1e3 * joint.ci_low, hi = 1e3 * joint.ci_high;
      const Eigen::Vector3d three_step = 1e3 * trial.estimate.misalignment_m;
      char estimate[64], intervals[96];
      std::snprintf(estimate, sizeof estimate, "[%.2f, %.2f, %.2f]", p[0], p[1], p[2]);
      std::snprintf(intervals, sizeof intervals, "[%.1f, %.1f] [%.1f, %.1f] [%.1f, %.1f]", lo[0], hi[0], lo[1], hi[1],
                    lo[2], hi[2]);
      std::printf("%-12s %-30s %-40s [%.1f, %.1f, %.1f]%s\n", trial.name.c_str(), estimate, intervals, three_step[0],
                  three_step[1], three_step[2], joint.solver.converged ? "" : "  (solver did not converge)");
      // A simulated session carries the truth; a clinical one does not.
      if (trial.truth_m) {
        const Eigen::Vector3d t = 1e3 * *trial.truth_m;
        std::printf("%-12s truth [%.2f, %.2f, %.2f], error %.2f mm\n", "", t[0], t[1], t[2],
                    1e3 * *trial.get_error_m());
      }
    }
    return 0;
  } catch (const rcm::InputError& e) {
    // Bad input names its file, line and field: pass it on as it is.
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
}
