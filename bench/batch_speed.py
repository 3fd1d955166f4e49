#!/usr/bin/python3
"""How much `rcm batch` gains from its workers, and that it changes no number.

N simulated sessions (`rcm simulate --quick --seed S`, S = 1..N, each its own
bench, teleoperation and noise) are estimated three ways: `rcm run` on each, one
after another; `rcm batch --workers 1`; `rcm batch --workers W` (a LocalCluster
on this machine). Every session's results.json must be the same in the three,
wall-clock times aside. The table goes between the batch-speed markers of
docs/benchmarks.md, with the date, the machine and its load.

    /usr/bin/python3 bench/batch_speed.py --build build [--sessions 8] [--workers 2] [--no-doc]
"""
import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

from doc_tables import cpu_model, publish_block, run

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
BEGIN, END = "<!-- batch-speed:begin -->", "<!-- batch-speed:end -->"
TARGET = 1.7  # speed-up of 2 workers on 2 cores over one session after another


def without_timings(value):
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if k not in ("seconds", "mean_update_us")}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


def results(folder, names):
    out = {}
    for name in names:
        with open(os.path.join(folder, name, "results.json")) as f:
            out[name] = without_timings(json.load(f))
    return out


def timed(cmd):
    start = time.monotonic()
    run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.monotonic() - start


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--sessions", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-doc", action="store_true", help="print the table without writing docs/benchmarks.md")
    a = ap.parse_args()
    rcm = os.path.abspath(os.path.join(a.build, "bin", "rcm"))
    work = tempfile.mkdtemp(prefix="rcm_batch_speed_")
    try:
        names = [f"seed{s}" for s in range(1, a.sessions + 1)]
        manifests = []
        for s, name in enumerate(names, start=1):
            folder = os.path.join(work, "sessions", name)
            run([rcm, "simulate", "--quick", "--seed", str(s), "--out", folder], stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL)
            manifests.append(os.path.join(folder, "session.json"))
        load_start = os.getloadavg()[0]
        serial = 0.0
        for name, manifest in zip(names, manifests):
            serial += timed([rcm, "run", manifest, "--out", os.path.join(work, "alone", name)])
        one = timed([rcm, "batch", "--workers", "1", "--out", os.path.join(work, "one"), *manifests])
        many = timed([rcm, "batch", "--workers", str(a.workers), "--out", os.path.join(work, "many"), *manifests])
        load_end = os.getloadavg()[0]
        alone = results(os.path.join(work, "alone"), names)
        same = all(results(os.path.join(work, d), names) == alone for d in ("one", "many"))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    lines = [f"Measured {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} cores of "
             f"{cpu_model()} (load average {load_start:.1f} before, {load_end:.1f} after, other work included) by "
             f"`/usr/bin/python3 bench/batch_speed.py --sessions {a.sessions} --workers {a.workers}`: "
             f"{a.sessions} sessions of `rcm simulate --quick` (seeds 1-{a.sessions}, 10 trials each), default "
             "options (linear model fitted per session, joint method).", "",
             "| run | wall time (s) | speed-up over `rcm run` one after another |", "|---|---|---|",
             f"| `rcm run` on each, one after another | {serial:.1f} | 1.00 |",
             f"| `rcm batch --workers 1` | {one:.1f} | {serial / one:.2f} |",
             f"| `rcm batch --workers {a.workers}` | {many:.1f} | {serial / many:.2f} |", "",
             f"Every session's results.json (wall-clock times aside) identical in the three runs: "
             f"{'yes' if same else 'NO'}. Target: `rcm batch` with 2 workers at least {TARGET:g} times as fast as "
             f"`rcm run` one after another, results identical: "
             f"{'met' if same and a.workers == 2 and serial / many >= TARGET else 'not met'}. "
             "`rcm batch` does a little more per session than `rcm run` (the setup checks of setup.json) and "
             "starts its cluster (a few seconds)."]
    publish_block(DOC, BEGIN, END, "\n".join(lines), write=not a.no_doc)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
