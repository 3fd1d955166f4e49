"""A saved free-space torque model run on a recording: whole, as offline analysis
does, and one sample at a time, as a live robot does.

    python3 free_space_model.py MODEL.json RECORDING.csv OUT.csv

MODEL.json is any kind of model (linear, mlp, lstm, hybrid) saved by `rcm
dynamics fit` or rcm.dynamics.save_torque_model; the module runs every kind.
RECORDING.csv should be free of tissue contact (the model predicts the torque
of the arm moving in free space). Prints the model, how much of the recording
lies beyond what the model was fitted on, and the per-joint error against the
measured effort; writes OUT.csv with the offline prediction (time,
tau_fs_1..M).

`rcm dynamics eval` prints the same errors; examples/free_space_model.cpp is
this program in C++.
"""

import sys

import numpy as np

import rcm


def print_errors(what, errors):
    print(f"{what:<36}" + "".join(f"  joint {e.index} {e.rmse:.4f} ({e.nrmse_percent:.2f} %)" for e in errors))


def main(argv):
    if len(argv) != 4:
        print(f"usage: {argv[0]} MODEL.json RECORDING.csv OUT.csv", file=sys.stderr)
        return 2
    # The model is immutable; anything that changes while it runs lives in a
    # workspace, so one model serves any number of streams.
    model = rcm.dynamics.load_torque_model(argv[1])
    recording = rcm.load_recording(argv[2])
    m = model.num_outputs
    print(f"model: {model.kind.name}, reads {model.num_joints} joints, predicts {m}, "
          f"fitted at {1.0 / model.info.sample_period_s:.1f} Hz, output delay {model.output_delay} samples")

    rate_warning = rcm.dynamics.check_sample_period(model, recording)
    if rate_warning:
        print(f"warning: {rate_warning}", file=sys.stderr)
    # A prediction beyond the positions, speeds and accelerations the model was
    # fitted on is an extrapolation; the model file says what it saw.
    print(f"regime: {rcm.dynamics.compute_regime_summary(model, recording)}")

    # Offline: the whole recording at once. The linear and hybrid models then
    # estimate the acceleration zero-phase, from later samples too.
    offline = rcm.dynamics.predict_torque(model, recording)

    # Live: one compute_step per sample, causal. A model whose output trails its
    # input by d samples gives sample t's torque at call t + d. (Each call
    # crosses into C++; predict_torque_streaming runs the same loop there.)
    d = model.output_delay
    workspace = model.create_workspace()
    time, position, velocity = recording.time, recording.position, recording.velocity
    steps = [model.compute_step(workspace, time[t], position[t], velocity[t]) for t in range(len(time))]
    live = np.array(steps[d:])

    measured = recording.effort[:, :m]
    print_errors("RMSE (NRMSE), offline", rcm.dynamics.compute_torque_errors(measured, offline))
    print_errors("RMSE (NRMSE), live", rcm.dynamics.compute_torque_errors(measured[:len(live)], live))

    with open(argv[3], "w") as out:
        out.write("time," + ",".join(f"tau_fs_{j}" for j in range(1, m + 1)) + "\n")
        for t, row in zip(time, offline):
            out.write(f"{t!r}," + ",".join(repr(v) for v in row) + "\n")
    print(f"wrote {argv[3]} ({len(time)} samples)")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv))
    except rcm.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
