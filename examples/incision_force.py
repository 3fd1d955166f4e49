"""The force at the incision over a whole recording (paper Eq. 6):

    f_inc_base = J_D^-T (tau - tau_fs)

    python3 incision_force.py SESSION.json MODEL.json OUT.csv

The recording is the session's calibration, whose coaxial offset D* is known (a
phantom bench measures it); on a trial, use the D that estimate_offset found.
MODEL.json is a saved free-space torque model (`rcm dynamics fit`). Writes
OUT.csv (time, force_x, force_y, force_z in the base frame, N; theta, rad; the
Jacobian's status) and, when the recording has force columns from a sensor,
prints the RMSE per axis against them.

The same as `rcm force --model MODEL.json --offset D* --q0 ... calibration.csv`;
examples/incision_force.cpp is this program in C++.
"""

import sys

import numpy as np

import rcm


def main(argv):
    if len(argv) != 4:
        print(f"usage: {argv[0]} SESSION.json MODEL.json OUT.csv", file=sys.stderr)
        return 2
    session = rcm.load_session(argv[1])
    if session.calibration is None:
        print(f"{argv[1]}: the session has no calibration, so no recording with a known D", file=sys.stderr)
        return 2
    model = rcm.dynamics.load_torque_model(argv[2])
    recording = rcm.load_recording(session.calibration.recording)
    D = session.calibration.coaxial_offset_m

    # A recurrent model learned per-sample dynamics at one rate: say so when
    # the recording was sampled at another.
    rate_warning = rcm.dynamics.check_sample_period(model, recording)
    if rate_warning:
        print(f"warning: {rate_warning}", file=sys.stderr)

    # The model runs over the whole recording with its state carried, so the
    # friction the joints remember reaches every sample.
    tau_fs = rcm.dynamics.predict_torque(model, recording)

    # The incision frame is that of DH frame 3 at the docking configuration q0.
    incision = rcm.make_incision_frame(session.q0)
    series = rcm.compute_incision_force_series(incision, recording, tau_fs, D)

    # series.status is a new list at every access: take it once.
    force, theta, status = series.f_inc_base, series.theta, series.status
    with open(argv[3], "w") as out:
        out.write("time,force_x,force_y,force_z,theta,status\n")
        for t, time in enumerate(recording.time):
            out.write(f"{time!r},{force[t, 0]!r},{force[t, 1]!r},{force[t, 2]!r},{theta[t]!r},{status[t].name}\n")

    print(f"{recording.source}: {recording.num_samples} samples at D = {1e3 * D:.1f} mm, model {model.kind.name}; "
          f"{series.num_ill_conditioned} ill-conditioned, {series.num_singular} singular (NaN rows)")
    # Near the RCM (small D) or at large pivot angles J_D amplifies torque
    # noise: an ill-conditioned sample's force is computed but not to be trusted.
    ok = np.array([s == rcm.JacobianStatus.ok for s in status])
    if recording.force is not None and ok.any():
        rmse = np.sqrt(np.mean((force[ok] - recording.force[ok]) ** 2, axis=0))
        print(f"RMSE against the force sensor over {ok.sum()} well-conditioned samples: "
              f"x {rmse[0]:.2f}, y {rmse[1]:.2f}, z {rmse[2]:.2f} N")
    print(f"wrote {argv[3]}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv))
    except rcm.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
