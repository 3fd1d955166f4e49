#!/usr/bin/python3
"""`make coverage`: each method's error on the worst seed, its spread over the
seeds, and how often the 95 % intervals cover the truth, per free-space row,
over the seeds and the three tissue laws (linear, stiffening, sliding), on the
default bench (`real` friction).

A row is a free-space recording: `teleop15` (15 min of the simulator's
teleoperation), `teleop2` (2 min of it) and `excite2` (the 2-minute path of
`rcm excite --duration 120`, played on the arm). For a seed S and a law L every
row shares the same calibration and trials (they do not depend on the free
space), so the work splits into independent tasks, each a plain function of
its arguments that runs rcm commands in its own folder under --work and
returns a JSON-able dict (a kept folder resumes):

- free_space_task(rcm, work, seed, row): the row's free-space recording and the
  linear model `rcm dynamics fit` fits on it;
- session_task(rcm, work, seed, law): the calibration, baseline and the 15
  trials (D = 10..50 mm x radial [0, 0], [10, 15], [-12, 8] mm, two holds per
  static file) of `rcm simulate --tissue L`;
- study_task(rcm, work, seed, law, row, free_space, session): the session with
  the row's free space, `rcm run` with its defaults on the row's model
  (`--model-file`: joint method with the calibration's bias correction,
  three-step with balanced holds beside it) and once more without the
  correction (`fit_torque_offset` false, no bootstrap: point estimates for
  the before/after table).

`main` runs them through rcm.batch: a local cluster (--workers, default one
per core) or a Dask scheduler's workers (--scheduler), which must see --work
at the same path. The tables go between the worst-case markers of
docs/validation.md, with the date, machine and wall time, and every task's
figures into --work/summary.json.

Run with Debian's Python: /usr/bin/python3 bench/interval_coverage.py --build build
"""
import argparse
import datetime
import json
import math
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import add_cluster_flags, cpu_model, open_runner, publish_block  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation.md")
BEGIN, END = "<!-- worst-case:begin -->", "<!-- worst-case:end -->"
LAWS = ("linear", "stiffening", "sliding")
ROWS = {"teleop15": ("teleoperation", 15.0), "teleop2": ("teleoperation", 2.0), "excite2": ("rcm excite", 2.0)}
GRID = {"coaxial_offsets_m": [0.010, 0.020, 0.030, 0.040, 0.050],
        "radial_offsets_m": [[0.0, 0.0], [0.010, 0.015], [-0.012, 0.008]], "static_approaches": 2}
# Targets on the worst seed (mean e, D > 20 / <= 20 mm), and the self-check's threshold.
TARGETS = {"teleop15": {"joint": (0.5, 1.0), "three_step": (2.0, 4.0)}, "excite2": {"joint": (1.0, 1.5)}}
SELF_CHECK_M = 0.001


def call(cmd, log):
    """Runs an rcm command, its output appended to `log`; raises on failure."""
    with open(log, "a") as f:
        f.write("+ " + " ".join(cmd) + "\n")
        f.flush()
        subprocess.run(cmd, check=True, stdout=f, stderr=subprocess.STDOUT)


def write_json(path, value):
    with open(path + ".tmp", "w") as f:
        json.dump(value, f)
    os.replace(path + ".tmp", path)


def open_task(folder):
    """The task's result when its folder holds one (a kept --work resumes);
    else None, the folder made."""
    done = os.path.join(folder, "task.json")
    if os.path.exists(done):
        with open(done) as f:
            return json.load(f)
    os.makedirs(folder, exist_ok=True)
    return None


def finish_task(folder, out):
    """Keeps the task's result in its folder, for open_task; returns it."""
    write_json(os.path.join(folder, "task.json"), out)
    return out


