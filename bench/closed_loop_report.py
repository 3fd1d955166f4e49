#!/usr/bin/python3
"""The closed-loop bench's table in docs/simulator.md and docs/compensation.md,
and its figures in docs/figures/, from a run of `rcm simulate --experiment
closed-loop` (the default session and free-space model unless told otherwise).

    /usr/bin/python3 bench/closed_loop_report.py --build build [--seed 1] [--model KIND] [--quick]
"""
import argparse
import datetime
import json
import os
import shutil
import tempfile

from doc_tables import cpu_model, run, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCS = [(os.path.join(ROOT, "docs", "simulator.md"), "<!-- closed-loop:begin -->", "<!-- closed-loop:end -->"),
        (os.path.join(ROOT, "docs", "compensation.md"), "<!-- closed-loop-summary:begin -->",
         "<!-- closed-loop-summary:end -->")]
FIGURES = ["closed_loop_step_force", "closed_loop_step_misalignment", "closed_loop_drift_force",
           "closed_loop_breathing_force"]


def fmt_time(v):
    return "never" if v is None else f"{v:.1f}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--seed", default="1")
    ap.add_argument("--model", default=None, help="free-space model kind (default: rcm monitor's)")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    rcm = os.path.join(a.build, "bin", "rcm")
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [rcm, "simulate", "--experiment", "closed-loop", "--seed", a.seed, "--out", tmp, "--json"]
        if a.model:
            cmd += ["--model", a.model]
        if a.quick:
            cmd += ["--quick"]
        j = json.loads(run(cmd, capture_output=True, text=True).stdout)
        for name in FIGURES:
            shutil.copyfile(os.path.join(tmp, name + ".png"), os.path.join(ROOT, "docs", "figures", name + ".png"))
    shown = " ".join(os.path.relpath(c, ROOT) if c == rcm else c for c in cmd if c != tmp).replace(" --out", " --out DIR")
    lines = [f"Measured {datetime.date.today().isoformat()} on {cpu_model()} ({os.cpu_count()} cores): `{shown}` "
             f"(`/usr/bin/python3 bench/closed_loop_report.py`), {j['free_space_model']} free-space model, "
             f"{j['elapsed_s']:.0f} s in all.", "",
             "| scenario | run | peak force (N) | RMS force after settling (N) | onset to force below 2 N (s) | "
             "residual misalignment (mm) | moves | wrong-direction moves |", "|---|---|---|---|---|---|---|---|"]
    for name, s in j["scenarios"].items():
        for run_name in ("open", "closed"):
            r = s[run_name]
            moves = str(r["moves"]) if run_name == "closed" else "-"
            lines.append(f"| {name} | {run_name} | {r['peak_force_n']:.1f} | {r['rms_force_after_settle_n']:.2f} | "
                         f"{fmt_time(r['time_to_below_2n_s'])} | {1e3 * r['residual_misalignment_m']:.1f} | {moves} | "
                         f"{r['wrong_direction_moves']} |")
    lines += ["", "Figures (true incision force and true misalignment against time, both runs): " +
              ", ".join(f"[{n}](figures/{n}.png)" for n in FIGURES) + "."]
    for doc, begin, end in DOCS:
        write_block(doc, begin, end, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
