#!/usr/bin/python3
"""The simulator's `real` friction preset: identified on real Classic PSM
recordings, and shown to reproduce their hysteresis loops.

Identification. Each joint's effort is regressed on rcm's rigid-body
regressors (the free potential and the inertia terms, one set per recording:
the payloads differ), a viscous term, and the forces of Maxwell-slip elements
whose breakaway displacements sit on a fixed logarithmic grid: with the
displacements fixed, an element's friction is its force times a play operator
of the position (its deflection over its breakaway displacement, in [-1, 1]),
so the model is linear in the forces, which are fitted non-negative over every
recording at once (both speeds). The grid is then pruned to the elements that
carry friction and refitted. The figures are printed as the preset's values;
the recordings never leave their folder.

Validation. Every recording's path (positions and velocities) is played on the
simulated arm (`trajectory.free_space_path` = file) with the `real` preset of the
rcm module in use and with the `hysteretic` preset. The real and simulated
efforts go through the same extraction (the fit above, its rigid-body part
taken out), and the table compares what a friction model must reproduce for
the estimators: the friction change after a reversal against the travel since
it (the loop's branch), the friction level the motion leaves at a reversal
(what a hold keeps), the RMS difference of the extracted friction along the
path, and the pitch's gravity torque range along it (the arm's counterweight).

Run with Debian's Python and the built module:
  PYTHONPATH=build/python /usr/bin/python3 bench/real_friction_fit.py --real DIR [--no-doc]
The table goes between the real-friction markers of docs/validation.md, the
figure to docs/figures/real_friction_loops.png.
"""
import argparse
import datetime
import glob
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.optimize import lsq_linear
from scipy.interpolate import CubicSpline
from scipy.signal import butter, filtfilt

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import cpu_model, publish_block  # noqa: E402
from recording_arrays import load, zero_phase_acceleration  # noqa: E402

import rcm  # build/python on PYTHONPATH  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation.md")
FIGURE = os.path.join(ROOT, "docs", "figures", "real_friction_loops.png")
BEGIN, END = "<!-- real-friction:begin -->", "<!-- real-friction:end -->"
JOINTS = ("yaw", "pitch", "insertion")
UNITS = ("N m", "N m", "N")
# Breakaway displacements tried (rad, rad, m) and the travels at which the loops are compared.
GRID = [np.logspace(np.log10(5e-5), np.log10(0.15), 14)] * 2 + [np.logspace(np.log10(5e-6), np.log10(0.015), 14)]
TRAVELS = [np.array([0.5, 1, 2, 5, 10, 20, 50]) * 1e-3] * 2 + [np.array([0.05, 0.1, 0.2, 0.5, 1, 2, 5]) * 1e-3]
MAX_ELEMENTS = 8
EDGE_S = 2.0  # the simulated runs' first and last seconds left out


def play(q, width):
    """A Maxwell-slip element's deflection over its breakaway displacement, from rest."""
    z = np.zeros_like(q)
    s = 0.0
    dq = np.diff(q, prepend=q[0])
    for k in range(len(q)):
        s = min(width, max(-width, s + dq[k]))
        z[k] = s
    return z / width


def rigid_body(d):
    """n x 3 x 36: rcm's free-potential and inertia regressors."""
    if "Y" not in d:
        d["qdd"] = zero_phase_acceleration(d["t"], d["qd"])
        g = [rcm.dynamics.compute_gravity_regressor(q) for q in d["q"]]
        i = [rcm.dynamics.compute_inertia_regressor(q, qd, qdd) for q, qd, qdd in zip(d["q"], d["qd"], d["qdd"])]
        d["Yg"] = np.stack(g, 0)
        d["Y"] = np.concatenate([d["Yg"], np.stack(i, 0)], 2)
    return d["Y"]


