#!/usr/bin/python3
"""Where a free-space model's error comes from on real arm recordings.

Each split TRAIN.csv:TEST.csv (recordings in rcm's CSV format, joints 1-3 = yaw,
pitch, insertion) is fitted with `rcm dynamics fit` and scored with
`rcm dynamics eval --predictions` on the other recording. The script then:

1. tabulates the torque RMSE (N m, N m, N) per model, the RMS incision force
   error the residual causes at D = 30 mm and theta = 20 deg (J_D from
   `rcm kinematics`), and the share of test samples outside the model's
   training regime;
2. with --explain, explains the linear models' test residuals: the share (R^2) that each group
   of terms absorbs when regressed on them after the fact (rcm's own
   regressors, through its Python module), their RMS by speed tercile and their
   mean by direction of motion;
3. with --explain, draws the mean residual against velocity per joint;
4. with --payload-split, re-identifies a payload change (`rcm dynamics
   payload`) on the first seconds of a recording with the new payload and
   scores the result on another one;
5. with --pair FAST:SLOW (two runs of the same path points, row for row, the
   second slower), compares the runs row by row: at the same point of the path
   gravity and any position-dependent torque cancel, so the difference in
   effort is what the change of speed alone does (inertia, friction's rate
   dependence, anything else that differs between the runs), and what the
   default model fitted on either run predicts of it.

Run with Debian's Python (numpy, gnuplot) and the built module:
  PYTHONPATH=build/python /usr/bin/python3 bench/real_arm_residuals.py --build build \\
      --split "LABEL=DIR/fast.csv:DIR/slow.csv" ... [--models "linear|linear, generic|hybrid"]
The tables go between the real-arm markers of docs/validation-free-space.md,
with the date and machine; with --explain, items 2 and 3 too, and the figure
to docs/figures/real_arm_residual_velocity.png.
The recordings stay where they are; nothing of them is copied.
"""
import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from doc_tables import cpu_model, run, write_block
from recording_arrays import load, zero_phase_acceleration


import rcm  # build/python on PYTHONPATH

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation-free-space.md")
FIGURE = os.path.join(ROOT, "docs", "figures", "real_arm_residual_velocity.png")
BEGIN, END = "<!-- real-arm:begin -->", "<!-- real-arm:end -->"
PAYLOAD_BEGIN, PAYLOAD_END = "<!-- real-arm-payload:begin -->", "<!-- real-arm-payload:end -->"
PAIRS_BEGIN, PAIRS_END = "<!-- real-arm-pairs:begin -->", "<!-- real-arm-pairs:end -->"
JOINTS = ("yaw", "pitch", "insertion")
UNITS = ("N m", "N m", "N")


# ------------------------------------------------------------------ regressors
# rcm's own (Python bindings): n x 3 x p, the torque of joints 1-3 per unit parameter.

def stack(fn, *arrays):
    return np.stack([fn(*(a[i] for a in arrays)) for i in range(len(arrays[0]))], 0)


def per_joint(columns):
    """n x 3 x (3 k): each of the k per-joint signals (n x 3) on its own joint."""
    n = columns[0].shape[0]
    Y = np.zeros((n, 3, 3 * len(columns)))
    for k, c in enumerate(columns):
        for j in range(3):
            Y[:, j, 3 * k + j] = c[:, j]
    return Y


def dahl_states(q, x_c):
    z = np.zeros_like(q)
    for j in range(q.shape[1]):
        for k in range(1, len(q)):
            z[k, j] = rcm.dynamics.compute_dahl_state(z[k - 1, j], q[k, j] - q[k - 1, j], x_c[j])
    return z


def knot_hats(x, k):
    """n x k: the piecewise-linear basis of k knots equally spaced over x's range."""
    knots = np.linspace(x.min(), x.max(), k)
    h = knots[1] - knots[0] if k > 1 and x.max() > x.min() else 1.0
    return np.clip(1.0 - np.abs((x[:, None] - knots[None, :]) / h), 0.0, None)


