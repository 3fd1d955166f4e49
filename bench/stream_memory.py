#!/usr/bin/python3
"""Peak memory and wall time of the commands that stream a recording, on
recordings of 1e5, 1e6 and 1e7 rows: does memory stay flat as the recording
grows, and does time grow linearly?

The recording is a simulated trial (`rcm simulate --quick`, which also gives
the session for `rcm monitor` and the free space for the model of `rcm force`
and `rcm dynamics eval`), or a recording CSV given with --recording (a real
one: its folder may be outside the project). It is tiled to each length: copy
k starts one median interval after copy k - 1 ends, so time keeps increasing.
Each length is written as CSV and, by `rcm convert`, as an MCAP file of the
same samples (`rcm convert` to CSV then reads the MCAP).

Each command runs as a child process; its peak resident memory is the
child's own maximum RSS (os.wait4), its time the wall clock. With --before
RCM, the same commands are measured with another rcm program (a build of an
earlier version) up to --before-max-rows.

    /usr/bin/python3 bench/stream_memory.py --build build [--recording FILE]
        [--rows 100000,1000000,10000000] [--before OTHER/bin/rcm] [--write]

With --write, the table goes into docs/benchmarks.md between the
stream-memory markers, and the chunked-read benchmark (bench_recording_read)
into the same page between the recording-read markers.
"""
import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from doc_tables import cpu_model, publish_block, run

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
MARKERS = ("<!-- stream-memory:begin -->", "<!-- stream-memory:end -->")
READ_MARKERS = ("<!-- recording-read:begin -->", "<!-- recording-read:end -->")