def fit_joint(records, j, widths):
    """Joint j over all records: rigid body per record, shared slip forces and viscous.
    Returns (forces, viscous, rigid-body coefficients per record)."""
    blocks, plays, rows = [], [], []
    for d in records:
        blocks.append(rigid_body(d)[:, j, :])
        plays.append(np.stack([play(d["q"][:, j], w) for w in widths] + [d["qd"][:, j]], 1))
        rows.append(d["tau"][:, j])
    p = blocks[0].shape[1]
    n_rec = len(records)
    A = np.zeros((sum(len(r) for r in rows), n_rec * p + plays[0].shape[1]))
    at = 0
    for k, (B, P) in enumerate(zip(blocks, plays)):
        A[at:at + len(B), k * p:(k + 1) * p] = B
        A[at:at + len(B), n_rec * p:] = P
        at += len(B)
    lo = np.concatenate([np.full(n_rec * p, -np.inf), np.zeros(plays[0].shape[1])])
    scale = np.maximum(np.abs(A).max(0), 1e-12)  # columns to unit size for the solver
    sol = lsq_linear(A / scale, np.concatenate(rows), bounds=(lo * scale, np.full(A.shape[1], np.inf)),
                     lsmr_tol="auto", max_iter=5000)
    x = sol.x / scale
    return x[n_rec * p:-1], x[-1], [x[k * p:(k + 1) * p] for k in range(n_rec)]


def identify(records):
    """Per joint: the pruned elements [(width, force)], viscous, and per record its rigid-body coefficients."""
    out = []
    for j in range(3):
        forces, _, _ = fit_joint(records, j, GRID[j])
        keep = np.argsort(forces)[::-1][:MAX_ELEMENTS]
        keep = sorted(k for k in keep if forces[k] > 0.02 * forces.sum())
        widths = GRID[j][keep]
        forces, viscous, rb = fit_joint(records, j, widths)
        elements = [(float(w), float(f)) for w, f in zip(widths, forces) if f > 1e-4]
        out.append({"elements": elements, "viscous": float(viscous), "rigid_body": rb})
    return out


def extract_friction(d, fit_j, j):
    """Effort minus the fit's rigid-body part for this record's coefficients: the friction along the path."""
    return d["tau"][:, j] - rigid_body(d)[:, j, :] @ fit_j


def reversals(q, qd, threshold):
    """Indices where the motion reverses (the velocity crosses zero and passes threshold on both sides)."""
    idx, sign, last = [], 0, 0
    for k, v in enumerate(qd):
        s = 1 if v > threshold else (-1 if v < -threshold else 0)
        if s and s != sign:
            if sign:
                seg = q[last:k + 1]
                idx.append(last + int(np.argmax(seg * sign)))  # the extreme position between the two
            sign = s
            last = k
    return idx


def loop_metrics(d, f, j):
    """Median friction change after a reversal at each travel, and the mean |friction| at reversals."""
    q, qd = d["q"][:, j], d["qd"][:, j]
    rev = reversals(q, qd, 0.05 * np.abs(qd).max())
    changes = [[] for _ in TRAVELS[j]]
    levels = []
    for a, b in zip(rev, rev[1:] + [len(q) - 1]):
        travel = np.abs(q[a:b] - q[a])
        df = np.abs(f[a:b] - f[a])
        levels.append(abs(f[a]))
        for i, x in enumerate(TRAVELS[j]):
            hit = np.nonzero(travel >= x)[0]
            if len(hit):
                changes[i].append(df[hit[0]])
    return np.array([np.median(c) if c else np.nan for c in changes]), float(np.mean(levels)), len(rev)


