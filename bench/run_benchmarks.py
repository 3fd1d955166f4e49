#!/usr/bin/python3
"""`make bench`: run every benchmark and record the results in docs/benchmarks.md.

1. every bench/bench_* program (Google Benchmark, JSON output) -> the table
   between the gbench markers, and from the same run the online path's share
   of a 1.5 kHz sample (online-share markers);
2. bench/rosbag2_anchors.py: the sqlite3 and zstd command-line tools on the
   file bench_rosbag2_read read (rosbag2-anchors markers);
3. bench/live_nodes_report.py: the live nodes' per-sample timings from their
   end-to-end tests (live-nodes markers);
4. bench/torch_compare.py (PyTorch side by side with LibTorch and the Eigen
   kernel) when the LibTorch benchmarks were built;
5. the scipy cross-check of the coaxial solve on a simulated default session.

Run with Debian's Python: /usr/bin/python3 bench/run_benchmarks.py --build build
`--tables-only` rewrites the derived tables (online-share) from the gbench
block already in the document, running nothing.
"""
import argparse
import datetime
import json
import os
import re
import shutil
import subprocess
import sys

from doc_tables import cpu_model

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
BEGIN, END = "<!-- gbench:begin -->", "<!-- gbench:end -->"
ONLINE = ("<!-- online-share:begin -->", "<!-- online-share:end -->")
SAMPLE_PERIOD_US = 1e6 / 1500.0  # the dVRK's fastest joint-state rate
# Per-sample targets of the online path (bench/bench_online.cpp).
ONLINE_TARGETS = {"BM_OnlineEstimatorUpdate": "<= 20 us"}
# Keys of a Google Benchmark JSON entry that are not user counters.
STANDARD_KEYS = {"name", "family_index", "per_family_instance_index", "run_name", "run_type", "repetitions",
                 "repetition_index", "threads", "iterations", "real_time", "cpu_time", "time_unit", "label",
                 "error_occurred", "error_message", "aggregate_name", "aggregate_unit"}
UNIT_NS = {"ns": 1.0, "us": 1e3, "ms": 1e6, "s": 1e9}
# Rows of the kernels' variants, a developer's view of the LSTM kernel and of
# LibTorch: run and printed, not written into the docs' table.
DETAIL_ROWS = re.compile(r"^BM_(LstmKernelStep|LibTorch|EigenLstm|LstmModelStep/direction:[03]/acceleration:[01]/dahl:0"
                         r"|LinearModelStepLiveZeroPhase/rate_hz:(100|200)/)")


def replace_block(text, begin, end, block):
    if begin in text:
        head, rest = text.split(begin, 1)
        return head + begin + "\n" + block + "\n" + end + rest.split(end, 1)[1]
    return text + f"\n{begin}\n{block}\n{end}\n"


def run(cmd, **kw):
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, check=True, **kw)


def counters_text(b):
    """A benchmark's user counters ("messages/s 1.7e+06, file_MB 297"), or ""."""
    return ", ".join(f"{k} {v:.4g}" for k, v in b.items()
                     if k not in STANDARD_KEYS and isinstance(v, (int, float)) and not isinstance(v, bool))


def gbench_rows(text):
    """The gbench block's date and rows (program, name, cpu in ns), read back from the document."""
    block = text.split(BEGIN, 1)[1].split(END, 1)[0]
    date = re.search(r"Run (\S+) by", block)
    rows = []
    for line in block.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 4 and cells[1].startswith("`"):
            value, unit = cells[3].split()
            rows.append((cells[0], cells[1].strip("`"), float(value) * UNIT_NS[unit]))
    return (date[1] if date else "?"), rows


def online_share_table(date, rows):
    """bench_online's CPU per sample against the 667 us of a 1.5 kHz sample."""
    lines = [f"From the `make bench` run of {date} (table above): `bench_online`'s CPU time per sample, and its share "
             f"of the {SAMPLE_PERIOD_US:.0f} us between two samples at 1.5 kHz (the dVRK's fastest rate).", "",
             "| benchmark | CPU per sample | share of a 1.5 kHz sample | target |", "|---|---|---|---|"]
    for prog, name, cpu_ns in rows:
        if prog != "bench_online":
            continue
        lines.append(f"| `{name}` | {cpu_ns / 1e3:.2f} us | {100.0 * cpu_ns / 1e3 / SAMPLE_PERIOD_US:.2f} % | "
                     f"{ONLINE_TARGETS.get(name, '')} |")
    return "\n".join(lines)