def free_space_task(rcm, work, seed, row):
    """The row's free-space recording for this seed, and its fitted linear model."""
    folder = os.path.join(work, f"free_space_{row}_seed{seed}")
    finished = open_task(folder)
    if finished is not None:
        return finished
    log = os.path.join(folder, "log.txt")
    path, minutes = ROWS[row]
    # Only the free space is wanted: the rest of the protocol as short as it may be.
    config = os.path.join(folder, "config.json")
    write_json(config, {"protocol": {"coaxial_offsets_m": [0.03], "radial_offsets_m": [[0.0, 0.0]],
                                     "calibration_s": 1.0, "trial_s": 1.0, "static_hold_s": 1.0,
                                     "baseline_hold_s": 1.0, "write_truth": False}})
    sim = [rcm, "simulate", "--out", os.path.join(folder, "sim"), "--seed", str(seed), "--config", config, "--no-truth"]
    if path == "rcm excite":
        trajectory = os.path.join(folder, "excitation.csv")
        call([rcm, "excite", "--duration", str(60 * minutes), "--seed", str(seed), "--out", trajectory], log)
        sim += ["--free-space-trajectory", trajectory, "--free-space-s", str(60 * minutes)]
    else:
        sim += ["--free-space-s", str(60 * minutes)]
    call(sim, log)
    with open(os.path.join(folder, "sim", "session.json")) as f:
        recordings = [os.path.join(folder, "sim", p) for p in json.load(f)["free_space"]]
    model = os.path.join(folder, "free_space_model.json")
    call([rcm, "dynamics", "fit", "--model", "linear", "--seed", str(seed), "--out", model] + recordings, log)
    return finish_task(folder, {"free_space": recordings, "model": model})


def session_task(rcm, work, seed, law):
    """Calibration, baseline and trials of one seed and tissue law (a token free space)."""
    folder = os.path.join(work, f"session_{law}_seed{seed}")
    finished = open_task(folder)
    if finished is not None:
        return finished
    config = os.path.join(folder, "config.json")
    write_json(config, {"protocol": GRID})
    call([rcm, "simulate", "--out", os.path.join(folder, "sim"), "--seed", str(seed), "--tissue", law,
          "--config", config, "--free-space-s", "5", "--no-truth"], os.path.join(folder, "log.txt"))
    return finish_task(folder, {"manifest": os.path.join(folder, "sim", "session.json")})


def trial_summary(results, side_of):
    """Per trial of a results.json: truth, joint and three-step errors, whether the interval covers each axis."""
    out = []
    for t in results["trials"]:
        j = t["joint"]
        out.append({"name": t["name"], "D_m": t["truth_m"][2], "far": side_of(t["truth_m"][2]),
                    "joint_m": j["error_m"], "three_step_m": t["three_step"]["error_m"],
                    "covered": [j["ci95_low_m"][a] <= t["truth_m"][a] <= j["ci95_high_m"][a] for a in range(3)]})
    return out


def prepare_task(rcm, work, kind, seed, name):
    """free_space_task or session_task, so that both go to the cluster together."""
    return (free_space_task if kind == "free_space" else session_task)(rcm, work, seed, name)