def simulate_path(d, preset, work, name):
    """The record's path played on the simulated arm with a friction preset; its recording as arrays.
    The path is the recorded one low-passed at 3 Hz (zero phase): the commanded Fourier path is smooth,
    the recorded positions carry encoder noise that the simulated servo's feedforward would amplify."""
    b, a = butter(4, 3.0 / (0.5 / np.median(np.diff(d["t"]))))
    spline = CubicSpline(d["t"] - d["t"][0], filtfilt(b, a, d["q"], axis=0))
    t_path = np.arange(0.0, d["t"][-1] - d["t"][0], 1e-3)  # at 1 kHz: a smooth reference for the 2 kHz servo
    q_path, qd_path = spline(t_path), spline(t_path, 1)
    path = os.path.join(work, f"{name}_path.csv")
    with open(path, "w") as fh:
        fh.write("time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3\n")
        for t, q, qd in zip(t_path, q_path, qd_path):
            fh.write(f"{t:.6f},{q[0]:.9g},{q[1]:.9g},{q[2]:.9g},{qd[0]:.9g},{qd[1]:.9g},{qd[2]:.9g}\n")
    config = rcm.sim.make_default_config()
    config.update({"friction": {"preset": preset},
                   "trajectory": {"free_space_path": "file", "free_space_file": path},
                   "protocol": {"q0": [float(x) for x in q_path[0]],
                                "free_space_s": float(d["t"][-1] - d["t"][0])}}, "real_friction_fit")
    rec = rcm.sim.simulate_free_space(config, 0).recording
    t = np.asarray(rec.time)
    keep = (t - t[0] >= EDGE_S) & (t[-1] - t >= EDGE_S)  # the servo starting and stopping on a moving path
    return {"t": t[keep], "q": np.asarray(rec.position)[keep, :3], "qd": np.asarray(rec.velocity)[keep, :3],
            "tau": np.asarray(rec.effort)[keep, :3]}


def gravity_range(d, coefficients, j):
    n = d["Yg"].shape[2]
    g = d["Yg"][:, j, :] @ coefficients[:n]
    return float(g.max() - g.min())


