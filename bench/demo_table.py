#!/usr/bin/python3
"""`make docs-figures` (with bench/interval_coverage.py): the demo's figures in
docs/validation.md and docs/benchmarks.md, from a run.

Runs `rcm demo` (the default bench, seed 1) and `rcm demo --quick` into a
temporary folder, checks that the demo printed no line twice, and writes
- the table "paper vs rcm" of docs/validation.md (Table II-IV figures of the demo's
  results.json) between the demo-table markers,
- the wall time of both runs in docs/benchmarks.md between the demo-time markers,
with the date, machine and commands.

Run with Debian's Python: /usr/bin/python3 bench/demo_table.py --build build
"""
import argparse
import collections
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time

from doc_tables import cpu_model, run, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ACCURACY = os.path.join(ROOT, "docs", "validation.md")
SPEED = os.path.join(ROOT, "docs", "benchmarks.md")
TABLE = ("<!-- demo-table:begin -->", "<!-- demo-table:end -->")
TIMES = ("<!-- demo-time:begin -->", "<!-- demo-time:end -->")

# The paper's physical bench (Tables II-IV), quoted beside rcm's simulated one.
PAPER = {"nrmse": "1.6 / 1.5 / 5.3 %", "above": "4.2 +- 2.1 mm", "below": "10.8-17.2 mm",
         "coaxial": "1.4 / 0.7 / 2.1 N", "offset": "2.0 / 1.4 / 1.8 N"}


def demo(rcm, out, quick):
    """Runs the demo; its printed lines and wall time, and its results.json."""
    cmd = [rcm, "demo", "--out", out] + (["--quick"] if quick else [])
    start = time.monotonic()
    proc = run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seconds = time.monotonic() - start
    # Within one step of the run (the lines up to the first trial, each
    # trial's) no line repeats; trials of the same bench may say the same.
    steps, repeated = [[]], []
    for line in proc.stdout.splitlines():
        if line.startswith("[rcm] trial "):
            steps.append([])
        if line.strip() and not set(line.strip()) <= set("-|: "):
            steps[-1].append(line)
    for step in steps:
        repeated += [l for l, n in collections.Counter(step).items() if n > 1]
    if repeated:
        sys.exit(f"{' '.join(cmd)} printed these lines more than once:\n  " + "\n  ".join(repeated))
    with open(os.path.join(out, "report", "results.json")) as f:
        return json.load(f), seconds


def mm(x):
    return f"{1e3 * x:.2f}"


def trial(results, name):
    for t in results["trials"]:
        if t["name"] == name:
            return t
    sys.exit(f"the demo has no trial {name}")


def worst_case_rows(summary_path):
    """The demo table's worst-seed rows, from the summary.json of `make coverage`: the
    default method's and the three-step's mean e per seed on 15 min of teleoperation,
    worst seed and median over every seed and tissue law, and the intervals' coverage."""
    with open(summary_path) as f:
        summary = json.load(f)
    sel = [r for r in summary["results"] if r["row"] == "teleop15"]
    if not sel:
        return []
    mean_of = lambda v: sum(v) / len(v)

    def seeds(key):
        far = sorted(mean_of([t[key] for t in r["corrected"]["trials"] if t["far"]]) for r in sel)
        near = sorted(mean_of([t[key] for t in r["corrected"]["trials"] if not t["far"]]) for r in sel)
        return (f"{mm(far[-1])} / {mm(near[-1])} mm (median {mm(far[len(far) // 2])}/"
                f"{mm(near[len(near) // 2])})")

    trials = [t for r in sel for t in r["corrected"]["trials"]]
    cov = " / ".join(f"{100 * mean_of([t['covered'][a] for t in trials]):.0f}" for a in range(3))
    laws = sorted({r["law"] for r in sel})
    n_seeds = len({r["seed"] for r in sel})
    return [f"| mean e, worst of {n_seeds} seeds x {len(laws)} laws (`make coverage`) | | "
            f"{seeds('three_step_m')} | {seeds('joint_m')} | |",
            f"| 95 % intervals covering x / y / D, those {len(trials)} trials | | | {cov} % | |"]


