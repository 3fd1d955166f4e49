#!/usr/bin/python3
"""From docking to the first estimate on the simulated bench, end to end:

    rcm excite --duration 120                  (designed before docking)
    rcm simulate --free-space-trajectory ...   (the robot's time: free space,
                 --calibration-s 30             baseline, calibration)
    rcm setup SESSION                          (checks, fits; says ready)
    rcm monitor --model-file ...               (every trial streamed: the first
                                                estimate, its settling and error)
    rcm run --model-file ...                   (the same trials, the batch
                                                estimate beside it)

for a few seeds. Robot time is the recordings' own duration as `rcm setup`
counts it; computation is the wall time of `rcm setup` (fit, learning curve,
tissue model, checks) on this machine. The table goes between the markers of
docs/validation.md with the date and machine:

    /usr/bin/python3 bench/ready_time.py [--build build] [--seeds 1,2,3] [--no-doc]
"""
import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import cpu_model, run, write_block  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation.md")
BEGIN, END = "<!-- ready-time:begin -->", "<!-- ready-time:end -->"


def timed_json(cmd, ok_codes=(0,)):
    start = time.monotonic()
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    if p.returncode not in ok_codes:
        raise SystemExit(f"{cmd[1]} exited {p.returncode}")
    return json.loads(p.stdout), time.monotonic() - start, p.returncode


