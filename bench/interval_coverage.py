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
docs/estimation.md, with the date and machine.

Run with Debian's Python: /usr/bin/python3 bench/interval_coverage.py --build build
"""
import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "estimation.md")
BEGIN, END = "<!-- coverage:begin -->", "<!-- coverage:end -->"
GRID = {"protocol": {"radial_offsets_m": [[0.0, 0.0], [0.010, 0.015], [-0.012, 0.008]]}}


def run(cmd, **kw):
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, check=True, **kw)


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def replace_block(text, block):
    if BEGIN in text:
        head, rest = text.split(BEGIN, 1)
        return head + BEGIN + "\n" + block + "\n" + END + rest.split(END, 1)[1]
    return text + f"\n{BEGIN}\n{block}\n{END}\n"


def mean(v):
    return sum(v) / len(v) if v else float("nan")


def study(rcm, work, condition, seed, static_step):
    friction, path, minutes = condition
    session_dir = os.path.join(work, f"{friction}_{path}_{minutes:g}min_seed{seed}")
    manifest = os.path.join(session_dir, "session.json")
    if not os.path.exists(manifest):
        config = os.path.join(work, f"config_{path}.json")
        with open(config, "w") as f:
            json.dump({**GRID, "trajectory": {"free_space_path": path}}, f)
        run([rcm, "simulate", "--out", session_dir, "--friction", friction, "--seed", str(seed),
             "--free-space-s", str(60 * minutes), "--config", config, "--no-truth"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    model = os.path.join(session_dir, "free_space_model.json")
    run_dir = os.path.join(session_dir, f"run_{static_step}")
    fitted = os.path.join(run_dir, "free_space_model.json")
    if not (os.path.exists(os.path.join(run_dir, "results.json")) and os.path.exists(fitted)):
        cmd = [rcm, "run", manifest, "--out", run_dir, "--seed", str(seed), "--static-step", static_step]
        if static_step != "balanced":  # the ablation: the same fitted model, the three-step method alone
            cmd += ["--model-file", model, "--method", "three-step"]
        run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    if static_step == "balanced":
        shutil.copyfile(fitted, model)
    with open(os.path.join(run_dir, "results.json")) as f:  # a kept --work folder resumes from these
        return json.load(f)


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
        far, near, far3, near3, farp, nearp = [], [], [], [], [], []
        inside, trials = [0, 0, 0], 0
        for seed in seeds:
            res = study(rcm, work, condition, seed, "balanced")
            paper = study(rcm, work, condition, seed, "last-hold")
            for t, tp in zip(res["trials"], paper["trials"]):
                j = t["joint"]
                far_trial = t["truth_m"][2] > 0.020 + 1e-9
                (far if far_trial else near).append(j["error_m"])
                (far3 if far_trial else near3).append(t["three_step"]["error_m"])
                (farp if far_trial else nearp).append(tp["three_step"]["error_m"])
                trials += 1
                for a in range(3):
                    inside[a] += j["ci95_low_m"][a] <= t["truth_m"][a] <= j["ci95_high_m"][a]
        rows.append((*condition, trials, mean(far), mean(near), mean(far3), mean(near3),
                     mean(farp), mean(nearp), [i / trials for i in inside]))
        print(rows[-1], file=sys.stderr, flush=True)
    load = os.getloadavg()
    lines = [f"Run {datetime.date.today().isoformat()} by `make coverage` (bench/interval_coverage.py, seeds "
             f"{args.seeds}) on {os.cpu_count()} cores of {cpu_model()}, load average {load[0]:.1f} at the end. "
             "Each seed is one simulated session of 15 trials (D = 10..50 mm x radial [0, 0], [10, 15], "
             "[-12, 8] mm), estimated by `rcm run` with its defaults; the paper's last-hold static step "
             "(`--static-step last-hold`) reuses the same fitted model. Mean e in mm, D > 20 / <= 20 mm.", "",
             "| friction | free space | trials | joint mean e | three-step (balanced holds) | "
             "three-step (paper: last hold) | joint 95 % coverage x / y / D |",
             "|---|---|---|---|---|---|---|"]
    for fr, path, mins, n, f, ne, f3, n3, fp, np_, cov in rows:
        lines.append(f"| {fr} | {mins:g} min {path} | {n} | {1e3 * f:.2f} / {1e3 * ne:.2f} | "
                     f"{1e3 * f3:.2f} / {1e3 * n3:.2f} | {1e3 * fp:.2f} / {1e3 * np_:.2f} | "
                     f"{100 * cov[0]:.0f} / {100 * cov[1]:.0f} / {100 * cov[2]:.0f} % |")
    block = "\n".join(lines)
    print(block)
    if not args.no_doc:
        with open(DOC) as f:
            text = f.read()
        with open(DOC + ".tmp", "w") as f:
            f.write(replace_block(text, block))
        os.replace(DOC + ".tmp", DOC)
        print(f"wrote {DOC}", file=sys.stderr)


if __name__ == "__main__":
    main()