def features(d):
    if "qdd" not in d:
        d["qdd"] = zero_phase_acceleration(d["t"], d["qd"])
        span = d["q"].max(0) - d["q"].min(0)
        d["z"] = dahl_states(d["q"], 3e-3 * span)       # fast: about the bristle scale
        d["z_slow"] = dahl_states(d["q"], 3e-2 * span)  # slow: friction that builds over a longer travel
        d["gravity"] = stack(rcm.dynamics.compute_gravity_regressor, d["q"])
        d["inertia"] = stack(rcm.dynamics.compute_inertia_regressor, d["q"], d["qd"], d["qdd"])
    return d


# ------------------------------------------------------------------ explanation

def explained(residual, Y):
    """R^2 of each joint's residual regressed on the group's columns for that joint."""
    r2 = np.zeros(3)
    for j in range(3):
        A = Y[:, j, :]
        A = A[:, np.abs(A).max(0) > 0]
        if A.shape[1] == 0:
            continue
        th = np.linalg.lstsq(A, residual[:, j], rcond=None)[0]
        r2[j] = 1.0 - ((residual[:, j] - A @ th) ** 2).sum() / (residual[:, j] ** 2).sum()
    return r2


def groups(d):
    d = features(d)
    qd = d["qd"]
    return {
        "armature (qddot)": per_joint([d["qdd"]]),
        "rigid-body inertia, velocity products": d["inertia"],
        "free potential (position)": d["gravity"],
        "viscous (qd)": per_joint([qd]),
        "Dahl, bristle scale": per_joint([d["z"]]),
        "Dahl, 10x longer": per_joint([d["z_slow"]]),
        "sqrt(|qd|) sign(qd)": per_joint([np.sign(qd) * np.sqrt(np.abs(qd))]),
        # A Coulomb level that varies along the travel: the Dahl state times
        # each of 6 piecewise-linear knots over the joint's range.
        "Coulomb along the travel": per_joint([np.stack([d["z"][:, j] * knot_hats(d["q"][:, j], 6)[:, k]
                                                         for j in range(3)], 1) for k in range(6)]),
    }


def force_error(J, residual):
    """RMS of |J_D^-T r| over the samples, with J_D fixed at one configuration."""
    f = np.linalg.solve(J.T, residual.T).T
    return float(np.sqrt((f ** 2).sum(1).mean()))


MODELS = {"linear": [], "linear, no insertion stiffness": ["--no-insertion-stiffness"],
          "linear, constant Coulomb": ["--constant-coulomb"], "linear, free inertia": ["--free-inertia"],
          "linear, generic": ["--generic-structure"], "linear, streamed": [],
          "linear, causal, streamed": ["--no-live-zero-phase"],
          "hybrid": [], "lstm": []}
# What each model of the torque table is, in its header (only the models run).
MODEL_NOTES = {"linear": "the default fit, inertia tied by the bodies of a remote-centre arm, Coulomb levels "
                         "that vary along the travel where they predict better, a stiffness along the insertion",
               "linear, no insertion stiffness": "`--no-insertion-stiffness`",
               "linear, constant Coulomb": "`--constant-coulomb`, one Coulomb level per joint",
               "linear, free inertia": "`--free-inertia`, the 19 inertia coefficients free",
               "linear, generic": "`--generic-structure`, the free potential and constant armature",
               "linear, streamed": "the default fit scored by `rcm dynamics eval --streaming`, compute_step sample "
                                   "by sample, what the live robot gets (its zero-phase qddot live, the torque "
                                   "trailing by the half window)",
               "linear, causal, streamed": "`--no-live-zero-phase` scored the same way, qddot causal, no delay"}


def describe_torque_table(kinds, seed, max_minutes):
    """The header of the torque error table, naming the models that were run."""
    notes = [f"`{k}`: {MODEL_NOTES[k]}" for k in kinds if k in MODEL_NOTES]
    if any(k in ("hybrid", "lstm") for k in kinds):
        notes.append(f"networks with `--max-minutes {max_minutes}`")
    return (f"**Torque error** (`rcm dynamics fit --model M --seed {seed}` on the first, `rcm dynamics eval` on the "
            "second; " + "; ".join(notes) + "), and the RMS incision force error the residual causes at "
            "D = 30 mm, theta = 20 deg (yaw 20 deg from q0 = [0, 0, 0.12 m]):\n")


# Scored as the live robot gets it: compute_step sample by sample (the default
# fit's zero-phase qddot, its torque trailing by the half window; or causal).
EVAL_FLAGS = {"linear, streamed": ["--streaming"], "linear, causal, streamed": ["--streaming"]}


