#!/usr/bin/python3
"""How long the CI's work takes from scratch (`.ci/run`: `make test`, then
`make test-sanitize`), phase by phase, in fresh build directories, and the disk
both build directories hold after each phase (a CI machine's disk is finite);
writes the table into docs/validation-reliability.md between its markers.

    /usr/bin/python3 bench/ci_timing.py [--work /tmp/rcm-ci-timing]

The Debian packages are assumed installed (`make deps` first): their download
time depends on the mirror, not on rcm.
"""
import argparse
import datetime
import os
import shutil
import subprocess
import sys
import time

from doc_tables import cpu_model, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation-reliability.md")
BEGIN, END = "<!-- ci-timing:begin -->", "<!-- ci-timing:end -->"


def timed(label, cmd, env=None):
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    t0 = time.monotonic()
    r = subprocess.run(cmd, cwd=ROOT, env=env)
    seconds = time.monotonic() - t0
    print(f"{label}: {seconds:.0f} s, exit {r.returncode}", file=sys.stderr, flush=True)
    return seconds, r.returncode


def disk_gb(*paths):
    """Disk the folders hold (allocated blocks, as du counts), GB."""
    total = 0
    for path in paths:
        for folder, _, files in os.walk(path):
            for name in files:
                try:
                    total += os.lstat(os.path.join(folder, name)).st_blocks * 512
                except OSError:
                    pass
    return total / 1e9


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/rcm-ci-timing")
    a = ap.parse_args()
    build, sanitize = os.path.join(a.work, "build"), os.path.join(a.work, "build-sanitize")
    shutil.rmtree(a.work, ignore_errors=True)
    os.makedirs(a.work)
    env = dict(os.environ)
    rows = []
    # make build = deps + configure + build; make test = build + ctest; make
    # test-sanitize = configure + build + ctest, here one phase at a time.
    phases = [("build (`make build`, fresh)", "build", ["make", "build", f"BUILD={build}"]),
              ("tests (`make test`'s ctest)", "test", ["make", "test", f"BUILD={build}"]),
              ("instrumented build (`make build-sanitize`, fresh)", "build-sanitize",
               ["make", "build-sanitize", f"SANITIZE_BUILD={sanitize}"]),
              ("instrumented tests (`make test-sanitize`'s ctest)", "test-sanitize",
               ["make", "test-sanitize", f"SANITIZE_BUILD={sanitize}"])]
    for label, name, cmd in phases:
        seconds, code = timed(name, cmd, env)
        rows.append((label, seconds, code, disk_gb(build, sanitize)))
        if code != 0:
            break
    total = sum(r[1] for r in rows)
    ok = len(rows) == len(phases) and all(r[2] == 0 for r in rows)
    lines = [f"Measured {datetime.date.today().isoformat()} on {cpu_model()} ({os.cpu_count()} cores), Debian packages "
             "installed, fresh build directories (`/usr/bin/python3 bench/ci_timing.py`); disk: both build "
             "directories after the phase:", "",
             "| phase | minutes | exit | disk (GB) |", "|---|---|---|---|"]
    for label, seconds, code, gb in rows:
        lines.append(f"| {label} | {seconds / 60:.1f} | {code} | {gb:.1f} |")
    lines.append(f"| all of `.ci/run` | {total / 60:.1f} | {'0' if ok else 'failed'} | {max(r[3] for r in rows):.1f} |")
    write_block(DOC, BEGIN, END, "\n".join(lines))
    print("\n".join(lines))
    shutil.rmtree(a.work, ignore_errors=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
