"""The RCM misalignment [dr_x, dr_y, D] of every trial of a session.

    python3 estimate_offset.py SESSION.json [--model MODEL.json] [TRIAL ...]

SESSION.json is an rcm-session/1 manifest (docs/formats.md): free-space
recordings, a calibration at a known coaxial offset D*, and the trials.
MODEL.json is a saved free-space torque model of any kind (`rcm dynamics fit`);
without it the linear model is fitted here on the free-space recordings. TRIAL
names restrict the study to those trials.

The same as `rcm run SESSION.json --model-file MODEL.json`, without the report;
examples/estimate_offset.cpp is this program in C++.
"""

import sys

import rcm


def main(argv):
    if len(argv) < 2:
        print(f"usage: {argv[0]} SESSION.json [--model MODEL.json] [TRIAL ...]", file=sys.stderr)
        return 2
    session = rcm.load_session(argv[1])

    options = rcm.StudyOptions()
    options.verbose = False
    options.fit.verbose = False
    # The module fits the linear model by itself; the networks (lstm, mlp,
    # hybrid) need LibTorch to fit and arrive here as a saved file instead.
    options.model_kind = rcm.dynamics.TorqueModelKind.linear
    names = []
    args = iter(argv[2:])
    for arg in args:
        if arg == "--model":
            options.model_file = next(args)
        else:
            names.append(arg)

    if names:
        by_name = {trial.name: trial for trial in session.trials}
        missing = [name for name in names if name not in by_name]
        if missing:
            print(f"{argv[1]}: no trial named {missing[0]!r}", file=sys.stderr)
            return 2
        # session.trials hands out a copy: assign a new list, never append.
        session.trials = [by_name[name] for name in names]

    # The default method is "joint": all three offsets at once in torque space
    # over the whole motion, so the friction the joints hold at rest barely
    # moves it. The paper's three-step estimate comes beside it.
    result = rcm.run_study(session, options)

    errors = " ".join(f"joint {e.index} {e.rmse:.3f}" for e in result.free_space_errors)
    print(f"free-space model: {result.model.kind.name}, held-out RMSE {errors}")
    print(f"tissue model: {result.joint_tissue.family}, k1 {result.joint_tissue.parameters[0]:.0f} N/m")
    print(f"{'trial':<12} {'estimate [dr_x, dr_y, D], mm':<30} {'95 % intervals, mm':<40} three-step, mm")
    for trial in result.trials:
        # joint is set whenever the method is "joint"; a solver that did not
        # converge is reported, not raised.
        joint = trial.joint
        p, lo, hi = 1e3 * joint.misalignment_m, 1e3 * joint.ci_low, 1e3 * joint.ci_high
        three_step = 1e3 * trial.estimate.misalignment_m
        estimate = f"[{p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}]"
        intervals = " ".join(f"[{lo[i]:.1f}, {hi[i]:.1f}]" for i in range(3))
        note = "" if joint.solver.converged else "  (solver did not converge)"
        print(f"{trial.name:<12} {estimate:<30} {intervals:<40} "
              f"[{three_step[0]:.1f}, {three_step[1]:.1f}, {three_step[2]:.1f}]{note}")
        # A simulated session carries the truth; a clinical one does not.
        if trial.truth_m is not None:
            t = 1e3 * trial.truth_m
            print(f"{'':<12} truth [{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}], error {1e3 * trial.get_error_m():.2f} mm")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv))
    except rcm.InputError as e:
        # Bad input names its file, line and field: pass it on as it is.
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