def one_seed(rcm, seed, work, args):
    d = os.path.join(work, f"seed{seed}")
    os.makedirs(d, exist_ok=True)
    traj = os.path.join(d, "excitation.csv")
    excite, excite_s, _ = timed_json([rcm, "excite", "--duration", str(args.free_space_s), "--seed", str(seed),
                                      "--out", traj, "--json"])
    session_dir = os.path.join(d, "session")
    run([rcm, "simulate", "--seed", str(seed), "--free-space-trajectory", traj, "--calibration-s",
         str(args.calibration_s), "--trial-s", str(args.trial_s), "--out", session_dir],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    manifest = os.path.join(session_dir, "session.json")
    setup, setup_s, code = timed_json([rcm, "setup", manifest, "--out", os.path.join(d, "setup"), "--json"],
                                      ok_codes=(0, 3))
    with open(manifest) as f:
        trials = json.load(f)["trials"]
    model = os.path.join(d, "setup", "free_space_model.json")
    errors = {"above": [], "up_to": []}
    settled = []
    covered = []  # per axis: the truth within the monitor's final estimate +- 1.96 sd
    for t in trials:
        rec = os.path.join(session_dir, t["recording"])
        mon, _, _ = timed_json([rcm, "monitor", "--session", manifest, "--model-file", model, rec, "--quiet",
                                "--json"])
        D = t["truth"]["misalignment_m"][2]
        errors["above" if D > 0.020 else "up_to"].append(mon["error_m"])
        if mon.get("settled_after_s") is not None:
            settled.append(mon["settled_after_s"])
        final = mon["final"]
        covered += [abs(p - q) <= 1.96 * s for p, q, s in zip(final["misalignment_m"], mon["truth_m"], final["sd_m"])]
    # The batch estimate on the same trials, with the same model.
    run([rcm, "run", manifest, "--model-file", model, "--out", os.path.join(d, "run")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(os.path.join(d, "run", "results.json")) as f:
        batch = {"above": [], "up_to": []}
        for t in json.load(f)["trials"]:
            batch["above" if t["truth_m"][2] > 0.020 else "up_to"].append(t["joint"]["error_m"])
    return {
        "seed": seed,
        "excite_s": excite_s,
        "condition_number": excite["condition_number"],
        "ready": setup["ready"],
        "exit": code,
        "missing": [f["message"] for f in setup["findings"] if f["severity"] == "missing"],
        "robot_s": setup["robot_time_s"],
        "setup_compute_s": setup["compute_s"],
        "setup_wall_s": setup_s,
        "force_error_n": setup["model"]["force_error_n"],
        "self_check_m": (setup["calibration"] or {}).get("self_check_error_m"),
        "mean_e_above_20mm": statistics.mean(errors["above"]) if errors["above"] else None,
        "mean_e_up_to_20mm": statistics.mean(errors["up_to"]) if errors["up_to"] else None,
        "run_mean_e_above_20mm": statistics.mean(batch["above"]) if batch["above"] else None,
        "run_mean_e_up_to_20mm": statistics.mean(batch["up_to"]) if batch["up_to"] else None,
        "monitor_axes_covered": sum(covered),
        "monitor_axes": len(covered),
        "settled_after_s_max": max(settled) if settled else None,
        "trials": len(trials),
    }


def mm(v):
    return "n/a" if v is None else f"{1e3 * v:.2f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--free-space-s", type=float, default=120.0)
    ap.add_argument("--calibration-s", type=float, default=30.0)
    ap.add_argument("--trial-s", type=float, default=30.0)
    ap.add_argument("--keep", help="keep the sessions and reports in this directory")
    ap.add_argument("--json", help="write every figure to this file")
    ap.add_argument("--no-doc", action="store_true", help="print the table instead of writing docs/validation.md")
    args = ap.parse_args()
    rcm = os.path.join(args.build, "bin", "rcm")
    work = args.keep or tempfile.mkdtemp(prefix="rcm_ready_")
    rows = [one_seed(rcm, int(s), work, args) for s in args.seeds.split(",")]
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=2)

    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    # Robot time: the same on every seed by construction; said once, else with its seeds.
    robot = {}
    for r in rows:
        t = r["robot_s"]
        robot.setdefault(f"{t['free_space']:g} + {t['baseline']:g} + {t['calibration']:g} s", []).append(str(r["seed"]))
    robot_text = "; ".join(k if len(robot) == 1 else f"{k} (seed {', '.join(v)})" for k, v in robot.items())
    robot_text += " of free space, baseline, calibration"
    lines = [f"Measured by `bench/ready_time.py` on {stamp}, {cpu_model()}, {os.cpu_count()} cores. "
             f"Per seed: `rcm excite --duration {args.free_space_s:g}`, `rcm simulate --free-space-trajectory` with "
             f"`--calibration-s {args.calibration_s:g} --trial-s {args.trial_s:g}` (robot time {robot_text}), "
             "then `rcm setup`. Then `rcm monitor --model-file` and `rcm run --model-file` on every trial, final "
             "estimates against the truth. Settled: from the first motion on, the running estimate within 5 mm of "
             "the final one.",
             "",
             "| seed | ready | `rcm setup` computation (s) | force error (N) | self-check (mm) | "
             "mean e, D > 20 / <= 20 mm, `rcm monitor` | `rcm run` | settled, worst (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['seed']} | {'yes' if r['ready'] else 'no'} | {r['setup_compute_s']:.1f} | "
                     f"{r['force_error_n']:.2f} | {mm(r['self_check_m'])} | {mm(r['mean_e_above_20mm'])} / "
                     f"{mm(r['mean_e_up_to_20mm'])} | {mm(r['run_mean_e_above_20mm'])} / "
                     f"{mm(r['run_mean_e_up_to_20mm'])} | "
                     f"{'n/a' if r['settled_after_s_max'] is None else format(r['settled_after_s_max'], '.2f')} |")
    axes, held = sum(r["monitor_axes"] for r in rows), sum(r["monitor_axes_covered"] for r in rows)
    lines.append(f"\nThe monitor's 95 % bands held the truth on {held} of {axes} axes.")
    for r in rows:
        for m in r["missing"]:
            lines.append(f"\nSeed {r['seed']}, missing: {m}")
    block = "\n".join(lines)
    if args.no_doc:
        print(block)
        return
    write_block(DOC, BEGIN, END, block)
    print(block)


if __name__ == "__main__":
    main()