def readme_table(results, seconds, when, machine, summary_path=None):
    s = results["summary"]
    fit = results["free_space_model"]["fit"]
    nrmse = " / ".join(f"{j['nrmse_percent']:.2f}" for j in fit["test"])
    trials = results["trials"]
    covered = sum(1 for t in trials if t.get("joint", {}).get("truth_inside_ci95"))

    def three_step(key):
        e = s[key]
        return f"{mm(e['mean_m'])} +- {mm(e['sd_m'])} mm"

    def force(name):
        return " / ".join(f"{f:.2f}" for f in trial(results, name)["force_rmse_n"]) + " N"

    lines = [
        f"`make demo` on {when} ({machine}), by `bench/demo_table.py`: {seconds:.0f} s for `rcm demo` in all. "
        f"Seed 1 of the default bench (real friction, two holds per static file, the paper's 10 trials), "
        f"{fit['kind']} free-space model fitted in {fit['seconds']:.0f} s:",
        "",
        "| | paper | rcm three-step (balanced holds) | rcm joint (default) | rcm online (streamed) |",
        "|---|---|---|---|---|",
        f"| free-space NRMSE yaw / pitch / insertion | {PAPER['nrmse']} | {nrmse} % | (same model) | (same model) |",
        f"| mean e, D > 20 mm | {PAPER['above']} | {three_step('three_step_error_D_above_20mm')} | "
        f"{mm(s['error_D_above_20mm']['mean_m'])} mm | {mm(s['online_error_D_above_20mm']['mean_m'])} mm |",
        f"| mean e, D <= 20 mm | {PAPER['below']} | {three_step('three_step_error_D_up_to_20mm')} | "
        f"{mm(s['error_D_up_to_20mm']['mean_m'])} mm | {mm(s['online_error_D_up_to_20mm']['mean_m'])} mm |",
        f"| force RMSE at D = 30 mm, Fx / Fy / Fz, pure coaxial | {PAPER['coaxial']} | {force('D30_r0_0')} | | |",
        f"| force RMSE at D = 30 mm, Fx / Fy / Fz, hybrid offset | {PAPER['offset']} | {force('D30_r10_15')} | | |",
        f"| 95 % intervals covering the truth | | | {covered} of {len(trials)} | |",
        f"| settled within 5 mm of the final estimate | | | | < {s['online_settled_after_s_max']:.1f} s after the "
        "first motion |",
    ]
    if summary_path:
        lines += worst_case_rows(summary_path)
    return "\n".join(lines)


def times_table(full, quick, when, machine):
    lines = [
        f"Measured by `bench/demo_table.py` on {when}, {machine}.", "",
        "| what | wall | target |", "|---|---|---|",
        f"| `rcm demo`: the whole study, {full[0]['free_space_model']['fit']['kind']} fit "
        f"{full[0]['free_space_model']['fit']['seconds']:.0f} s, 10 trials, 60 + 30 bootstrap replicates, "
        f"three-step and online beside | {full[1]:.0f} s | < 10 min |",
        f"| `rcm demo --quick` (150 s of free space, 30 s trials, 20 + 10 replicates) | {quick[1]:.0f} s | < 2 min |",
    ]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--no-doc", action="store_true", help="print the tables only")
    ap.add_argument("--coverage-summary", help="summary.json of `make coverage`: adds its worst-seed rows")
    args = ap.parse_args()
    rcm = os.path.join(os.path.abspath(args.build), "bin", "rcm")
    with tempfile.TemporaryDirectory(prefix="rcm_demo_table_") as work:
        full = demo(rcm, os.path.join(work, "full"), False)
        quick = demo(rcm, os.path.join(work, "quick"), True)
    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    machine = f"{os.cpu_count()} cores of {cpu_model()}, load average {os.getloadavg()[0]:.1f} at the end"
    table = readme_table(*full, when, machine, args.coverage_summary)
    times = times_table(full, quick, when, machine)
    print(table + "\n\n" + times)
    if not args.no_doc:
        write_block(ACCURACY, *TABLE, table)
        write_block(SPEED, *TIMES, times)
        print(f"wrote {ACCURACY} and {SPEED}", file=sys.stderr)


if __name__ == "__main__":
    main()