def draw(panels, path):
    """Friction against position over a window, real and simulated, one panel per joint (gnuplot)."""
    with tempfile.TemporaryDirectory() as tmp:
        plots = []
        for j, series in enumerate(panels):
            files = []
            for label, (x, y) in series.items():
                fn = os.path.join(tmp, f"{j}_{len(files)}.dat")
                np.savetxt(fn, np.stack([x, y], 1))
                files.append((label, fn))
            unit_x = "mm" if j == 2 else "mrad"
            plots.append(f"set title '{JOINTS[j]}'; set xlabel 'position from the window start ({unit_x})'; "
                         f"set ylabel 'friction ({UNITS[j]})'; plot " +
                         ", ".join(f"'{fn}' using 1:2 with lines title '{label}'" for label, fn in files))
        script = (f"set terminal pngcairo size 1500,450 font ',10'; set output '{path}'; set multiplot layout 1,3; "
                  "set key bottom right; " + "; ".join(plots) + "; unset multiplot")
        subprocess.run(["gnuplot", "-e", script], check=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--real", required=True, help="folder of real PSM recordings (rcm CSV, joints 1-3)")
    ap.add_argument("--no-doc", action="store_true", help="print only")
    args = ap.parse_args()
    files = sorted(glob.glob(os.path.join(args.real, "*.csv")))
    if not files:
        sys.exit(f"no recordings in {args.real}")
    records = [dict(load(f), name=os.path.basename(f)[:-4]) for f in files]
    fit = identify(records)
    print("identified (width, force) per joint, viscous:", file=sys.stderr)
    for j, f in enumerate(fit):
        print(f"  {JOINTS[j]}: {[(float(f'{w:.3g}'), round(F, 4)) for w, F in f['elements']]} "
              f"sum {sum(F for _, F in f['elements']):.3f}, viscous {f['viscous']:.4f}", file=sys.stderr)

    rows, panels = [], [dict() for _ in range(3)]
    with tempfile.TemporaryDirectory(prefix="rcm_real_friction_") as work:
        for k, d in enumerate(records):
            sims = {p: simulate_path(d, p, work, f"{d['name']}_{p}") for p in ("real", "hysteretic")}
            for j in range(3):
                f_real = extract_friction(d, fit[j]["rigid_body"][k], j)
                curve_real, level_real, n_rev = loop_metrics(d, f_real, j)
                row = {"record": d["name"], "joint": j, "reversals": n_rev, "curve": {"recording": curve_real},
                       "level": {"recording": level_real}, "rms": {},
                       "gravity": {"recording": gravity_range(d, fit[j]["rigid_body"][k], j)}}
                for preset, s in sims.items():
                    # The same extraction on the simulated effort: its own rigid-body fit.
                    _, _, rb = fit_joint([s], j, [w for w, _ in fit[j]["elements"]])
                    f_sim = extract_friction(s, rb[0], j)
                    curve, level, _ = loop_metrics(s, f_sim, j)
                    row["curve"][preset], row["level"][preset] = curve, level
                    # On the simulated run's span (its clock starts with the path's).
                    t_real = d["t"] - d["t"][0]
                    inside = (t_real >= s["t"][0]) & (t_real <= s["t"][-1])
                    f_sim_at = np.interp(t_real[inside], s["t"], f_sim)
                    f_rec = f_real[inside]
                    row["rms"][preset] = float(np.sqrt(np.mean(((f_sim_at - f_sim_at.mean()) -
                                                                 (f_rec - f_rec.mean())) ** 2)))
                    row["gravity"][preset] = gravity_range(s, rb[0], j)
                    if k == 0:
                        win = (s["t"] >= 10.0) & (s["t"] < 16.0)
                        x0 = s["q"][win, j][0]
                        panels[j][f"simulated, {preset}"] = (1e3 * (s["q"][win, j] - x0), f_sim[win])
                if k == 0:
                    win = (d["t"] - d["t"][0] >= 10.0) & (d["t"] - d["t"][0] < 16.0)
                    panels[j]["real PSM1"] = (1e3 * (d["q"][win, j] - d["q"][win, j][0]), f_real[win])
                rows.append(row)
                print(d["name"], JOINTS[j], {p: round(v, 4) for p, v in row["rms"].items()}, file=sys.stderr)

    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    lines = [f"Measured by `bench/real_friction_fit.py --real DIR` on {when}, {os.cpu_count()} cores of "
             f"{cpu_model()}: the {len(records)} real Classic PSM1 recordings (Fourier excitation, 105 g and 205 g, "
             "full and half speed), and each recording's path played on the simulated arm with the `real` and the "
             "`hysteretic` friction presets. Friction is the effort minus a rigid-body fit (rcm's regressors) "
             "done the same way on the real and the simulated efforts.", "",
             "Identified elements (breakaway displacement: force), the preset's values:", "",
             "| joint | elements | sum (the level a long motion leaves) | viscous |", "|---|---|---|---|"]
    for j, f in enumerate(fit):
        unit_w = 1e3
        el = ", ".join(f"{unit_w * w:.3g} {'mm' if j == 2 else 'mrad'}: {F:.3f}" for w, F in f["elements"])
        lines.append(f"| {JOINTS[j]} ({UNITS[j]}) | {el} | {sum(F for _, F in f['elements']):.3f} | "
                     f"{f['viscous']:.3f} |")
    lines += ["", "The loops, per joint over the recordings (median over recordings of each figure; friction change "
              "after a reversal at the travels shown, recording / `real` / `hysteretic`):", "",
              "| joint | change after a reversal at travel | level left at a reversal | RMS difference from the "
              "recording, `real` / `hysteretic` | pitch gravity range |", "|---|---|---|---|---|"]
    for j in range(3):
        sel = [r for r in rows if r["joint"] == j]
        med = lambda key, p: np.nanmedian(np.stack([r[key][p] for r in sel]), 0)
        unit_x = "mm" if j == 2 else "mrad"
        curve = "; ".join(f"{1e3 * x:g} {unit_x}: {med('curve', 'recording')[i]:.3f} / {med('curve', 'real')[i]:.3f}"
                          f" / {med('curve', 'hysteretic')[i]:.3f}" for i, x in enumerate(TRAVELS[j]))
        level = " / ".join(f"{med('level', p):.3f}" for p in ("recording", "real", "hysteretic"))
        rms = " / ".join(f"{med('rms', p):.3f}" for p in ("real", "hysteretic"))
        grav = " / ".join(f"{med('gravity', p):.2f}" for p in ("recording", "real", "hysteretic")) if j == 1 else ""
        lines.append(f"| {JOINTS[j]} ({UNITS[j]}) | {curve} | {level} | {rms} | {grav} |")
    block = "\n".join(lines)
    if not args.no_doc:
        os.makedirs(os.path.dirname(FIGURE), exist_ok=True)
        draw(panels, FIGURE)
    publish_block(DOC, BEGIN, END, block, write=not args.no_doc)


if __name__ == "__main__":
    main()
