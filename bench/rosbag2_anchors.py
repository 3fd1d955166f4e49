#!/usr/bin/python3
"""Anchors for rcm's rosbag2 reading speed: other tools on the same file.

`bench_rosbag2_read` writes its recordings into RCM_BENCH_ROSBAG2_DIR when that
is set (and keeps them); `make bench` (bench/run_benchmarks.py) sets it and then
calls this on the SQLite file, jazzy.db3:

- the `sqlite3` command line selecting every message in rcm's order
  (`ORDER BY timestamp, id`) with a count and the sum of the payloads' lengths:
  what reading the storage alone costs;
- `zstd -d -c` to /dev/null of every payload of the file, concatenated and
  compressed alone at level 3: what decompressing the data alone costs.

Each is timed REPEAT times (wall clock, median). A tool that is not installed
(Debian: sqlite3, zstd) gets a row saying so. The table goes between the
rosbag2-anchors markers of docs/benchmarks.md.

Run with Debian's Python: /usr/bin/python3 bench/rosbag2_anchors.py --dir DIR [--no-doc]
"""
import argparse
import datetime
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import time

from doc_tables import cpu_model, publish_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
MARKERS = ("<!-- rosbag2-anchors:begin -->", "<!-- rosbag2-anchors:end -->")
QUERY = "SELECT count(*), sum(length(data)) FROM (SELECT data FROM messages ORDER BY timestamp, id);"


def timed(cmd, repeat, **kw):
    """Median wall time of `cmd` over `repeat` runs, and its last output."""
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    seconds, out = [], None
    stdout = kw.pop("stdout", subprocess.PIPE)
    for _ in range(repeat):
        start = time.monotonic()
        out = subprocess.run(cmd, check=True, stdout=stdout, **kw).stdout
        seconds.append(time.monotonic() - start)
    return statistics.median(seconds), out


def measure(bag_dir, repeat=3):
    """The anchors' table for the files in `bag_dir`."""
    db3 = os.path.join(bag_dir, "jazzy.db3")
    if not os.path.exists(db3):
        sys.exit(f"{db3}: missing (run bench_rosbag2_read with RCM_BENCH_ROSBAG2_DIR={bag_dir})")
    rows = []
    if shutil.which("sqlite3"):
        seconds, out = timed(["sqlite3", db3, QUERY], repeat)
        count, size = (int(x) for x in out.decode().strip().split("|"))
        rows.append(f"| `sqlite3 jazzy.db3 \"{QUERY}\"` | {os.path.getsize(db3) / 1e6:.0f} MB file, {count} "
                    f"messages, {size / 1e6:.0f} MB of payloads | {seconds:.2f} s |")
    else:
        rows.append("| `sqlite3` (every message in rcm's order) | not installed (Debian: sqlite3) | |")
    if shutil.which("zstd"):
        payloads = os.path.join(bag_dir, "payloads.bin")
        with sqlite3.connect(db3) as db, open(payloads, "wb") as f:
            for (data,) in db.execute("SELECT data FROM messages ORDER BY timestamp, id"):
                f.write(data)
        raw = os.path.getsize(payloads)
        subprocess.run(["zstd", "-3", "-q", "-f", payloads, "-o", payloads + ".zst"], check=True)
        packed = os.path.getsize(payloads + ".zst")
        seconds, _ = timed(["zstd", "-d", "-c", payloads + ".zst"], repeat, stdout=subprocess.DEVNULL)
        os.remove(payloads)
        os.remove(payloads + ".zst")
        rows.append(f"| `zstd -d -c` of the payloads compressed alone (level 3) to /dev/null | {raw / 1e6:.0f} MB, "
                    f"{packed / 1e6:.0f} MB compressed | {seconds:.2f} s |")
    else:
        rows.append("| `zstd -d -c` of the payloads compressed alone | not installed (Debian: zstd) | |")
    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    lines = [f"Measured by `bench/rosbag2_anchors.py` (`make bench`) on {when}, {os.cpu_count()} cores of "
             f"{cpu_model()}, load average {os.getloadavg()[0]:.1f} at the end; wall clock, median of {repeat}, "
             "on the files `bench_rosbag2_read` read.", "",
             "| tool | input | wall |", "|---|---|---|"] + rows
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dir", required=True, help="where bench_rosbag2_read wrote its files (RCM_BENCH_ROSBAG2_DIR)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-doc", action="store_true", help="print the table only")
    args = ap.parse_args()
    publish_block(DOC, *MARKERS, measure(args.dir, args.repeat), write=not args.no_doc)


if __name__ == "__main__":
    main()
