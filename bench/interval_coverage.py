#!/usr/bin/python3
"""`make coverage`: how often the 95 % intervals cover the truth, and what each
method's error is, per friction model, free-space path and free-space length.

A condition is FRICTION:PATH:MINUTES (friction preset hysteretic or smooth;
free-space path teleoperation or excitation, the periodic Fourier path of an
identification run). For each condition and seed it simulates a session on
the 5 x 3 grid of offsets (D = 10..50 mm, radial [0, 0], [10, 15] and [-12, 8]
mm), runs `rcm run` with its defaults (joint method, three-step beside it, the
default free-space model) and once more with the paper's last-hold static step
on the same fitted model, and writes the table between the coverage markers of
docs/validation.md, with the date and machine.

Run with Debian's Python: /usr/bin/python3 bench/interval_coverage.py --build build
"""
import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile

from doc_tables import cpu_model, run, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation.md")
BEGIN, END = "<!-- coverage:begin -->", "<!-- coverage:end -->"
GRID = {"protocol": {"radial_offsets_m": [[0.0, 0.0], [0.010, 0.015], [-0.012, 0.008]]}}


def mean(v):
    return sum(v) / len(v) if v else float("nan")


def simulate(rcm, work, condition, seed, approaches):
    """The session of a condition and seed, with `approaches` holds per static file.

    The trial recordings do not depend on the static protocol (same seed, same
    path and noise up to the trial's end), so the sessions with one and with two
    holds differ only in their static files."""
    friction, path, minutes = condition
    session_dir = os.path.join(work, f"{friction}_{path}_{minutes:g}min_seed{seed}" +
                               ("" if approaches == 2 else f"_{approaches}hold"))
    manifest = os.path.join(session_dir, "session.json")
    if not os.path.exists(manifest):
        config = os.path.join(work, f"config_{path}_{approaches}.json")
        with open(config, "w") as f:
            json.dump({"protocol": {**GRID["protocol"], "static_approaches": approaches},
                       "trajectory": {"free_space_path": path}}, f)
        run([rcm, "simulate", "--out", session_dir, "--friction", friction, "--seed", str(seed),
             "--free-space-s", str(60 * minutes), "--config", config, "--no-truth"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return session_dir


def study(rcm, session_dir, name, seed, extra):
    """`rcm run` on the session into session_dir/run_<name>; a kept --work folder resumes."""
    run_dir = os.path.join(session_dir, f"run_{name}")
    if not (os.path.exists(os.path.join(run_dir, "results.json")) and
            os.path.exists(os.path.join(run_dir, "free_space_model.json"))):
        run([rcm, "run", os.path.join(session_dir, "session.json"), "--out", run_dir, "--seed", str(seed)] + extra,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(os.path.join(run_dir, "results.json")) as f:
        return json.load(f)


def study_condition(rcm, work, condition, seed):
    """The defaults on the two-hold session, then the three-step method alone on
    the same fitted model: the last of the two holds, and the paper's protocol
    (one hold per static file)."""
    two = simulate(rcm, work, condition, seed, 2)
    one = simulate(rcm, work, condition, seed, 1)
    default = study(rcm, two, "balanced", seed, ["--static-step", "balanced"])
    model = os.path.join(two, "run_balanced", "free_space_model.json")
    paper = ["--model-file", model, "--method", "three-step", "--static-step", "last-hold"]
    return default, study(rcm, two, "last-hold", seed, paper), study(rcm, one, "paper", seed, paper)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--condition", action="append", default=[], metavar="FRICTION:PATH:MINUTES",
                    help="repeatable; default: hysteretic and smooth, each with 2 and 15 min of teleoperation "
                         "and 2 min of excitation")
    ap.add_argument("--work", help="keep the sessions here (default: a temporary folder); a kept folder resumes")
    ap.add_argument("--no-doc", action="store_true", help="print the table only")
    args = ap.parse_args()
    rcm = os.path.join(os.path.abspath(args.build), "bin", "rcm")
    work = args.work or tempfile.mkdtemp(prefix="rcm_coverage_")
    os.makedirs(work, exist_ok=True)
    conditions = []
    for c in args.condition or [f"{f}:{p}:{m}" for f in ("hysteretic", "smooth")
                                for p, m in (("teleoperation", 2), ("teleoperation", 15), ("excitation", 2))]:
        friction, path, minutes = c.split(":")
        conditions.append((friction, path, float(minutes)))
    seeds = [int(x) for x in args.seeds.split(",")]
    rows = []
    for condition in conditions:
        errors = {k: ([], []) for k in ("joint", "balanced", "last", "paper")}
        inside, trials = [0, 0, 0], 0
        for seed in seeds:
            default, last, paper = study_condition(rcm, work, condition, seed)
            for t, tl, tp in zip(default["trials"], last["trials"], paper["trials"]):
                j = t["joint"]
                side = 0 if t["truth_m"][2] > 0.020 + 1e-9 else 1
                errors["joint"][side].append(j["error_m"])
                errors["balanced"][side].append(t["three_step"]["error_m"])
                errors["last"][side].append(tl["three_step"]["error_m"])
                errors["paper"][side].append(tp["three_step"]["error_m"])
                trials += 1
                for a in range(3):
                    inside[a] += j["ci95_low_m"][a] <= t["truth_m"][a] <= j["ci95_high_m"][a]
        rows.append((*condition, trials, {k: (mean(v[0]), mean(v[1])) for k, v in errors.items()},
                     [i / trials for i in inside]))
        print(rows[-1], file=sys.stderr, flush=True)
    load = os.getloadavg()
    lines = [f"Run {datetime.date.today().isoformat()} by `make coverage` (bench/interval_coverage.py, seeds "
             f"{args.seeds}) on {os.cpu_count()} cores of {cpu_model()}, load average {load[0]:.1f} at the end. "
             "Each seed is one simulated session of 15 trials (D = 10..50 mm x radial [0, 0], [10, 15], "
             "[-12, 8] mm) with two holds per static file, estimated by `rcm run` with its defaults; the "
             "three-step method is also run alone on the same fitted model with the last hold only "
             "(`--static-step last-hold`) and on the same trials with the paper's protocol of one hold per "
             "static file. Mean e in mm, D > 20 / <= 20 mm.", "",
             "| friction | free space | trials | joint | joint 95 % coverage x / y / D | three-step, balanced "
             "holds | three-step, last hold | three-step, paper protocol (one hold) |",
             "|---|---|---|---|---|---|---|---|"]
    for fr, path, mins, n, e, cov in rows:
        pair = lambda k: f"{1e3 * e[k][0]:.2f} / {1e3 * e[k][1]:.2f}"
        lines.append(f"| {fr} | {mins:g} min {path} | {n} | {pair('joint')} | "
                     f"{100 * cov[0]:.0f} / {100 * cov[1]:.0f} / {100 * cov[2]:.0f} % | {pair('balanced')} | "
                     f"{pair('last')} | {pair('paper')} |")
    block = "\n".join(lines)
    print(block)
    if not args.no_doc:
        write_block(DOC, BEGIN, END, block)
        print(f"wrote {DOC}", file=sys.stderr)


if __name__ == "__main__":
    main()