def payload_table(args, rcm_cli, J):
    """The payload re-identification table, between its own markers."""
    out = [f"Measured by `bench/real_arm_residuals.py` on {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}, "
           f"{cpu_model()}, {os.cpu_count()} cores."]
    out.append(f"\n**Payload re-identified** (`rcm dynamics payload` on the first {args.refit_seconds:g} s of the "
               "second recording, which has the new payload; then `rcm dynamics eval` on the third; the default "
               "linear model). Torque RMSE yaw / pitch (N m) / insertion (N), and the force error at D = 30 mm, "
               "theta = 20 deg, before and after; the inertia the refit added to the yaw and pitch armatures; the "
               "angle between the model's gravity direction and the one the refit found; "
               "last column: what the re-identified model's yaw and pitch "
               "residuals on the third recording hold of an inertia (regressed after the fact on qddot, zero-phase "
               "cubic over 0.15 s, and a constant), and the RMS that leaves:\n")
    out.append("| split | without | force error (N) | re-identified | force error (N) | first moment found (N m) | "
               "weight along the instrument found (N) | inertia found, yaw / pitch (kg m^2) | gravity direction moved | "
               "inertia left, yaw / pitch |")
    out.append("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as work:
        for s in args.payload_split:
            label, files = s.split("=", 1)
            train, refit_file, test = files.split(":")
            model, refitted = os.path.join(work, "model.json"), os.path.join(work, "refit.json")
            run([rcm_cli, "dynamics", "fit", "--model", "linear", "--seed", str(args.seed), "--out", model, train],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            head = os.path.join(work, "refit.csv")
            with open(refit_file) as f, open(head, "w") as g:
                header = f.readline()
                g.write(header)
                column = header.strip().split(",").index("time")
                t0 = None
                for line in f:
                    t = float(line.split(",")[column])
                    t0 = t if t0 is None else t0
                    if t - t0 >= args.refit_seconds:
                        break
                    g.write(line)
            found = json.loads(run([rcm_cli, "dynamics", "payload", model, head, "--out", refitted, "--json"],
                                   capture_output=True, text=True).stdout)
            cells = []
            for m in (model, refitted):
                pred = os.path.join(work, "pred.csv")
                ev = json.loads(run([rcm_cli, "dynamics", "eval", m, test, "--json", "--predictions", pred],
                                    capture_output=True, text=True).stdout)
                p = np.genfromtxt(pred, delimiter=",", names=True)
                r = np.stack([p[f"effort_{j}"] - p[f"tau_fs_{j}"] for j in (1, 2, 3)], 1)
                e = ev["joints"]
                cells += [f"{e[0]['rmse']:.3f} / {e[1]['rmse']:.3f} / {e[2]['rmse']:.3f}", f"{force_error(J, r):.1f}"]
            # r is the re-identified model's residual (the loop's last model).
            d = load(test)
            qdd = zero_phase_acceleration(d["t"], d["qd"])
            left = []
            for j in (0, 1):
                X = np.stack([qdd[:, j], np.ones_like(qdd[:, j])], 1)
                th = np.linalg.lstsq(X, r[:, j], rcond=None)[0]
                left.append(f"{th[0]:+.3f} kg m^2 ({np.sqrt((r[:, j] ** 2).mean()):.3f} -> "
                            f"{np.sqrt(((r[:, j] - X @ th) ** 2).mean()):.3f} N m)")
            h = np.linalg.norm(found["payload"]["first_moment_n_m"])
            inertia = found["payload"]["inertia_kg_m2"]
            g0 = np.asarray(rcm.dynamics.load_torque_model(model).parameters.gravity_direction)
            moved = np.degrees(np.arccos(np.clip(np.dot(g0, found["gravity_direction"]), -1.0, 1.0)))
            out.append(f"| {label} | " + " | ".join(cells) + f" | {h:.3f} | {abs(found['payload']['weight_n']):.2f} | "
                       f"{inertia[0]:+.3f} / {inertia[1]:+.3f} | {moved:.0f} deg | " + " / ".join(left) + " |")

    block = "\n".join(out)
    print(block)
    if not args.no_doc:
        write_block(DOC, PAYLOAD_BEGIN, PAYLOAD_END, block)


def pair_table(args, rcm_cli):
    """Row-by-row comparison of runs of the same path at two speeds, between its own markers."""
    out = [f"Measured by `bench/real_arm_residuals.py` on {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}, "
           f"{cpu_model()}, {os.cpu_count()} cores."]
    out.append("\n**The same path points at two speeds, row by row.** d = fast run minus slow run at the same row "
               "(the same commanded point). Position: RMS of d q against the joint's RMS excursion. The effort "
               "difference regressed on d qddot (zero-phase cubic, 0.15 s) and a constant: the apparent inertia "
               "(kg m^2, kg) and the offset between the runs (N m, N), with the share R^2 of the difference they "
               "explain; then R^2 once d qd and d sqrt(|qd|) sign(qd) (friction that depends on the rate) are added, "
               "and, instead of those, once the difference of the rigid-body velocity products is (rcm's 19 Lagrange "
               "terms at zero qddot: centripetal and Coriolis torques, which grow with the square of the speed), with "
               "the offset then left. "
               "Last two columns: the default fit (`rcm dynamics fit`) on one run predicts both, and the RMS of "
               "what its predicted difference misses of the measured one:\n")
    out.append("| runs | joint | position d / excursion | RMS effort d | apparent inertia | offset between runs | "
               "R^2 inertia + offset | R^2 with the rate terms | R^2 with the velocity products | offset left | "
               "missed, fit on the fast run | missed, fit on the slow run |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
    units = ("kg m^2", "kg m^2", "kg")
    insertion = []
    with tempfile.TemporaryDirectory() as work:
        for s in args.pair:
            label, files = s.split("=", 1)
            fast, slow = files.split(":")
            a, b = load(fast), load(slow)
            if len(a["t"]) != len(b["t"]):
                raise SystemExit(f"--pair {label}: {fast} has {len(a['t'])} rows and {slow} {len(b['t'])}; "
                                 "the runs must hold the same path points row for row")
            # What each run's default fit predicts on both runs, and the
            # insertion it finds with and without the stiffness.
            predicted = {}
            for name, train in (("fast", fast), ("slow", slow)):
                model = os.path.join(work, f"{name}.json")
                plain = os.path.join(work, f"{name}_plain.json")
                run([rcm_cli, "dynamics", "fit", "--seed", str(args.seed), "--out", model, train],
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                run([rcm_cli, "dynamics", "fit", "--seed", str(args.seed), "--no-insertion-stiffness", "--out", plain,
                     train], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                with_k = rcm.dynamics.load_torque_model(model).parameters
                without = rcm.dynamics.load_torque_model(plain).parameters
                insertion.append(f"| {label}, {name} run | {with_k.armature[0]:.4f} kg m^2 | "
                                 f"{with_k.armature[1]:.4f} kg m^2 | {without.armature[2]:.3f} kg | "
                                 f"{with_k.armature[2]:.3f} kg | {with_k.stiffness[2]:.2f} N/m |")
                for which, path in (("fast", fast), ("slow", slow)):
                    pred = os.path.join(work, "pred.csv")
                    run([rcm_cli, "dynamics", "eval", model, path, "--json", "--predictions", pred],
                        stdout=subprocess.DEVNULL)
                    p = np.genfromtxt(pred, delimiter=",", names=True)
                    predicted[(name, which)] = np.stack([p[f"tau_fs_{j}"] for j in (1, 2, 3)], 1)
            qdd_a = zero_phase_acceleration(a["t"], a["qd"])
            qdd_b = zero_phase_acceleration(b["t"], b["qd"])
            sq = lambda v: np.sign(v) * np.sqrt(np.abs(v))
            products = [stack(rcm.dynamics.compute_inertia_regressor, r["q"], r["qd"], np.zeros_like(r["qd"]))
                        for r in (a, b)]
            for j in range(3):
                de = a["tau"][:, j] - b["tau"][:, j]
                ss = ((de - de.mean()) ** 2).sum()
                X = np.stack([qdd_a[:, j] - qdd_b[:, j], np.ones_like(de)], 1)
                th = np.linalg.lstsq(X, de, rcond=None)[0]
                r2 = 1.0 - ((de - X @ th) ** 2).sum() / ss
                Xr = np.column_stack([X, a["qd"][:, j] - b["qd"][:, j], sq(a["qd"][:, j]) - sq(b["qd"][:, j])])
                r2r = 1.0 - ((de - Xr @ np.linalg.lstsq(Xr, de, rcond=None)[0]) ** 2).sum() / ss
                dv = products[0][:, j, :] - products[1][:, j, :]
                Xv = np.column_stack([X, dv[:, np.abs(dv).max(0) > 0]])
                thv = np.linalg.lstsq(Xv, de, rcond=None)[0]
                r2v = 1.0 - ((de - Xv @ thv) ** 2).sum() / ss
                missed = [np.sqrt(((de - (predicted[(n, "fast")][:, j] - predicted[(n, "slow")][:, j])) ** 2).mean())
                          for n in ("fast", "slow")]
                dq = np.sqrt(((a["q"][:, j] - b["q"][:, j]) ** 2).mean()) / a["q"][:, j].std()
                out.append(f"| {label} | {JOINTS[j]} | {100 * dq:.1f} % | {np.sqrt((de ** 2).mean()):.3f} {UNITS[j]} | "
                           f"{th[0]:.3f} {units[j]} | {th[1]:+.3f} {UNITS[j]} | {r2:.2f} | {r2r:.2f} | {r2v:.2f} | "
                           f"{thv[1]:+.3f} {UNITS[j]} | "
                           f"{missed[0]:.3f} {UNITS[j]} | {missed[1]:.3f} {UNITS[j]} |")
    out.append("\n**Each run's default fit**: the constant inertia it found on yaw and pitch (the armature; the "
               "configuration-dependent part is the rigid-body terms), the insertion's mass along the axis (the "
               "armature, which holds the sliding body's mass) fitted with `--no-insertion-stiffness` and by default, "
               "and the stiffness the default fit found:\n")
    out.append("| run | yaw armature | pitch armature | insertion mass, no stiffness | insertion mass, default | "
               "stiffness |")
    out.append("|---|---|---|---|---|---|")
    out += insertion
    block = "\n".join(out)
    print(block)
    if not args.no_doc:
        write_block(DOC, PAIRS_BEGIN, PAIRS_END, block)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default="build")
    ap.add_argument("--split", action="append", default=[],
                    help="LABEL=TRAIN.csv[+TRAIN2.csv...]:TEST.csv")
    ap.add_argument("--models", default="linear|linear, generic",
                    help="'|'-separated: linear, linear, free inertia (19 free coefficients), linear, generic (the free "
                         "potential), hybrid, lstm")
    ap.add_argument("--max-minutes", default="3", help="wall-clock budget of each network fit")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-doc", action="store_true",
                    help="print the tables instead of writing docs/validation-free-space.md")
    ap.add_argument("--explain", action="store_true",
                    help="add what the linear models' residuals are made of (R^2 per group of terms, the Coulomb "
                         "level along the travel) and the figure of the mean residual against velocity")
    ap.add_argument("--payload-split", action="append", default=[],
                    help="LABEL=TRAIN.csv:REFIT.csv:TEST.csv: the linear model fitted on TRAIN, its payload "
                         "re-identified on the first --refit-seconds of REFIT, scored on TEST")
    ap.add_argument("--refit-seconds", type=float, default=10.0)
    ap.add_argument("--pair", action="append", default=[],
                    help="LABEL=FAST.csv:SLOW.csv, two runs of the same path points row for row (item 5)")
    args = ap.parse_args()
    rcm_cli = os.path.join(args.build, "bin", "rcm")
    kinds = [k.strip() for k in args.models.split("|")]
    for k in kinds:
        if k not in MODELS:
            ap.error(f"unknown model {k!r}: {', '.join(MODELS)}")
    kin = json.loads(run([rcm_cli, "kinematics", "--q", "0.3490658504,0,0.12", "--offset", "0.03", "--json"],
                         capture_output=True, text=True).stdout)
    J = np.array(kin["J_inc_base"])
    if args.payload_split:
        payload_table(args, rcm_cli, J)
    if args.pair:
        pair_table(args, rcm_cli)
    if not args.split:
        if not args.payload_split and not args.pair:
            ap.error("nothing to do: give --split, --payload-split or --pair")
        return
    splits = []
    for s in args.split:
        label, files = s.split("=", 1)
        train, test = files.split(":")
        splits.append((label, train.split("+"), test))

    out = []
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    out.append(f"Measured by `bench/real_arm_residuals.py` on {stamp}, {cpu_model()}, {os.cpu_count()} cores. "
               "Each split fits on its first recording and scores on its second.\n")

    # 1. rcm's models.
    out.append(describe_torque_table(kinds, args.seed, args.max_minutes))
    out.append("| split | model | RMSE yaw / pitch (N m) / insertion (N) | NRMSE % | force error (N) | test samples out of regime |")
    out.append("|---|---|---|---|---|---|")
    residuals = {}
    profiles = {}  # training files -> the default fit's Coulomb level along each joint's travel
    with tempfile.TemporaryDirectory() as work:
        for label, train, test in splits:
            for kind in kinds:
                model = os.path.join(work, "model.json")
                pred = os.path.join(work, "pred.csv")
                cmd = [rcm_cli, "dynamics", "fit", "--model", kind.split(",")[0], "--seed", str(args.seed), "--out", model]
                if kind in ("hybrid", "lstm"):
                    cmd += ["--max-minutes", args.max_minutes]
                run(cmd + MODELS[kind] + train, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                ev = json.loads(run([rcm_cli, "dynamics", "eval", model, test, "--json", "--predictions", pred] +
                                    EVAL_FLAGS.get(kind, []), capture_output=True, text=True).stdout)
                p = np.genfromtxt(pred, delimiter=",", names=True)
                r = np.stack([p[f"effort_{j}"] - p[f"tau_fs_{j}"] for j in (1, 2, 3)], 1)
                residuals[(label, kind)] = r
                if kind == "linear":
                    lp = rcm.dynamics.load_torque_model(model).parameters
                    profiles.setdefault(tuple(train), (label, lp.coulomb, lp.coulomb_profile, lp.coulomb_profile_range))
                e = ev["joints"]
                reg = ev["regime"][0]
                out.append(f"| {label} | {kind} | {e[0]['rmse']:.3f} / {e[1]['rmse']:.3f} / {e[2]['rmse']:.3f} | "
                           f"{e[0]['nrmse_percent']:.1f} / {e[1]['nrmse_percent']:.1f} / {e[2]['nrmse_percent']:.1f} | "
                           f"{force_error(J, r):.1f} | {100 * reg['fraction']:.0f} % |")

    # The target: on every joint at most half the error of the free potential
    # with a constant armature (the structure every fit had before the
    # rigid-body one), for the default model.
    if "linear" in kinds and "linear, generic" in kinds:
        out.append("\n**Against half the free potential's error** (`linear` over `linear, generic`, per joint; "
                   "met: at most 0.5):\n")
        out.append("| split | yaw | pitch | insertion | met |")
        out.append("|---|---|---|---|---|")
        for label, train, test in splits:
            a = np.sqrt((residuals[(label, "linear")] ** 2).mean(0))
            b = np.sqrt((residuals[(label, "linear, generic")] ** 2).mean(0))
            ratio = a / b
            out.append(f"| {label} | " + " | ".join(f"{x:.2f}" for x in ratio) +
                       f" | {int((ratio <= 0.5).sum())} of 3 |")

    if profiles and args.explain:
        out.append("\n**The Coulomb level the default fit kept along each joint's travel** (`linear`: the Dahl "
                   "state's coefficient at each knot, from the low to the high end of the range it was fitted on; "
                   "a joint without a row kept a constant level):\n")
        out.append("| fitted on (first split) | joint | range | level at the knots |")
        out.append("|---|---|---|---|")
        for train, (label, coulomb, profile, span) in profiles.items():
            for j in range(3):
                if profile.size == 0 or not np.any(profile[j]):
                    continue
                unit = "m" if j == 2 else "rad"
                out.append(f"| {label} | {JOINTS[j]} | {span[j, 0]:.3f} .. {span[j, 1]:.3f} {unit} | " +
                           " / ".join(f"{coulomb[j] + v:.3f}" for v in profile[j]) + f" {UNITS[j]} |")

    data = {}

    def get(path):
        if path not in data:
            data[path] = features(load(path))
        return data[path]

    # 2. What the linear models' test residuals are made of (--explain).
    explained_kinds = [k for k in ("linear, generic", "linear, constant Coulomb", "linear") if k in kinds]
    if not args.explain:
        explained_kinds = []
    names = list(groups(get(splits[0][2])).keys()) if explained_kinds else []
    if explained_kinds:
        out.append("\n**What the residual is made of.** R^2: the share of each joint's test residual (its mean square) that "
                   "each group of terms absorbs when regressed on it after the fact, an upper bound on what adding the "
                   "group could gain (the groups overlap; 0: nothing). Speed terciles: RMS of the residual over the slowest, middle and fastest "
                   "third of the samples by |qd|. Direction: mean residual while the joint moves up minus while it moves "
                   "down. Free potential and armature: the structure `--generic-structure` fits; rigid-body inertia: "
                   "rcm's 19 Lagrange terms (both regressors from rcm's Python module); Dahl states at 0.3 % and 3 % of "
                   "each joint's range; Coulomb along the travel: the first Dahl state times six piecewise-linear knots "
                   "over the joint's range.\n")
        out.append("| split | model | joint | RMS | " + " | ".join(f"R^2 {n}" for n in names) +
                   " | RMS by speed tercile | direction |")
        out.append("|---|---|---|---|" + "---|" * len(names) + "---|---|")
        for label, train, test in splits:
            d = get(test)
            for kind in explained_kinds:
                r = residuals[(label, kind)]
                r2 = {n: explained(r, Y) for n, Y in groups(d).items()}
                for j in range(3):
                    speed = np.abs(d["qd"][:, j])
                    edges = np.quantile(speed, [1 / 3, 2 / 3])
                    bins = [speed <= edges[0], (speed > edges[0]) & (speed <= edges[1]), speed > edges[1]]
                    terc = " / ".join(f"{np.sqrt((r[b, j] ** 2).mean()):.3f}" for b in bins)
                    up, down = d["qd"][:, j] > 0, d["qd"][:, j] < 0
                    direction = r[up, j].mean() - r[down, j].mean()
                    out.append(f"| {label} | {kind} | {JOINTS[j]} | {np.sqrt((r[:, j] ** 2).mean()):.3f} {UNITS[j]} | " +
                               " | ".join(f"{r2[n][j]:.2f}" for n in names) + f" | {terc} | {direction:+.3f} |")

    # 3. Figure: mean residual against velocity, per model, on the first two splits.
    with tempfile.TemporaryDirectory() as work:
        plots = []
        for k, (label, train, test) in enumerate(splits[:2] if explained_kinds else []):
            d = get(test)
            for kind in explained_kinds:
                r = residuals[(label, kind)]
                for j in range(3):
                    v = d["qd"][:, j]
                    edges = np.linspace(np.quantile(v, 0.01), np.quantile(v, 0.99), 25)
                    idx = np.digitize(v, edges)
                    path = os.path.join(work, f"s{k}{kind.replace(' ', '').replace(',', '')}j{j}.dat")
                    with open(path, "w") as f:
                        for b in range(1, len(edges)):
                            m = idx == b
                            if m.sum() >= 10:
                                f.write(f"{0.5 * (edges[b - 1] + edges[b])} {r[m, j].mean()}\n")
                    plots.append((j, f"{label}, {kind}", path))
        if plots and not args.no_doc:  # --no-doc leaves docs/ as it is, figure included
            os.makedirs(os.path.dirname(FIGURE), exist_ok=True)
            tmp = FIGURE + ".tmp.png"
            script = ["set terminal pngcairo size 1500,450 font ',10'", f"set output '{tmp}'",
                      "set multiplot layout 1,3", "set grid", "set key bottom right font ',8'"]
            for j in range(3):
                script.append(f"set title 'mean test residual, {JOINTS[j]}'")
                script.append(f"set xlabel 'velocity ({'rad/s' if j < 2 else 'm/s'})'")
                script.append(f"set ylabel 'residual ({UNITS[j]})'")
                series = [f"'{p}' with linespoints title '{lab}'" for (jj, lab, p) in plots if jj == j]
                script.append("plot " + ", ".join(series))
            script.append("unset multiplot")
            run(["gnuplot"], input="\n".join(script), text=True)
            os.replace(tmp, FIGURE)
            out.append("\n![mean test residual against velocity](figures/real_arm_residual_velocity.png)")

    block = "\n".join(out)
    if args.no_doc:
        print(block)
        return
    write_block(DOC, BEGIN, END, block)
    print(block)


if __name__ == "__main__":
    main()
