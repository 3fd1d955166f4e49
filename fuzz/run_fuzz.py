#!/usr/bin/python3
"""Runs the libFuzzer targets of a fuzz build one after another and reports.

Each target fuzzes for --seconds on a scratch corpus outside the repository
(seeded from fuzz/corpus/<target>; what it finds is kept there, never written
back), with its dictionary, -timeout=1, -rss_limit_mb=512 and leak detection.
Prints a table of libFuzzer's final figures; with --doc, writes it into the
"## Fuzzing" section of that Markdown file between the fuzz-table markers.
Exit status 1 when any target found a crash, hang, leak or OOM (the input is
left under the scratch directory's artifacts/).
"""
import argparse
import datetime
import os
import platform
import re
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
# Longest input per target: a few times the seeds, so that mutations can grow
# them, small enough that every execution stays fast.
MAX_LEN = {
    "csv_recording": 4096, "csv_rostopic": 4096, "session": 2048, "torque_model": 32768,
    "tissue_law": 2048, "robot": 4096, "sim_config": 8192, "rosbag2_db3": 16384,
    "rosbag2_metadata": 2048, "mcap": 16384, "cdr": 1024, "ros_bag": 16384, "joint_trajectory": 4096,
}
# ASan keeps the allocation stack of every live and quarantined chunk in a
# depot that is never freed; yaml-cpp's recursive parser makes a new stack for
# nearly every input, so the depot alone took the metadata target past 512 MB
# in 90,000 executions (live heap 25 MB). Without allocation stacks its RSS
# stays at 385 MB over 185,000.
ASAN_OPTIONS = {"rosbag2_metadata": "malloc_context_size=0"}
BEGIN, END = "<!-- fuzz-table:begin -->", "<!-- fuzz-table:end -->"


def machine():
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{platform.machine()}, {cpu}, {os.cpu_count()} cores"


def run_target(build, name, seconds, scratch, extra):
    exe = os.path.join(build, "bin", "fuzz_" + name)
    corpus = os.path.join(scratch, "corpus", name)
    artifacts = os.path.join(scratch, "artifacts")
    os.makedirs(corpus, exist_ok=True)
    os.makedirs(artifacts, exist_ok=True)
    seeds = os.path.join(HERE, "corpus", name)
    largest = 0
    for f in os.listdir(seeds):
        src = os.path.join(seeds, f)
        largest = max(largest, os.path.getsize(src))
        shutil.copy(src, os.path.join(corpus, f))
    max_len = max(MAX_LEN.get(name, 4096), largest)
    cmd = [exe, corpus, f"-max_total_time={seconds}", f"-max_len={max_len}", "-timeout=1",
           "-rss_limit_mb=512", "-malloc_limit_mb=512", "-detect_leaks=1", "-print_final_stats=1",
           f"-artifact_prefix={artifacts}/{name}-"] + extra
    d = os.path.join(HERE, "dict", name + ".dict")
    if os.path.exists(d):
        cmd.append(f"-dict={d}")
    log_path = os.path.join(scratch, name + ".log")
    print("$ " + " ".join(cmd), flush=True)
    env = dict(os.environ)
    if name in ASAN_OPTIONS:
        env["ASAN_OPTIONS"] = ":".join(filter(None, [env.get("ASAN_OPTIONS"), ASAN_OPTIONS[name]]))
    with open(log_path, "w") as log:
        rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    text = open(log_path, errors="replace").read()
    stats = {k: int(v) for k, v in re.findall(r"^stat::(\w+):\s+(\d+)", text, re.M)}
    last = [l for l in text.splitlines() if re.match(r"#\d+\s", l)]
    status = last[-1] if last else ""
    def grab(key):
        m = re.search(key + r":\s*(\d+)", status)
        return int(m.group(1)) if m else None
    corp = re.search(r"corp:\s*(\d+)/(\S+)", status)
    crashes = sorted(f for f in os.listdir(artifacts) if f.startswith(name + "-"))
    return {
        "name": name, "rc": rc, "seconds": seconds, "max_len": max_len,
        "execs": stats.get("number_of_executed_units", 0), "exec_s": stats.get("average_exec_per_sec", 0),
        "cov": grab("cov"), "ft": grab("ft"), "corpus": f"{corp.group(1)} ({corp.group(2)})" if corp else "?",
        "rss": stats.get("peak_rss_mb", 0), "crashes": crashes, "log": log_path,
    }