def study_task(rcm, work, seed, law, row, free_space, session):
    """`rcm run` on the session with the row's free space and model: with and without the bias correction."""
    folder = os.path.join(work, f"study_{row}_{law}_seed{seed}")
    finished = open_task(folder)
    if finished is not None:
        return finished
    log = os.path.join(folder, "log.txt")
    with open(session["manifest"]) as f:
        manifest = json.load(f)
    base = os.path.dirname(session["manifest"])
    absolute = lambda p: p if os.path.isabs(p) else os.path.join(base, p)
    manifest["free_space"] = free_space["free_space"]
    manifest["baseline"] = absolute(manifest["baseline"])
    manifest["calibration"]["recording"] = absolute(manifest["calibration"]["recording"])
    for t in manifest["trials"]:
        t["recording"] = absolute(t["recording"])
        if "static" in t:
            t["static"] = absolute(t["static"])
    path = os.path.join(folder, "session.json")
    write_json(path, manifest)
    runs = {}
    no_correction = os.path.join(folder, "no_correction.json")
    write_json(no_correction, {"joint": {"fit_torque_offset": False, "bootstrap_replicates": 0,
                                         "calibration_bootstrap_replicates": 0}, "tissue_sensitivity_delta_m": 0.0})
    start = time.monotonic()
    for name, extra in (("corrected", []), ("uncorrected", ["--options", no_correction])):
        out_dir = os.path.join(folder, name)
        call([rcm, "run", path, "--out", out_dir, "--seed", str(seed), "--model-file", free_space["model"]] + extra,
             log)
        with open(os.path.join(out_dir, "results.json")) as f:
            runs[name] = json.load(f)
    far = lambda D: D > 0.020 + 1e-9
    out = {"seed": seed, "law": law, "row": row, "seconds": time.monotonic() - start}
    for name, r in runs.items():
        tissue = r["joint_tissue_model"]
        out[name] = {"trials": trial_summary(r, far), "self_check_m": math.sqrt(sum(x * x for x in
                                                                                    tissue["calibration_bias_m"])),
                     "torque_offset": tissue.get("torque_offset"), "family": tissue["family"]}
    return finish_task(folder, out)


# ----------------------------------------------------------------------------- tables

def mean(v):
    return sum(v) / len(v) if v else float("nan")


def per_seed(trials, key):
    """Mean error (m) over the trials of D > 20 mm and of D <= 20 mm."""
    return (mean([t[key] for t in trials if t["far"]]), mean([t[key] for t in trials if not t["far"]]))


def spread(values):
    """'min-max' in mm."""
    return f"{1e3 * min(values):.2f}-{1e3 * max(values):.2f}"


