#!/usr/bin/env python3
"""The commands that stream a recording hold the same memory whatever its
length.

Tiles a trial of the test session to SHORT and LONG rows (as
bench/stream_memory.py does, with an MCAP copy by `rcm convert`) and runs each
streaming command on both: `inspect` (CSV and MCAP), `convert` to CSV,
`force --out`, `monitor --out` (CSV), `monitor` (MCAP) and `dynamics eval`.
Fails when a command's peak resident memory (the child's own maximum RSS) on
the long recording exceeds the short one's by more than LIMIT_MB, or when a
command fails.

A command that held the whole recording would grow by about 240 bytes a row
(what `rcm inspect` held when it loaded the file): over the LONG - SHORT rows
that is about 40 MB, against a limit of 8. A streaming command's peak moves by
a megabyte or two (allocator and page noise). `--self-test` runs the
measurement on a child that reads the long file whole and fails unless the
check flags it, and plants figures on both sides of the limit.

Usage: test_stream_memory.py --rcm PATH --session SESSION_JSON --model MODEL
           [--work DIR] | --self-test

Not run in the instrumented build: AddressSanitizer keeps freed memory in its
quarantine (256 MB), so the peak tracks what a command allocated in all, not
what it held at once.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
from stream_memory import measure, tile_csv  # noqa: E402

SHORT, LONG = 20_000, 200_000
LIMIT_MB = 8.0


def check(peaks, limit_mb=LIMIT_MB):
    """Messages for every command whose peak grew by more than `limit_mb`.

    `peaks`: {command label: (MB at SHORT rows, MB at LONG rows)}."""
    return [f"{label}: peak memory {short:.1f} MB at {SHORT} rows, {long:.1f} MB at {LONG} rows "
            f"(+{long - short:.1f} MB, limit +{limit_mb:g} MB)"
            for label, (short, long) in peaks.items() if long - short > limit_mb]


def commands(rcm, session, model, csv, bag, out):
    return [
        ("inspect CSV", [rcm, "inspect", csv]),
        ("inspect MCAP", [rcm, "inspect", bag]),
        ("convert MCAP to CSV", [rcm, "convert", bag, os.path.join(out, "converted.csv")]),
        ("force --out", [rcm, "force", "--model", model, "--offset", "0.03", csv,
                         "--out", os.path.join(out, "force.csv")]),
        ("monitor --out CSV", [rcm, "monitor", "--session", session, csv, "--quiet",
                               "--out", os.path.join(out, "monitor.csv")]),
        ("monitor MCAP", [rcm, "monitor", "--session", session, bag, "--quiet"]),
        ("dynamics eval", [rcm, "dynamics", "eval", model, csv]),
    ]


def tiled(rcm, source, rows, work):
    csv = os.path.join(work, f"tiled_{rows}.csv")
    bag = os.path.join(work, f"tiled_{rows}.mcap")
    tile_csv(source, rows, csv)
    subprocess.run([rcm, "convert", csv, bag], check=True, stdout=subprocess.DEVNULL)
    return csv, bag


def first_trial(session):
    with open(session) as f:
        manifest = json.load(f)
    return os.path.join(os.path.dirname(session), manifest["trials"][0]["recording"])


def self_test():
    failures = []
    if check({"flat": (30.0, 31.5)}):
        failures.append(f"a flat peak was flagged: {check({'flat': (30.0, 31.5)})}")
    if not check({"grows": (30.0, 70.0)}):
        failures.append("a peak growing by 40 MB was not flagged")
    # A child that holds the whole file: the measurement must see it grow.
    with tempfile.TemporaryDirectory(prefix="rcm_test_stream_memory_self_") as work:
        source = os.path.join(work, "source.csv")
        with open(source, "w") as f:
            f.write("time,q1,q2,q3,tau1,tau2,tau3\n")
            f.writelines(f"{0.005 * i!r},0.1,0.2,0.12,0.01,0.02,0.3\n" for i in range(1000))
        peaks = {}
        for rows in (SHORT, LONG):
            csv = os.path.join(work, f"tiled_{rows}.csv")
            tile_csv(source, rows, csv)
            mb, _ = measure([sys.executable, "-c", "import sys; rows = open(sys.argv[1]).readlines()", csv])
            peaks.setdefault("whole-file reader", []).append(mb)
        peaks = {k: tuple(v) for k, v in peaks.items()}
        if not check(peaks):
            failures.append(f"a child reading the whole file was not flagged: {peaks}")
    for f in failures:
        print("self-test:", f)
    print("self-test:", "failed" if failures else "passed")
    return 1 if failures else 0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rcm", help="the rcm program")
    ap.add_argument("--session", help="session.json of a simulated session (its first trial is tiled)")
    ap.add_argument("--model", help="free-space model for force and dynamics eval")
    ap.add_argument("--work", help="directory for the tiled recordings (default: a temporary one, removed)")
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    if not (args.rcm and args.session and args.model):
        ap.error("--rcm, --session and --model are required")
    work = args.work or tempfile.mkdtemp(prefix="rcm_test_stream_memory_")
    os.makedirs(work, exist_ok=True)
    try:
        out = os.path.join(work, "out")
        os.makedirs(out, exist_ok=True)
        source = first_trial(args.session)
        peaks = {}
        for rows in (SHORT, LONG):
            csv, bag = tiled(args.rcm, source, rows, work)
            for label, cmd in commands(args.rcm, args.session, args.model, csv, bag, out):
                mb, _ = measure(cmd)
                peaks.setdefault(label, []).append(mb)
        peaks = {k: tuple(v) for k, v in peaks.items()}
    finally:
        if not args.work:
            shutil.rmtree(work, ignore_errors=True)
    for label, (short, long) in peaks.items():
        print(f"{label}: {short:.1f} MB at {SHORT} rows, {long:.1f} MB at {LONG} rows")
    problems = check(peaks)
    for p in problems:
        print("FAIL:", p)
    print("failed" if problems else "passed")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
