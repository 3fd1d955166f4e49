#!/usr/bin/python3
"""What each sanitizer flag costs on the estimator's kind of arithmetic
(bench/sanitizer/jet_kernel.cpp: ceres::Jet through small Eigen expressions)
and on the compile time of one of the library's Eigen-heavy files
(src/estimation/online.cpp), the reason for `make test-sanitize`'s flags;
prints the table (--doc writes it into docs/validation-reliability.md between its markers).

    /usr/bin/python3 bench/sanitizer_cost.py [--repeats 3]
"""
import argparse
import datetime
import os
import platform
import subprocess
import sys
import tempfile
import time

from doc_tables import cpu_model, run, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation-reliability.md")
BEGIN, END = "<!-- sanitizer-cost:begin -->", "<!-- sanitizer-cost:end -->"
BASE = ["-O2", "-DNDEBUG", "-std=c++17", "-I/usr/include/eigen3"]
VARIANTS = [
    ("uninstrumented", []),
    ("ASan + UBSan", ["-fsanitize=address,undefined", "-fno-sanitize-recover=all"]),
    ("ASan + UBSan, no use-after-scope",
     ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-sanitize-address-use-after-scope"]),
    ("ASan + UBSan, no use-after-scope, no null / alignment / pointer-overflow (make test-sanitize)",
     ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-sanitize-address-use-after-scope",
      "-fno-sanitize=null,alignment,pointer-overflow"]),
    ("ASan alone", ["-fsanitize=address"]),
    ("ASan alone, no use-after-scope", ["-fsanitize=address", "-fno-sanitize-address-use-after-scope"]),
    ("UBSan alone", ["-fsanitize=undefined", "-fno-sanitize-recover=all"]),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3, help="runs per build; the median is reported")
    ap.add_argument("--cxx", default="g++")
    ap.add_argument("--doc", action="store_true", help="also write the table into docs/validation-reliability.md")
    a = ap.parse_args()
    src = os.path.join(ROOT, "bench", "sanitizer", "jet_kernel.cpp")
    library_file = os.path.join(ROOT, "src", "estimation", "online.cpp")
    library_flags = ["-I" + os.path.join(ROOT, "include"), "-I" + os.path.join(ROOT, "src"), "-g1"]
    rows, results = [], set()
    with tempfile.TemporaryDirectory() as tmp:
        for name, flags in VARIANTS:
            exe = os.path.join(tmp, "kernel")
            run([a.cxx] + BASE + flags + [src, "-o", exe])
            t0 = time.monotonic()
            run([a.cxx] + BASE + library_flags + flags + ["-c", library_file, "-o", os.path.join(tmp, "online.o")])
            compile_s = time.monotonic() - t0
            times = []
            for _ in range(a.repeats):
                out = subprocess.run([exe], check=True, capture_output=True, text=True,
                                     env=dict(os.environ, ASAN_OPTIONS="detect_leaks=0")).stdout.split()
                times.append(float(out[0]))
                results.add(out[1])
            rows.append((name, sorted(times)[len(times) // 2], compile_s))
    if len(results) != 1:
        sys.exit(f"the builds disagree on the result: {sorted(results)}")
    plain = rows[0][1]
    compiler = subprocess.run([a.cxx, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    lines = [f"Measured {datetime.date.today().isoformat()} on {cpu_model()} ({os.cpu_count()} cores, "
             f"{platform.system()}), {compiler}, `-O2`; median of {a.repeats} runs of "
             "`bench/sanitizer/jet_kernel.cpp`, and one compile of `src/estimation/online.cpp` "
             "(`/usr/bin/python3 bench/sanitizer_cost.py`):", "",
             "| build | kernel run (s) | x uninstrumented | compile online.cpp (s) |", "|---|---|---|---|"]
    for name, t, compile_s in rows:
        lines.append(f"| {name} | {t:.2f} | {t / plain:.1f} | {compile_s:.1f} |")
    if a.doc:  # why the instrumented build's checks are what they are: printed, written on request
        write_block(DOC, BEGIN, END, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