def measure(cmd, stdout=subprocess.DEVNULL):
    """Runs `cmd`; returns (peak RSS in MB, wall seconds). Fails on a non-zero exit.

    The disks first write back what is pending (the tiled input, the last command's output), so that a command is
    not charged for another's gigabytes; what it writes itself stays in its time."""
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    os.sync()
    start = time.monotonic()
    p = subprocess.Popen(cmd, stdout=stdout, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.monotonic() - start
    err = p.stderr.read().decode(errors="replace")
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        sys.exit(f"{cmd[0]} exited with {p.returncode}:\n{err}")
    return usage.ru_maxrss / 1024.0, wall  # ru_maxrss is in KiB on Linux


def measure_steady(cmd, short_s=5.0, repeats=3):
    """measure(), repeated when a run is short: the median time, the largest memory. A second's run moves by a
    tenth from one try to the next, and the ratio of two lengths with it."""
    runs = [measure(cmd)]
    if runs[0][1] < short_s:
        runs += [measure(cmd) for _ in range(repeats - 1)]
    return max(mb for mb, _ in runs), statistics.median(s for _, s in runs)


def rows_text(n):
    """1e5 for 100000; the number itself when it is not a power of ten."""
    text = f"{n:.0e}".replace("e+0", "e").replace("e+", "e")
    return text if float(text) == n else str(n)


def tile_csv(src, rows, dst):
    """Writes the first `rows` samples of `src` repeated end to end, time shifted."""
    with open(src) as f:
        header = f.readline()
        lines = [l for l in f if l.strip()]
    times = [float(l.split(",", 1)[0]) for l in lines]
    rests = [l.split(",", 1)[1] for l in lines]
    dts = sorted(b - a for a, b in zip(times, times[1:]))
    span = times[-1] - times[0] + dts[len(dts) // 2]
    with open(dst, "w") as out:
        out.write(header)
        n, copy = 0, 0
        while n < rows:
            shift = copy * span - times[0]
            take = min(len(lines), rows - n)
            out.writelines(f"{t + shift!r},{r}" for t, r in zip(times[:take], rests[:take]))
            n += take
            copy += 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default="build")
    ap.add_argument("--recording", help="recording CSV to tile (default: a simulated trial)")
    ap.add_argument("--rows", default="100000,1000000,10000000", help="lengths, comma separated")
    ap.add_argument("--before", help="another rcm program to measure the same way (e.g. an earlier build)")
    ap.add_argument("--before-max-rows", type=float, default=1e6,
                    help="longest recording the --before program is given (it may hold the whole recording)")
    ap.add_argument("--work", help="directory for the recordings (default: a temporary one, removed)")
    ap.add_argument("--write", action="store_true", help=f"write the tables into {os.path.relpath(DOC, ROOT)}")
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    rcm = os.path.join(build, "bin", "rcm")
    lengths = [int(float(x)) for x in args.rows.split(",")]
    work = args.work or tempfile.mkdtemp(prefix="rcm_stream_memory_")
    os.makedirs(work, exist_ok=True)
    shm = None
    try:
        session = os.path.join(work, "sim")
        if not os.path.exists(os.path.join(session, "session.json")):
            run([rcm, "simulate", "--quick", "--out", session, "--no-truth", "--no-plot"], stdout=subprocess.DEVNULL)
        manifest = json.load(open(os.path.join(session, "session.json")))
        source = args.recording or os.path.join(session, manifest["trials"][0]["recording"])
        free_space = manifest["free_space"]
        free_space = [os.path.join(session, f) for f in (free_space if isinstance(free_space, list) else [free_space])]
        model = os.path.join(work, "linear.json")
        if not os.path.exists(model):
            run([rcm, "dynamics", "fit", "--model", "linear", *free_space, "--out", model], stdout=subprocess.DEVNULL)
        session_json = os.path.join(session, "session.json")
        if os.access("/dev/shm", os.W_OK):
            shm = tempfile.mkdtemp(prefix="rcm_stream_memory_", dir="/dev/shm")

        def commands(prog, csv, bag, out):
            return [
                ("`inspect`", "CSV", [prog, "inspect", csv]),
                ("`inspect`", "MCAP", [prog, "inspect", bag]),
                ("`convert` to CSV", "MCAP", [prog, "convert", bag, os.path.join(out, "converted.csv")]),
                ("`force --out`", "CSV", [prog, "force", "--model", model, "--offset", "0.03", csv,
                                          "--out", os.path.join(out, "force.csv")]),
                ("`monitor --out`", "CSV", [prog, "monitor", "--session", session_json, csv, "--quiet",
                                            "--out", os.path.join(out, "monitor.csv")]),
                ("`monitor`", "MCAP", [prog, "monitor", "--session", session_json, bag, "--quiet"]),
                ("`dynamics eval`", "CSV", [prog, "dynamics", "eval", model, csv]),
            ] + ([
                # The two that write a CSV as long as their input, once more with the output on tmpfs: no disk
                # behind the page cache, so what their time owes to the kernel writing gigabytes back shows.
                ("`convert` to CSV, output on tmpfs", "MCAP", [prog, "convert", bag, os.path.join(shm, "converted.csv")]),
                ("`force --out`, output on tmpfs", "CSV", [prog, "force", "--model", model, "--offset", "0.03", csv,
                                                          "--out", os.path.join(shm, "force.csv")]),
            ] if shm else [])

        results = {}  # (command, input, rows) -> {"after": (mb, s), "before": (mb, s)}
        for rows in lengths:
            csv = os.path.join(work, f"tiled_{rows}.csv")
            bag = os.path.join(work, f"tiled_{rows}.mcap")
            tile_csv(source, rows, csv)
            run([rcm, "convert", csv, bag], stdout=subprocess.DEVNULL)
            out = os.path.join(work, "out")
            os.makedirs(out, exist_ok=True)
            for label, prog in [("after", rcm)] + ([("before", args.before)] if args.before else []):
                if label == "before" and rows > args.before_max_rows:
                    continue
                for name, kind, cmd in commands(prog, csv, bag, out):
                    results.setdefault((name, kind, rows), {})[label] = measure_steady(cmd)
            for f in (csv, bag):
                os.remove(f)

        load = os.getloadavg()[0]
        before_rows = [n for n in lengths if n <= args.before_max_rows] if args.before else []
        cell = lambda r: f"{r[0]:.0f} MB, {r[1]:.1f} s"
        head = ("| command | input | " + " | ".join(rows_text(n) + " rows" for n in lengths) +
                "".join(f" | before, {rows_text(n)}" for n in before_rows) + " |")
        lines = [f"`bench/stream_memory.py`, {datetime.datetime.now():%Y-%m-%d %H:%M}, {os.cpu_count()} cores of "
                 f"{cpu_model()}, load average {load:.1f} at the end. Peak resident memory and wall clock of each "
                 f"command on {'a given recording' if args.recording else 'a simulated trial'} tiled to each length, "
                 "each started once the disks had written back what was pending"
                 + ("; `before`: the version that loaded the whole recording" if before_rows else "") + ".",
                 "", head, "|---|---|" + "---|" * (len(lengths) + len(before_rows))]
        for name, kind in dict.fromkeys((n, k) for (n, k, _) in results):
            r = [results[(name, kind, n)] for n in lengths]
            lines.append(f"| {name} | {kind} | " + " | ".join(cell(x["after"]) for x in r) +
                         "".join(f" | {cell(results[(name, kind, n)]['before'])}" for n in before_rows) + " |")
        # What the table says, from its own numbers.
        first, last = lengths[0], lengths[-1]
        growth = [results[(n, k, last)]["after"][0] / results[(n, k, first)]["after"][0]
                  for (n, k) in dict.fromkeys((n, k) for (n, k, _) in results)]
        times = [results[(n, k, last)]["after"][1] / results[(n, k, lengths[-2])]["after"][1]
                 for (n, k) in dict.fromkeys((n, k) for (n, k, _) in results)] if len(lengths) > 1 else [1.0]
        lines += ["", f"From {rows_text(first)} to {rows_text(last)} rows peak memory changes by a factor of "
                  f"{min(growth):.2f} to {max(growth):.2f}; the last tenfold length takes {min(times):.1f} to "
                  f"{max(times):.1f} times as long (wall clock on a shared machine: compare within a column). "
                  "`force` and `monitor` include loading or fitting the model; the monitor's trace for the settling "
                  "time is on disk (32 bytes a sample)."]
        if shm and len(lengths) > 1:
            ratio = lambda name, kind: results[(name, kind, last)]["after"][1] / results[(name, kind, lengths[-2])]["after"][1]
            lines += ["", f"The last tenfold length, output on disk against on tmpfs (no disk behind the page cache): "
                      f"`convert` {ratio('`convert` to CSV', 'MCAP'):.1f} against "
                      f"{ratio('`convert` to CSV, output on tmpfs', 'MCAP'):.1f} times as long, `force --out` "
                      f"{ratio('`force --out`', 'CSV'):.1f} against {ratio('`force --out`, output on tmpfs', 'CSV'):.1f}. "
                      "Runs under 5 s are the median of three."]
        publish_block(DOC, *MARKERS, "\n".join(lines), write=args.write)

        # The chunked CSV read's throughput (Google Benchmark).
        bench = os.path.join(build, "bin", "bench_recording_read")
        if os.path.exists(bench):
            out_json = os.path.join(work, "bench_recording_read.json")
            run([bench, "--benchmark_format=console", f"--benchmark_out={out_json}", "--benchmark_out_format=json"],
                stdout=sys.stderr)
            rows = [f"`bench_recording_read`, {datetime.datetime.now():%Y-%m-%d %H:%M}: a CSV of 200 000 rows (7 "
                    "joints with force) read in chunks of 8192 rows, whole, and summarized as `rcm inspect` does.", "", "| benchmark | wall | CPU | rows/s |", "|---|---|---|---|"]
            for b in json.load(open(out_json))["benchmarks"]:
                name = b["name"].replace("/iterations:3/real_time", "")
                if name.endswith("/1024") or name.endswith("/65536"):
                    continue  # the chunk size barely matters: the default's row says it
                rows.append(f"| `{name}` | {b['real_time']:.0f} {b['time_unit']} | {b['cpu_time']:.0f} "
                            f"{b['time_unit']} | {b['rows/s']:.3g} |")
            publish_block(DOC, *READ_MARKERS, "\n".join(rows), write=args.write)
    finally:
        if shm:
            shutil.rmtree(shm, ignore_errors=True)
        if not args.work:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