def tables(results, wall_s, where, finished=None):
    """The block; `finished`: when the last study ended (default now)."""
    when = (finished or datetime.datetime.now()).strftime("%Y-%m-%d %H:%M")
    seeds = sorted({r["seed"] for r in results})
    rows = [ROWS[r] for r in ROWS if any(x["row"] == r for x in results)]
    lines = [f"Measured by `make coverage` (bench/interval_coverage.py) on {when}, {os.cpu_count()} cores of "
             f"{cpu_model()}, {where}: {wall_s / 60:.0f} min. Seeds {seeds[0]}-{seeds[-1]}, {len(rows)} free spaces. "
             "Per seed and law 15 trials (D 10-50 mm, three radial "
             "offsets), `rcm run` with its defaults. A seed's error "
             "is its mean e over the trials of D > 20 / <= 20 mm; worst seed and range over seeds and laws, in mm.",
             "", "| free space | law | joint (default): worst seed | joint: range | joint 95 % intervals covering "
             "x / y / D (%) | three-step: worst seed |", "|---|---|---|---|---|---|"]
    worst_of, labelled = {}, None
    for row in ROWS:
        for law in LAWS + ("all",):
            sel = [r for r in results if r["row"] == row and (law == "all" or r["law"] == law)]
            if not sel:
                continue
            joint = [per_seed(r["corrected"]["trials"], "joint_m") for r in sel]
            three = [per_seed(r["corrected"]["trials"], "three_step_m") for r in sel]
            trials = [t for r in sel for t in r["corrected"]["trials"]]
            cov = [100.0 * mean([t["covered"][a] for t in trials]) for a in range(3)]
            worst = lambda v: (max(x[0] for x in v), max(x[1] for x in v))
            if law == "all":  # the row's verdicts only: its worst seed is the worst of the laws' rows
                worst_of[row] = {"joint": worst(joint), "three_step": worst(three), "coverage": min(cov)}
                continue
            mm = lambda w: f"{1e3 * w[0]:.2f} / {1e3 * w[1]:.2f}"
            # The free space named on its first row only.
            label = "" if row == labelled else f"{ROWS[row][1]:g} min {ROWS[row][0]}"
            labelled = row
            lines.append(f"| {label} | {law} | {mm(worst(joint))} | "
                         f"{spread([x[0] for x in joint])} / {spread([x[1] for x in joint])} | "
                         f"{cov[0]:.0f} / {cov[1]:.0f} / {cov[2]:.0f} of {len(trials)} | {mm(worst(three))} |")
    # Before / after the bias correction: one row per seed, the laws side by side.
    before_after = sorted((r for r in results if r["row"] == "teleop15"), key=lambda r: (r["seed"], r["law"]))
    if before_after:
        lines += ["", "The bias correction (`joint.fit_torque_offset`), joint method, 15 min of teleoperation: "
                  "mean e D > 20 / <= 20 mm without -> with it:", "",
                  "| seed | " + " | ".join(LAWS) + " |", "|---|" + "---|" * len(LAWS)]
        for seed in sorted({r["seed"] for r in before_after}):
            cells = []
            for law in LAWS:
                r = next((r for r in before_after if r["seed"] == seed and r["law"] == law), None)
                if r is None:
                    cells.append("-")
                    continue
                b, a = per_seed(r["uncorrected"]["trials"], "joint_m"), per_seed(r["corrected"]["trials"], "joint_m")
                cells.append(f"{1e3 * b[0]:.2f}/{1e3 * b[1]:.2f} -> {1e3 * a[0]:.2f}/{1e3 * a[1]:.2f}")
            lines.append(f"| {seed} | " + " | ".join(cells) + " |")
    # The self-check against what the estimate turned out to be: a session is
    # off when its mean e (the targets' unit) or, stricter, its worst trial is.
    def counts(sel, off):
        n = [0, 0, 0, 0]
        for r in sel:
            flagged = r["corrected"]["self_check_m"] > SELF_CHECK_M
            n[(0 if off(r) else 1) if flagged else (2 if off(r) else 3)] += 1
        return "/".join(str(x) for x in n)
    mean_off = lambda r: max((e for e in per_seed(r["corrected"]["trials"], "joint_m") if not math.isnan(e)),
                             default=0.0) > SELF_CHECK_M
    worst_off = lambda r: max(t["joint_m"] for t in r["corrected"]["trials"]) > SELF_CHECK_M
    cells = []
    for row in ROWS:
        sel = [r for r in results if r["row"] == row]
        if sel:
            cells.append(f"{ROWS[row][1]:g} min {ROWS[row][0]} {counts(sel, mean_off)}, {counts(sel, worst_off)}")
    lines += ["", f"`rcm setup`'s self-check (not ready above {1e3 * SELF_CHECK_M:g} mm) against each session's mean e, "
              "then its worst trial. Hits / false alarms / misses / fine: " + "; ".join(cells) + "."]
    # One sentence of verdicts per free-space row.
    lines.append("")
    for row, w in worst_of.items():
        verdicts = []
        for method, (a, b) in TARGETS.get(row, {}).items():
            got = w[method]
            verdicts.append(f"{method} {a:g} / {b:g} mm " +
                            ("met" if got[0] <= a * 1e-3 and got[1] <= b * 1e-3 else "not met"))
        verdicts.append("intervals >= 90 % " + ("met" if w["coverage"] >= 90.0 else "not met"))
        lines.append(f"Targets on the worst seed, {ROWS[row][1]:g} min {ROWS[row][0]}: " + "; ".join(verdicts) + ".")
    return "\n".join(lines)


