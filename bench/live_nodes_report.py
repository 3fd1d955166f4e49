#!/usr/bin/python3
"""The live nodes' per-sample timings, from their end-to-end tests.

Runs the end-to-end test of each live node through ctest (the fixture that
simulates the test session comes with it):

- `MonitorNode.EndToEndAgreesWithRcmMonitor`: `rcm_monitor_node` (ROS 1), the
  simulated trial published at full speed through a private rosmaster;
- `DdsMonitorNode.EndToEndAgreesWithRcmMonitor`: `rcm_monitor_dds`, the same
  trial published at 1.5 kHz over Cyclone DDS on the loopback interface;

RUNS times each, and reads the lines the nodes print at exit, which the tests
echo ("[ node log ] ..."):

    rcm: per sample: model + estimator X us mean, Y us max; whole callback with publishing Z us mean, W us max
    rcm: publishing (own thread): X us mean, Y us max per estimate (4 writes); queue depth max N of M, K outputs dropped

and writes a table of them, with the date, machine and load average, between
the live-nodes markers of docs/benchmarks.md. A node whose test is not built
(no ROS 1 or no Cyclone DDS) gets a row saying so; a failing test stops the
script before anything is written. `make bench` runs it after the benchmarks
(bench/run_benchmarks.py).

Run with Debian's Python: /usr/bin/python3 bench/live_nodes_report.py --build build [--runs 3]
"""
import argparse
import datetime
import os
import re
import subprocess
import sys

from doc_tables import cpu_model, publish_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
MARKERS = ("<!-- live-nodes:begin -->", "<!-- live-nodes:end -->")
SAMPLE_PERIOD_US = 1e6 / 1500.0  # the dVRK's fastest joint-state rate

# (node, how the test publishes, ctest name, where the node publishes when it prints no line of its own)
NODES = [
    ("`rcm_monitor_node` (ROS 1)", "unpaced publisher", "MonitorNode.EndToEndAgreesWithRcmMonitor",
     "Queued in the callback. The roscpp thread writes."),
    ("`rcm_monitor_dds` (DDS)", "publisher paced at 1.5 kHz", "DdsMonitorNode.EndToEndAgreesWithRcmMonitor", ""),
]

NUM = r"([0-9.]+)"
PER_SAMPLE = re.compile(r"rcm: per sample: model \+ estimator " + NUM + r" us mean, " + NUM +
                        r" us max; whole callback with publishing " + NUM + r" us mean, " + NUM + r" us max")
PUBLISHING = re.compile(r"rcm: publishing \(own thread\): " + NUM + r" us mean, " + NUM +
                        r" us max per estimate \(4 writes\); queue depth max ([0-9]+) of ([0-9]+), ([0-9]+) outputs dropped")
ACCEPTED = re.compile(r"rcm: ([0-9]+) samples accepted, ([0-9]+) rejected")


def listed(build, name):
    """Whether ctest knows the test `name` in `build`."""
    proc = subprocess.run(["ctest", "--test-dir", build, "-N", "-R", "^" + re.escape(name) + "$"],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return proc.returncode == 0 and re.search(r"Total Tests: [1-9]", proc.stdout) is not None


def run_test(build, name):
    """One run of the test; the figures its node printed at exit."""
    cmd = ["ctest", "--test-dir", build, "-R", "^" + re.escape(name) + "$", "--output-on-failure", "-V"]
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout)
        sys.exit(f"{name} failed (ctest exit {proc.returncode}); nothing written")
    m = PER_SAMPLE.search(proc.stdout)
    if not m:
        sys.stderr.write(proc.stdout)
        sys.exit(f"{name}: no 'rcm: per sample:' line in the test's output")
    run = {"step_mean": float(m[1]), "step_max": float(m[2]), "callback_mean": float(m[3]),
           "callback_max": float(m[4])}
    p = PUBLISHING.search(proc.stdout)
    if p:
        run.update(publish_mean=float(p[1]), publish_max=float(p[2]), depth=int(p[3]), capacity=int(p[4]),
                   dropped=int(p[5]))
    a = ACCEPTED.search(proc.stdout)
    if a:
        run["accepted"] = int(a[1])
    print(f"  {name}: " + ", ".join(f"{k} {v}" for k, v in run.items()), file=sys.stderr, flush=True)
    return run


