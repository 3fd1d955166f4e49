#!/usr/bin/python3
"""How long the CI's work takes from scratch (`.ci/run`: `make test`, then
`make test-sanitize`), phase by phase, in fresh build directories; writes the
table into docs/validation-reliability.md between its markers.

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
    rows.append(("build (`make build`, fresh)", *timed("build", ["make", "build", f"BUILD={build}"], env)))
    rows.append(("tests (`make test`'s ctest)", *timed("test", ["make", "test", f"BUILD={build}"], env)))
    rows.append(("instrumented build (`make build-sanitize`, fresh)",
                 *timed("build-sanitize", ["make", "build-sanitize", f"SANITIZE_BUILD={sanitize}"], env)))
    rows.append(("instrumented tests (`make test-sanitize`'s ctest)",
                 *timed("test-sanitize", ["make", "test-sanitize", f"SANITIZE_BUILD={sanitize}"], env)))
    total = sum(r[1] for r in rows)
    ok = all(r[2] == 0 for r in rows)
    lines = [f"Measured {datetime.date.today().isoformat()} on {cpu_model()} ({os.cpu_count()} cores), Debian packages "
             "installed, fresh build directories (`/usr/bin/python3 bench/ci_timing.py`):", "",
             "| phase | minutes | exit |", "|---|---|---|"]
    for label, seconds, code in rows:
        lines.append(f"| {label} | {seconds / 60:.1f} | {code} |")
    lines.append(f"| all of `.ci/run` | {total / 60:.1f} | {'0' if ok else 'failed'} |")
    write_block(DOC, BEGIN, END, "\n".join(lines))
    print("\n".join(lines))
    shutil.rmtree(a.work, ignore_errors=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
