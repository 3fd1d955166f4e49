#!/usr/bin/python3
"""`make coverage`: how often the 95 % intervals cover the truth, and what each
method's error is, per friction model and free-space data length.

For every friction preset (hysteretic, smooth), free-space length and seed it
simulates a session on the 5 x 3 grid of offsets (D = 10..50 mm, radial [0, 0],
[10, 15] and [-12, 8] mm), runs `rcm run` with its defaults (joint method,
three-step beside it, the default free-space model), and writes the table
between the coverage markers of docs/estimation.md, with the date and machine.
Per condition: joint mean e (D > 20 / <= 20 mm), three-step mean e with the
balanced static step and with the paper's last hold, and per-axis coverage.

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


def study(rcm, work, friction, minutes, seed, static_step):
    session_dir = os.path.join(work, f"{friction}_{minutes}_{seed}")
    manifest = os.path.join(session_dir, "session.json")
    if not os.path.exists(manifest):
        grid = os.path.join(work, "grid.json")
        with open(grid, "w") as f:
            json.dump(GRID, f)
        run([rcm, "simulate", "--out", session_dir, "--friction", friction, "--seed", str(seed),
             "--free-space-s", str(60 * minutes), "--config", grid, "--no-truth"], stdout=subprocess.DEVNULL)
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
    ap.add_argument("--minutes", default="2,15", help="free-space lengths, min")
    ap.add_argument("--frictions", default="hysteretic,smooth")
    ap.add_argument("--condition", action="append", default=[], metavar="FRICTION:MINUTES:SEEDS",
                    help="one condition with its own seeds, e.g. hysteretic:15:1,2 (repeatable; replaces the grid "
                         "of --frictions x --minutes x --seeds)")
    ap.add_argument("--work", help="keep the sessions here (default: a temporary folder); a kept folder resumes")
    ap.add_argument("--no-doc", action="store_true", help="print the table only")
    args = ap.parse_args()
    rcm = os.path.join(os.path.abspath(args.build), "bin", "rcm")
    work = args.work or tempfile.mkdtemp(prefix="rcm_coverage_")
    os.makedirs(work, exist_ok=True)
    conditions = []
    for c in args.condition:
        friction, minutes, seeds = c.split(":")
        conditions.append((friction, float(minutes), [int(x) for x in seeds.split(",")]))
    if not conditions:
        conditions = [(f, float(m), [int(x) for x in args.seeds.split(",")])
                      for f in args.frictions.split(",") for m in args.minutes.split(",")]
    rows = []
    for friction, minutes, seeds in conditions:
        far, near, far3, near3, farp, nearp = [], [], [], [], [], []
        inside, trials = [0, 0, 0], 0
        for seed in seeds:
            res = study(rcm, work, friction, minutes, seed, "balanced")
            paper = study(rcm, work, friction, minutes, seed, "last-hold")
            for t, tp in zip(res["trials"], paper["trials"]):
                j = t["joint"]
                far_trial = t["truth_m"][2] > 0.020 + 1e-9
                (far if far_trial else near).append(j["error_m"])
                (far3 if far_trial else near3).append(t["three_step"]["error_m"])
                (farp if far_trial else nearp).append(tp["three_step"]["error_m"])
                trials += 1
                for a in range(3):
                    inside[a] += j["ci95_low_m"][a] <= t["truth_m"][a] <= j["ci95_high_m"][a]
        rows.append((friction, minutes, ",".join(map(str, seeds)), trials, mean(far), mean(near), mean(far3), mean(near3),
                     mean(farp), mean(nearp), [i / trials for i in inside]))
        print(rows[-1], file=sys.stderr, flush=True)
    load = os.getloadavg()
    lines = [f"Run {datetime.date.today().isoformat()} by bench/interval_coverage.py on {os.cpu_count()} cores "
             f"of {cpu_model()}, load average {load[0]:.1f} at the end. "
             "Each seed is one simulated session of 15 trials (D = 10..50 mm x radial [0, 0], [10, 15], "
             "[-12, 8] mm), estimated by `rcm run` with its defaults; the paper's last-hold static step "
             "(`--static-step last-hold`) reuses the same fitted model.", "",
             "| friction | free space | seeds | trials | joint mean e, D > 20 / <= 20 mm | "
             "three-step (balanced holds) | three-step (paper: last hold) | joint 95 % coverage x / y / D |",
             "|---|---|---|---|---|---|---|---|"]
    for fr, mins, seed_list, n, f, ne, f3, n3, fp, np_, cov in rows:
        lines.append(f"| {fr} | {mins:g} min | {seed_list} | {n} | {1e3 * f:.2f} / {1e3 * ne:.2f} | "
                     f"{1e3 * f3:.2f} / {1e3 * n3:.2f} | "
                     f"{1e3 * fp:.2f} / {1e3 * np_:.2f} | "
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
