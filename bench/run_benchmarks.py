#!/usr/bin/python3
"""`make bench`: run every benchmark and record the results in docs/benchmarks.md.

1. every bench/bench_* program (Google Benchmark, JSON output) -> the table
   between the gbench markers;
2. bench/torch_compare.py (PyTorch side by side with LibTorch and the Eigen
   kernel) when the LibTorch benchmarks were built;
3. the scipy cross-check of the coaxial solve on a simulated default session.

Run with Debian's Python: /usr/bin/python3 bench/run_benchmarks.py --build build
"""
import argparse
import datetime
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
BEGIN, END = "<!-- gbench:begin -->", "<!-- gbench:end -->"


def replace_block(text, begin, end, block):
    if begin in text:
        head, rest = text.split(begin, 1)
        return head + begin + "\n" + block + "\n" + end + rest.split(end, 1)[1]
    return text + f"\n{begin}\n{block}\n{end}\n"


def run(cmd, **kw):
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, check=True, **kw)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--skip-python", action="store_true")
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    bin_dir = os.path.join(build, "bin")
    programs = sorted(p for p in os.listdir(bin_dir) if p.startswith("bench_"))
    if not programs:
        sys.exit(f"{bin_dir}: no bench_* programs (configure with -DRCM_BUILD_BENCH=ON)")
    rows = []
    for prog in programs:
        out = os.path.join(build, f"{prog}.json")
        run([os.path.join(bin_dir, prog), "--benchmark_format=console", f"--benchmark_out={out}",
             "--benchmark_out_format=json"], stdout=sys.stderr)
        for b in json.load(open(out))["benchmarks"]:
            if b.get("run_type") == "aggregate":
                continue
            rows.append((prog, b["name"], b["real_time"], b["cpu_time"], b["time_unit"], b.get("iterations", 0)))
    load = os.getloadavg()
    lines = [f"Run {datetime.date.today().isoformat()} by `make bench` on {os.cpu_count()} cores, "
             f"load average {load[0]:.1f} at the end of the run.", "",
             "| program | benchmark | wall | CPU | iterations |", "|---|---|---|---|---|"]
    for prog, name, real, cpu, unit, it in rows:
        lines.append(f"| {prog} | `{name}` | {real:.4g} {unit} | {cpu:.4g} {unit} | {it} |")
    text = open(DOC).read()
    text = replace_block(text, BEGIN, END, "\n".join(lines))
    open(DOC, "w").write(text)

    if args.skip_python:
        return
    if any(p.startswith("bench_torch_") for p in programs):
        run(["/usr/bin/python3", os.path.join(ROOT, "bench", "torch_compare.py"), build, "--write", DOC])
    session_dir = os.path.join(build, "bench-session")
    if not os.path.exists(os.path.join(session_dir, "session.json")):
        run([os.path.join(bin_dir, "rcm"), "simulate", "--out", session_dir, "--no-truth", "--no-plot"],
            stdout=subprocess.DEVNULL)
    problems = os.path.join(build, "bench-problems")
    run([os.path.join(bin_dir, "rcm"), "run", os.path.join(session_dir, "session.json"), "--model", "linear",
         "--out", os.path.join(build, "bench-run"), "--export-problems", problems], stdout=subprocess.DEVNULL)
    run(["/usr/bin/python3", os.path.join(ROOT, "bench", "scipy_crosscheck.py"), problems, "--write", DOC])


if __name__ == "__main__":
    main()