def runs_where(args):
    if args.scheduler:
        return "on a Dask cluster's workers"
    workers = os.cpu_count() if args.workers is None else args.workers
    return f"{workers} rcm.batch workers" if workers else "one task at a time"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--seeds", default="1,2,3,4,5,6,7,8,9,10")
    ap.add_argument("--rows", default=",".join(ROWS), help="free-space rows: " + ", ".join(ROWS))
    ap.add_argument("--laws", default=",".join(LAWS))
    ap.add_argument("--work", help="keep the tasks' folders here (default: a temporary folder); a kept folder resumes")
    ap.add_argument("--no-doc", action="store_true", help="print the tables only")
    ap.add_argument("--report-only", action="store_true",
                    help="run nothing: the tables of the study tasks finished in --work (e.g. by a cluster)")
    add_cluster_flags(ap)
    args = ap.parse_args()
    rcm = os.path.join(os.path.abspath(args.build), "bin", "rcm")
    work = os.path.abspath(args.work or tempfile.mkdtemp(prefix="rcm_coverage_"))
    os.makedirs(work, exist_ok=True)
    seeds = [int(x) for x in args.seeds.split(",")]
    rows, laws = args.rows.split(","), args.laws.split(",")
    summary_path = os.path.join(work, "summary.json")
    if args.report_only:
        results = []
        for name in sorted(os.listdir(work)):
            done = os.path.join(work, name, "task.json")
            if name.startswith("study_") and os.path.exists(done):
                with open(done) as f:
                    results.append(json.load(f))
        if os.path.exists(summary_path):
            with open(summary_path) as f:
                wall = json.load(f).get("wall_s", 0.0)
        else:  # tasks run elsewhere: from the first task's config to the last study's end
            folders = [os.path.join(work, n) for n in os.listdir(work) if os.path.isdir(os.path.join(work, n))]
            first = min(os.path.getmtime(os.path.join(d, "config.json")) for d in folders
                        if os.path.exists(os.path.join(d, "config.json")))
            wall = max(os.path.getmtime(os.path.join(work, n, "task.json")) for n in os.listdir(work)
                       if n.startswith("study_") and os.path.exists(os.path.join(work, n, "task.json"))) - first
        if not results:
            sys.exit(f"no finished study task in {work}")
        last = max(os.path.getmtime(os.path.join(work, n, "task.json")) for n in os.listdir(work)
                   if n.startswith("study_") and os.path.exists(os.path.join(work, n, "task.json")))
        publish_block(DOC, BEGIN, END, tables(results, wall, runs_where(args), datetime.datetime.fromtimestamp(last)),
                      write=not args.no_doc)
        return
    def report(r):
        print(f"seed {r['seed']} {r['law']} {r['row']}: joint "
              f"{[round(1e3 * x, 2) for x in per_seed(r['corrected']['trials'], 'joint_m')]} mm "
              f"(before {[round(1e3 * x, 2) for x in per_seed(r['uncorrected']['trials'], 'joint_m')]}), "
              f"{r['seconds']:.0f} s", file=sys.stderr, flush=True)

    start = time.monotonic()
    # Through rcm.batch: the free-space recordings and sessions first, then
    # every study on them; a cluster's workers must see --work at the same path.
    with open_runner(args.build, args.scheduler, args.workers) as run_all:
        inputs = run_all(prepare_task, [(rcm, work, "free_space", s, r) for s in seeds for r in rows] +
                         [(rcm, work, "session", s, l) for s in seeds for l in laws])
        fs = dict(zip([(s, r) for s in seeds for r in rows], inputs))
        ss = dict(zip([(s, l) for s in seeds for l in laws], inputs[len(fs):]))
        results = run_all(study_task, [(rcm, work, s, l, r, fs[(s, r)], ss[(s, l)])
                                       for r in rows for s in seeds for l in laws], report)
    wall = time.monotonic() - start
    # A resumed run adds the wall time of the runs before it on the same folder.
    if os.path.exists(summary_path):
        with open(summary_path) as f:
            wall += json.load(f).get("wall_s", 0.0)
    write_json(summary_path, {"seeds": seeds, "wall_s": wall, "results": results})
    publish_block(DOC, BEGIN, END, tables(results, wall, runs_where(args)), write=not args.no_doc)


if __name__ == "__main__":
    main()
