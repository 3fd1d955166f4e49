#!/usr/bin/python3
"""The speed experiment on the simulated bench beside the real arm.

For each arm preset (default: `cable`, the motors behind compliant cables, and
`rigid`) and seed, `rcm simulate --experiment speed` writes fast.csv (one
periodic excitation path at full speed, 200 Hz) and slow.csv (the same path at
half speed, 100 Hz, one row per command); `rcm dynamics fit --model linear
--seed 1` is fitted on each and `rcm dynamics eval` scores it on the other. The
fit's own held-out slice of its file is the in-sample figure.

Per split and joint it reports the torque RMSE (mean over the seeds, and their
range), the share of the residual's power above 5 Hz and the share of it that
the measured qddot (zero-phase, 0.1 s) explains by least squares (an
inertia-like error), with its coefficient: the inertia the scored run shows
beyond what the fit found, in kg m^2 (yaw, pitch) and kg (insertion).
Beside them, the real Classic PSM1 recordings' figures for the same protocol
(--real DIR: psm1_105g_insertion_full.csv, ..._half.csv and the 205 g pair,
fitted and scored the same way; they stay where they are). The table goes
with --doc, between the speed-effect markers of docs/validation-free-space.md, with the date and
machine.

  /usr/bin/python3 bench/sim_speed_effect.py --build build [--seeds 1,2,3] [--arms cable,rigid] [--real DIR] [--no-doc]
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

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCS = [os.path.join(ROOT, "docs", "validation-free-space.md")]
BEGIN, END = "<!-- speed-effect:begin -->", "<!-- speed-effect:end -->"
JOINTS = ("yaw", "pitch", "insertion")
# The real Classic PSM1 recordings of the same protocol (one excitation path,
# 200 Hz for 30 s and the same points at half speed, 100 Hz), with 105 g and
# 205 g on the instrument, in --real DIR.
REAL = {"105 g": ("psm1_105g_insertion_full.csv", "psm1_105g_insertion_half.csv"),
        "205 g": ("psm1_205g_insertion_full.csv", "psm1_205g_insertion_half.csv")}


def residual_traits(test, predictions):
    """Per joint: RMSE, share of residual power above 5 Hz, R^2 of qddot on it
    and its least-squares coefficient (the inertia the scored run shows beyond
    the model's, kg m^2 or kg)."""
    d = load(test)
    pred = np.genfromtxt(predictions, delimiter=",", names=True)
    r = np.stack([pred[f"effort_{j}"] - pred[f"tau_fs_{j}"] for j in (1, 2, 3)], 1)
    dt = np.median(np.diff(d["t"]))
    qdd = zero_phase_acceleration(d["t"], d["qd"])
    out = []
    for j in range(3):
        e = r[:, j] - r[:, j].mean()
        spec = np.abs(np.fft.rfft(e)) ** 2
        f = np.fft.rfftfreq(len(e), dt)
        hf = spec[f > 5.0].sum() / spec[1:].sum()
        A = np.stack([qdd[:, j], np.ones(len(e))], 1)
        fit = np.linalg.lstsq(A, r[:, j], rcond=None)[0]
        r2 = 1.0 - np.mean((r[:, j] - A @ fit) ** 2) / np.mean((r[:, j] - r[:, j].mean()) ** 2)
        out.append({"rmse": float(np.sqrt(np.mean(r[:, j] ** 2))), "hf": float(hf), "qdd_r2": float(max(r2, 0.0)),
                    "qdd_coef": float(fit[0])})
    return out


def fit_and_score(rcm, train, test, work, tag):
    model = os.path.join(work, f"{tag}.json")
    pred = os.path.join(work, f"{tag}_pred.csv")
    fit = json.loads(run([rcm, "dynamics", "fit", "--model", "linear", "--seed", "1", "--out", model, train, "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL).stdout)
    run([rcm, "dynamics", "eval", model, test, "--json", "--predictions", pred], stdout=subprocess.DEVNULL)
    return {"out": residual_traits(test, pred), "in": [j["rmse"] for j in fit["test"]]}


def experiment(rcm, fast, slow, work, tag):
    return {"full -> half": fit_and_score(rcm, fast, slow, work, tag + "_fh"),
            "half -> full": fit_and_score(rcm, slow, fast, work, tag + "_hf")}


def fmt3(v, digits=3):
    return " / ".join(f"{x:.{digits}f}" for x in v)


def fmt_range(r):
    """lo .. hi over the seeds; blank for one run."""
    return "" if np.array_equal(r[0], r[1]) else f"{fmt3(r[0])} .. {fmt3(r[1])}"


def summarize(runs):
    """Mean over runs of each split's per-joint figures, the RMSE's range."""
    out = {}
    for split in ("full -> half", "half -> full"):
        rmse = np.array([[j["rmse"] for j in r[split]["out"]] for r in runs])
        out[split] = {k: np.mean([[j[k] for j in r[split]["out"]] for r in runs], 0) for k in ("hf", "qdd_r2", "qdd_coef")}
        out[split]["rmse"] = rmse.mean(0)
        out[split]["range"] = (rmse.min(0), rmse.max(0))
        ins = np.array([r[split]["in"] for r in runs])
        out[split]["in"] = ins.mean(0)
        out[split]["in_range"] = (ins.min(0), ins.max(0))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--arms", default="cable,rigid", help="arm presets (rcm simulate --arm)")
    ap.add_argument("--config", help="a JSON file passed to every rcm simulate (--config)")
    ap.add_argument("--keep", help="keep the recordings and models in this directory")
    ap.add_argument("--real", help="directory of the real PSM1 recordings (REAL above); without it, no real rows")
    ap.add_argument("--no-doc", action="store_true", help="print the table only (the default; kept for scripts)")
    ap.add_argument("--doc", action="store_true", help="also write the table into docs/validation-free-space.md")
    args = ap.parse_args()
    rcm = os.path.join(args.build, "bin", "rcm")
    seeds = [int(s) for s in args.seeds.split(",")]
    arms = args.arms.split(",")
    work = args.keep or tempfile.mkdtemp(prefix="rcm_speed_")
    os.makedirs(work, exist_ok=True)

    results = {}
    for arm in arms:
        runs = []
        for seed in seeds:
            out = os.path.join(work, f"{arm}_{seed}")
            cmd = [rcm, "simulate", "--experiment", "speed", "--arm", arm, "--seed", str(seed), "--no-truth",
                   "--out", out, "--json"]
            if args.config:
                cmd += ["--config", args.config]
            run(cmd, stdout=subprocess.DEVNULL)
            runs.append(experiment(rcm, os.path.join(out, "fast.csv"), os.path.join(out, "slow.csv"), work,
                                   f"{arm}_{seed}"))
        results[f"bench, {arm} arm"] = summarize(runs)
    if args.real:
        for label, (fast, slow) in REAL.items():
            results[f"real PSM1, {label}"] = summarize(
                [experiment(rcm, os.path.join(args.real, fast), os.path.join(args.real, slow), work,
                            "real_" + label.replace(" ", ""))])

    stamp = datetime.date.today().isoformat()
    lines = [f"Measured by `bench/sim_speed_effect.py` on {stamp}, {cpu_model()}, {os.cpu_count()} cores: "
             f"`rcm simulate --experiment speed --arm A --seed S` for seeds {args.seeds}, "
             "`rcm dynamics fit --model linear --seed 1` on one recording, `rcm dynamics eval` on the other. "
             "Bench rows: the mean over the seeds and their range; in-sample is the fit's own held-out "
             "slice of the recording it was fitted on. Real rows: the real Classic PSM1 recordings of the same "
             "protocol, 105 g and 205 g on the instrument, fitted and scored the same way.",
             "",
             "| arm | fitted on -> scored on | RMSE yaw / pitch (N m) / insertion (N) | range over seeds | "
             "cross / in-sample at the scored speed | residual power above 5 Hz | qddot explains | "
             "qddot coefficient (kg m^2 / kg m^2 / kg) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, s in results.items():
        for split, own in (("full -> half", "full"), ("half -> full", "half")):
            x = s[split]
            lines.append(f"| {name} | {own} -> {own} (in-sample) | {fmt3(x['in'])} | "
                         f"{fmt_range(x['in_range'])} | | | | |")
        for split in ("full -> half", "half -> full"):
            x = s[split]
            # Against the in-sample error at the speed it is scored on.
            ratio = x["rmse"] / s["half -> full" if split == "full -> half" else "full -> half"]["in"]
            lines.append(f"| {name} | {split} | {fmt3(x['rmse'])} | {fmt_range(x['range'])} | "
                         f"{fmt3(ratio, 1)} | {' / '.join(f'{v:.0%}' for v in x['hf'])} | "
                         f"{' / '.join(f'{v:.0%}' for v in x['qdd_r2'])} | {fmt3(x['qdd_coef'])} |")
    block = "\n".join(lines)
    if args.no_doc or not args.doc:
        print(block)
        return
    for doc in DOCS:
        write_block(doc, BEGIN, END, block)
    print(block)


if __name__ == "__main__":
    sys.exit(main())
