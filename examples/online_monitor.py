"""The online monitor on a stream: one joint-state sample at a time, the running
misalignment estimate, and what the arm should do about it.

    python3 online_monitor.py SESSION.json MODEL.json TRIAL

The session's calibration identifies the tissue; MODEL.json is a saved
free-space torque model (`rcm dynamics fit`). The recording of TRIAL stands in
for the robot: each of its samples is handed over as a live node hands over a
sensor_msgs/JointState message. Prints the estimate every 5 s, the events
(onset, force alarm, a change of advice) as they happen, and the final
estimate.

What `rcm monitor --session SESSION.json --model-file MODEL.json TRIAL.csv` and
the ROS nodes run; examples/online_monitor.cpp is this program in C++.
"""

import sys

import numpy as np

import rcm


def main(argv):
    if len(argv) != 4:
        print(f"usage: {argv[0]} SESSION.json MODEL.json TRIAL", file=sys.stderr)
        return 2
    session = rcm.load_session(argv[1])
    trial = next((t for t in session.trials if t.name == argv[3]), None)
    if trial is None:
        print(f"{argv[1]}: no trial named {argv[3]!r}", file=sys.stderr)
        return 2

    # Everything the monitor needs before the first sample: the free-space
    # model, the incision frame at q0 and the tissue identified on the
    # calibration. A saved model means nothing is fitted here.
    options = rcm.StudyOptions()
    options.model_file = argv[2]
    options.verbose = False
    setup = rcm.prepare_monitor(session, options)

    # The estimator takes the batch estimator's bounds and residual scales, so
    # the two agree; the correction acts only on what the estimate is sure of.
    estimator = rcm.OnlineEstimator(setup.incision, setup.tissue, rcm.make_online_options(setup.joint_options))
    pipeline = rcm.OnlinePipeline(setup.free_space.model, estimator)
    corrector = rcm.RcmCorrector(setup.incision, rcm.CorrectionOptions())
    # The loop holds all running state; a new loop starts from scratch.
    loop = rcm.CorrectionLoop(pipeline, corrector)

    stream = rcm.load_recording(trial.recording)
    # The RCM of a recorded arm never moved: no software shift is in effect.
    # An arm that can move its RCM passes its setpoint minus the docked RCM.
    applied_base = np.zeros(3)

    onset_reported = False
    next_print = stream.time[0]
    # Take the arrays once: each attribute access makes a new view.
    time, position, velocity, effort = stream.time, stream.position, stream.velocity, stream.effort
    for t in range(stream.num_samples):
        # One message's worth of joint state.
        estimate, correction = loop.step(time[t], position[t], velocity[t], effort[t], applied_base)

        if estimate.onset and not onset_reported:
            print(f"{estimate.time:6.2f} s  onset: the incision is off the RCM (detected at {estimate.onset_time:.2f} s)")
            onset_reported = True
        if estimate.alarm_raised:
            print(f"{estimate.time:6.2f} s  alarm: {estimate.force_norm_n:.1f} N at the incision")
        if estimate.alarm_cleared:
            print(f"{estimate.time:6.2f} s  alarm cleared")
        if correction.changed:
            print(f"{correction.time:6.2f} s  advice: {corrector.describe(correction)}")
        if time[t] >= next_print:
            p, sd = 1e3 * estimate.misalignment_m, 1e3 * estimate.sd_m
            print(f"{estimate.time:6.2f} s  estimate [{p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}] mm  "
                  f"sd [{sd[0]:.1f}, {sd[1]:.1f}, {sd[2]:.1f}] mm  force {estimate.force_norm_n:.1f} N")
            next_print += 5.0

    p, sd = 1e3 * estimate.misalignment_m, 1e3 * estimate.sd_m
    print(f"final estimate [{p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}] mm  sd [{sd[0]:.2f}, {sd[1]:.2f}, {sd[2]:.2f}] mm "
          f"after {stream.num_samples} samples")
    if trial.truth_misalignment_m is not None:
        truth = trial.truth_misalignment_m
        print(f"truth          [{1e3 * truth[0]:.2f}, {1e3 * truth[1]:.2f}, {1e3 * truth[2]:.2f}] mm, "
              f"error {1e3 * np.linalg.norm(estimate.misalignment_m - truth):.2f} mm")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv))
    except rcm.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