def write_derived_tables():
    text = open(DOC).read()
    date, rows = gbench_rows(text)
    if any(prog == "bench_online" for prog, _, _ in rows):
        text = replace_block(text, *ONLINE, online_share_table(date, rows))
    open(DOC, "w").write(text)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--skip-python", action="store_true")
    ap.add_argument("--skip-live", action="store_true", help="no live nodes' tests (bench/live_nodes_report.py)")
    ap.add_argument("--tables-only", action="store_true",
                    help="rewrite the derived tables from the gbench block in the document; run nothing")
    args = ap.parse_args()
    if args.tables_only:
        write_derived_tables()
        return
    build = os.path.abspath(args.build)
    bin_dir = os.path.join(build, "bin")
    programs = sorted(p for p in os.listdir(bin_dir) if p.startswith("bench_"))
    if not programs:
        sys.exit(f"{bin_dir}: no bench_* programs (configure with -DRCM_BUILD_BENCH=ON)")
    rows = []
    # bench_rosbag2_read keeps its files there for the anchors (removed after them).
    bag_dir = os.path.join(build, "bench-rosbag2")
    for prog in programs:
        out = os.path.join(build, f"{prog}.json")
        env = dict(os.environ, RCM_BENCH_ROSBAG2_DIR=bag_dir) if prog == "bench_rosbag2_read" else None
        run([os.path.join(bin_dir, prog), "--benchmark_format=console", f"--benchmark_out={out}",
             "--benchmark_out_format=json"], stdout=sys.stderr, env=env)
        for b in json.load(open(out))["benchmarks"]:
            if b.get("run_type") == "aggregate":
                continue
            rows.append((prog, b["name"], b["real_time"], b["cpu_time"], b["time_unit"], b.get("iterations", 0),
                         counters_text(b)))
    load = os.getloadavg()
    lines = [f"Run {datetime.date.today().isoformat()} by `make bench` on {os.cpu_count()} cores of {cpu_model()}, "
             f"load average {load[0]:.1f} at the end of the run.", "",
             "| program | benchmark | wall | CPU | counters |", "|---|---|---|---|---|"]
    for prog, name, real, cpu, unit, it, counters in rows:
        if not DETAIL_ROWS.match(name):
            lines.append(f"| {prog} | `{name}` | {real:.4g} {unit} | {cpu:.4g} {unit} | {counters} |")
    text = open(DOC).read()
    text = replace_block(text, BEGIN, END, "\n".join(lines))
    open(DOC, "w").write(text)
    write_derived_tables()

    if os.path.exists(os.path.join(bag_dir, "jazzy.db3")):
        run(["/usr/bin/python3", os.path.join(ROOT, "bench", "rosbag2_anchors.py"), "--dir", bag_dir])
    shutil.rmtree(bag_dir, ignore_errors=True)
    if not args.skip_live:
        run(["/usr/bin/python3", os.path.join(ROOT, "bench", "live_nodes_report.py"), "--build", build])

    if args.skip_python:
        return
    if any(p.startswith("bench_torch_") for p in programs):
        # Printed, not written into the docs: a cross-check of the trainers, not a figure users need.
        run(["/usr/bin/python3", os.path.join(ROOT, "bench", "torch_compare.py"), build])
    session_dir = os.path.join(build, "bench-session")
    if not os.path.exists(os.path.join(session_dir, "session.json")):
        run([os.path.join(bin_dir, "rcm"), "simulate", "--out", session_dir, "--no-truth", "--no-plot"],
            stdout=subprocess.DEVNULL)
    problems = os.path.join(build, "bench-problems")
    run([os.path.join(bin_dir, "rcm"), "run", os.path.join(session_dir, "session.json"), "--model", "linear",
         "--out", os.path.join(build, "bench-run"), "--export-problems", problems], stdout=subprocess.DEVNULL)
    # Printed, not written into the docs: it fails when the two solvers' optima differ.
    run(["/usr/bin/python3", os.path.join(ROOT, "bench", "scipy_crosscheck.py"), problems])


if __name__ == "__main__":
    main()
