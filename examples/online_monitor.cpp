// The online monitor on a stream: one joint-state sample at a time, the running
// misalignment estimate, and what the arm should do about it.
//
//   online_monitor SESSION.json MODEL.json TRIAL
//
// The session's calibration identifies the tissue; MODEL.json is a saved
// free-space torque model (`rcm dynamics fit`). The recording of TRIAL stands
// in for the robot: each of its samples is handed over as a live node hands
// over a sensor_msgs/JointState message. Prints the estimate every 5 s, the
// events (onset, force alarm, a change of advice) as they happen, and the
// final estimate.
//
// What `rcm monitor --session SESSION.json --model-file MODEL.json TRIAL.csv`
// and the ROS nodes run; examples/online_monitor.py is this program in Python.

#include <algorithm>
#include <cstdio>
#include <exception>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s SESSION.json MODEL.json TRIAL\n", argv[0]);
    return 2;
  }
  try {
    const rcm::Session session = rcm::load_session(argv[1]);
    const auto trial = std::find_if(session.trials.begin(), session.trials.end(),
                                    [&](const rcm::TrialSpec& t) { return t.name == argv[3]; });
    if (trial == session.trials.end()) {
      std::fprintf(stderr, "%s: no trial named '%s'\n", argv[1], argv[3]);
      return 2;
    }

    // Everything the monitor needs before the first sample: the free-space
    // model, the incision frame at q0 and the tissue identified on the
    // calibration. A saved model means nothing is fitted here.
    rcm::StudyOptions options;
    options.model_file = argv[2];
    options.verbose = false;
    const rcm::MonitorSetup setup = rcm::prepare_monitor(session, options, rcm::get_linear_torque_model_fitter());

    // The estimator takes the batch estimator's bounds and residual scales, so
    // the two agree; the correction acts only on what the estimate is sure of.
    const rcm::OnlinePipeline pipeline(
        setup.free_space.model,
        rcm::OnlineEstimator(setup.incision, setup.tissue, rcm::make_online_options(setup.joint_options)));
    const rcm::RcmCorrector corrector(setup.incision, rcm::CorrectionOptions{});
    const rcm::CorrectionLoop loop(pipeline, corrector);
    // All running state lives here, sized once: no sample allocates after this.
    rcm::CorrectionLoop::Workspace workspace = loop.create_workspace();

    const rcm::Recording stream = rcm::load_recording(trial->recording);
    const int n = stream.num_joints();
    Eigen::VectorXd q(n), qd(n), effort(n);
    // The RCM of a recorded arm never moved: no software shift is in effect.
    // An arm that can move its RCM passes its setpoint minus the docked RCM.
    const Eigen::Vector3d applied_base = Eigen::Vector3d::Zero();

    bool onset_reported = false;
    double next_print = stream.time[0];
    for (Eigen::Index t = 0; t < stream.time.size(); ++t) {
      // One message's worth of joint state (a live node copies it from the message).
      q = stream.position.row(t).transpose();
      qd = stream.velocity.row(t).transpose();
      effort = stream.effort.row(t).transpose();
      const rcm::CorrectionOutput& correction =
          loop.compute_sample(workspace, stream.time[t], q.data(), qd.data(), effort.data(), applied_base);
      const rcm::OnlineOutput& estimate = rcm::get_online_output(workspace.pipeline.estimator);

      if (estimate.onset && !onset_reported) {
        std::printf("%6.2f s  onset: the incision is off the RCM (detected at %.2f s)\n", estimate.time,
                    estimate.onset_time);
        onset_reported = true;
      }
      if (estimate.alarm_raised) std::printf("%6.2f s  alarm: %.1f N at the incision\n", estimate.time, estimate.force_norm_n);
      if (estimate.alarm_cleared) std::printf("%6.2f s  alarm cleared\n", estimate.time);
      // The advice in words allocates: ask for it only when it changes.
      if (correction.changed)
        std::printf("%6.2f s  advice: %s\n", correction.time, rcm::describe_correction(correction, corrector).c_str());
      if (stream.time[t] >= next_print) {
        const Eigen::Vector3d p = 1e3 * estimate.misalignment_m, sd = 1e3 * estimate.sd_m;
        std::printf("%6.2f s  estimate [%.1f, %.1f, %.1f] mm  sd [%.1f, %.1f, %.1f] mm  force %.1f N\n", estimate.time,
                    p[0], p[1], p[2], sd[0], sd[1], sd[2], estimate.force_norm_n);
        next_print += 5.0;
      }
    }

    const rcm::OnlineOutput& last = rcm::get_online_output(workspace.pipeline.estimator);
    const Eigen::Vector3d p = 1e3 * last.misalignment_m, sd = 1e3 * last.sd_m;
    std::printf("final estimate [%.2f, %.2f, %.2f] mm  sd [%.2f, %.2f, %.2f] mm after %zu samples\n", p[0], p[1], p[2],
                sd[0], sd[1], sd[2], stream.num_samples());
    if (trial->truth_misalignment_m) {
      const Eigen::Vector3d truth = *trial->truth_misalignment_m;
      std::printf("truth          [%.2f, %.2f, %.2f] mm, error %.2f mm\n", 1e3 * truth[0], 1e3 * truth[1],
                  1e3 * truth[2], 1e3 * (last.misalignment_m - truth).norm());
    }
    return 0;
  } catch (const rcm::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
}