def span(runs, key, fmt):
    """'a' or 'a-b' over the runs (min-max)."""
    values = [r[key] for r in runs if key in r]
    if not values:
        return None
    lo, hi = min(values), max(values)
    return fmt.format(lo) if fmt.format(lo) == fmt.format(hi) else fmt.format(lo) + "-" + fmt.format(hi)


def row(node, publisher, publishes, runs):
    if runs is None:
        return f"| {node} | not built | | | | |"
    samples = span(runs, "accepted", "{:d}") or "?"
    step = f"{span(runs, 'step_mean', '{:.1f}')} us mean, {span(runs, 'step_max', '{:.0f}')} us max"
    callback = f"{span(runs, 'callback_mean', '{:.1f}')} us mean, {span(runs, 'callback_max', '{:.0f}')} us max"
    share = span([{"s": 100.0 * r["callback_mean"] / SAMPLE_PERIOD_US} for r in runs], "s", "{:.1f}") + " %"
    if any("publish_mean" in r for r in runs):
        # Short sentences: the row's cells before this one are the first's words.
        publishing = (f"Sent from its own thread. Per estimate (4 writes): {span(runs, 'publish_mean', '{:.0f}')} "
                      f"us mean, {span(runs, 'publish_max', '{:.0f}')} us max. Queue depth at most "
                      f"{max(r['depth'] for r in runs)} of {runs[0]['capacity']}; "
                      f"{sum(r['dropped'] for r in runs)} outputs dropped.")
    else:
        publishing = publishes
    return f"| {node}, {publisher} | {samples} | {step} | {callback} | {share} | {publishing} |"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default="build")
    ap.add_argument("--runs", type=int, default=3, help="runs of each test (default 3)")
    ap.add_argument("--no-doc", action="store_true", help="print the table only")
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    load_start = os.getloadavg()[0]
    results = []
    for node, publisher, name, publishes in NODES:
        if not listed(build, name):
            print(f"{name}: not in {build}'s tests (node not built); its row says so", file=sys.stderr)
            results.append((node, publisher, publishes, None))
            continue
        results.append((node, publisher, publishes, [run_test(build, name) for _ in range(args.runs)]))
    if all(r is None for _, _, _, r in results):
        sys.exit(f"{build}: neither node's end-to-end test is built; nothing written")
    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    # Both tests are named <suite>.<test>, one name across the suites: one ctest pattern.
    pattern = "|".join(sorted({n.split(".", 1)[1] for _, _, n, _ in NODES}))
    over = "one run" if args.runs == 1 else f"the range over {args.runs} runs"
    lines = [
        f"Measured by `bench/live_nodes_report.py --runs {args.runs}` on {when}, {os.cpu_count()} cores of "
        f"{cpu_model()}, load average {load_start:.1f} at the start and {os.getloadavg()[0]:.1f} at the end. "
        f"The other core may be busy. Each node's end-to-end test (`ctest -R {pattern}`) streams the simulated "
        "trial through the node, with bad messages among the samples. The "
        "figures are what the node prints at exit (`rcm: per sample:` and `rcm: publishing (own thread):`), "
        f"{over}. Model: linear, 3 joints.", "",
        "| node, publisher | samples accepted | model + estimator | whole callback (with the correction and the "
        "publishing or its queueing) | callback mean, share of a 1.5 kHz sample (667 us) | publishing |",
        "|---|---|---|---|---|---|",
    ]
    lines += [row(*r) for r in results]
    publish_block(DOC, *MARKERS, "\n".join(lines), write=not args.no_doc)


if __name__ == "__main__":
    main()