HEADER = ("| target | run (UTC) | seconds | executions | exec/s | cov | ft | corpus (inputs, size) | peak RSS MB | result |\n"
          "|---|---|---|---|---|---|---|---|---|---|")


def row(r, when):
    result = "clean" if r["rc"] == 0 else "FAILED: " + (", ".join(r["crashes"]) or f"exit {r['rc']}")
    if r["rc"] == 0 and r["execs"] < 1_000_000:
        result += " (short of 10^6 executions)"
    return (f"| {r['name']} | {when} | {r['seconds']} | {r['execs']:,} | {r['exec_s']:,} | {r['cov']} | {r['ft']} | "
            f"{r['corpus']} | {r['rss']} | {result} |")


def table(rows, where):
    order = list(MAX_LEN)
    lines = sorted(rows.values(), key=lambda l: order.index(l.split("|")[1].strip())
                   if l.split("|")[1].strip() in order else len(order))
    return (f"Machine: {where}. Each target alone, with its dictionary, `-timeout=1 -rss_limit_mb=512 "
            f"-malloc_limit_mb=512 -detect_leaks=1`; cov and ft are libFuzzer's final coverage and feature counts.\n\n"
            + HEADER + "\n" + "\n".join(lines) + "\n")


def write_doc(path, new_rows, where):
    doc = open(path).read()
    if BEGIN not in doc or END not in doc:
        sys.exit(f"{path}: no {BEGIN} ... {END} markers")
    head, rest = doc.split(BEGIN, 1)
    old, tail = rest.split(END, 1)
    # Rows of targets not run this time stay, with their own run time.
    rows = {}
    for l in old.splitlines():
        cells = l.split("|")
        if l.startswith("| ") and len(cells) == 12 and cells[1].strip() != "target":
            rows[cells[1].strip()] = l
    rows.update(new_rows)
    open(path, "w").write(head + BEGIN + "\n" + table(rows, where) + END + tail)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", required=True, help="the RCM_FUZZ build directory")
    ap.add_argument("--seconds", type=int, default=60, help="per target")
    ap.add_argument("--scratch", default=os.path.join("/tmp", f"rcm-fuzz-{os.getuid()}"),
                    help="scratch corpora, logs and crash inputs (outside the repository)")
    ap.add_argument("--doc", help="Markdown file whose fuzz table to replace (docs/validation-reliability.md)")
    ap.add_argument("targets", nargs="*", help="targets to run (default: every fuzz_* in BUILD/bin)")
    ap.add_argument("--libfuzzer", nargs=argparse.REMAINDER, default=[], help="extra libFuzzer flags")
    args = ap.parse_args()
    names = args.targets or sorted(f[len("fuzz_"):] for f in os.listdir(os.path.join(args.build, "bin"))
                                   if f.startswith("fuzz_") and f[len("fuzz_"):] in MAX_LEN)
    if not names:
        sys.exit("no fuzz targets in " + os.path.join(args.build, "bin"))
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
    results = []
    for name in names:
        r = run_target(args.build, name, args.seconds, args.scratch, args.libfuzzer)
        results.append(r)
        print(f"{name}: {r['execs']:,} executions, {r['exec_s']:,}/s, cov {r['cov']}, ft {r['ft']}, "
              f"exit {r['rc']}" + (f", crash inputs: {r['crashes']} (log {r['log']})" if r["rc"] else ""), flush=True)
    new_rows = {r["name"]: row(r, when) for r in results}
    print(table(new_rows, machine()))
    if args.doc:
        write_doc(args.doc, new_rows, machine())
    return 1 if any(r["rc"] != 0 for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
