#!/usr/bin/python3
"""`make soak`: the long reliability runs, and their figures in docs/validation-reliability.md.

1. The live stream soak: simulates a quick session and fits a linear free-space
   model on it (as the live tests do), then runs tests/soak_live.cpp (ten million
   messages by default) once with the ROS 2 convention for zero stamps (invalid
   data) and once with ROS 1's -> the table between the soak markers.
2. The estimate's properties on random sessions (tests/test_estimate_properties,
   50 sessions of 4 trials) -> the line between the property markers.
Exits non-zero when a run breaks a rule (the tables are written all the same).

    /usr/bin/python3 bench/soak_report.py --build build [--messages 10000000] [--sessions 50] [--no-properties]
"""
import argparse
import datetime
import json
import os
import subprocess
import sys

from doc_tables import cpu_model, run, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation-reliability.md")
BEGIN, END = "<!-- soak:begin -->", "<!-- soak:end -->"
PROPERTY_BEGIN, PROPERTY_END = "<!-- properties:begin -->", "<!-- properties:end -->"
# Counters that are not rejections: messages taken, timelines followed, and
# messages the stamps say never came.
NOT_REJECTIONS = ("accepted", "retimed", "missing", "gaps")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--messages", type=int, default=10_000_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sessions", type=int, default=50)
    ap.add_argument("--trials", type=int, default=4)
    ap.add_argument("--no-properties", action="store_true", help="the stream soak only; its line left as it is")
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    rcm = os.path.join(build, "bin", "rcm")
    soak = os.path.join(build, "bin", "soak_live")
    work = os.path.join(build, "soak")
    session = os.path.join(work, "session")
    model = os.path.join(work, "model.json")
    if not os.path.exists(os.path.join(session, "session.json")):
        run([rcm, "simulate", "--quick", "--seed", "1", "--out", session], stdout=subprocess.DEVNULL)
    if not os.path.exists(model):
        run([rcm, "dynamics", "fit", "--model", "linear", "--out", model, os.path.join(session, "free_space.csv")],
            stdout=subprocess.DEVNULL)
    results, failed = [], False
    for name, flag in (("ROS 2 (zero stamp: invalid)", []), ("ROS 1 (zero stamp: receive time)", ["--ros1"])):
        out = os.path.join(work, f"soak{'_ros1' if flag else ''}.json")
        proc = subprocess.run([soak, "--session", os.path.join(session, "session.json"), "--model", model,
                               "--recording", os.path.join(session, "D30_r10_15.csv"), "--messages",
                               str(args.messages), "--seed", str(args.seed), "--json", out] + flag)
        failed |= proc.returncode != 0
        results.append((name, json.load(open(out))))

    lines = [f"Run {datetime.date.today().isoformat()} by `make soak` on {cpu_model()}, {os.cpu_count()} cores. "
             f"{args.messages:,} clean samples of a simulated trial (D = 30 mm, radial (10, 15) mm, 200 Hz, "
             "looped), linear free-space model; one fault every 12 s of sample time or more.", ""]
    # The recovery each fault is allowed: one window, a longer one after a silence.
    allowed = {f["kind"]: f["recovery_window_s"] for f in results[0][1]["faults"] if f["injected"]}
    usual = min(allowed.values())
    windows = f"{usual:.0f} s" + "".join(f" ({k}: {w:.0f} s)" for k, w in allowed.items() if w != usual)
    lines += ["| convention | messages | sample time | wall | messages/s per node | rejected | missing (gaps) | "
              f"retimed | counts as predicted | exceptions | unrecovered in {windows} | RSS after 1 min -> peak | "
              "passed |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in results:
        c, p = r["counters"], r["predicted"]
        rejected = sum(c[k] for k in c if k not in NOT_REJECTIONS)
        lines.append(
            f"| {name} | {r['messages']:,} | {r['sample_time_s'] / 3600:.1f} h | {r['wall_s']:.0f} s | "
            f"{r['messages'] / r['wall_s']:,.0f} | {rejected:,} | {c['missing']:,} ({c['gaps']:,}) | {c['retimed']} | "
            f"{'yes' if c == p and r['verdict_mismatches'] == 0 else 'NO'} | {r['exceptions']} | "
            f"{r['unrecovered']} | {r['rss_kb']['baseline']:,} -> {r['rss_kb']['peak_after']:,} kB | "
            f"{'yes' if r['passed'] else 'NO'} |")
    lines += ["", f"Per fault ({results[0][0]}):", "",
              "| fault | injected | samples affected | longest recovery (s) | largest deviation (mm) |",
              "|---|---|---|---|---|"]
    for f in results[0][1]["faults"]:
        lines.append(f"| {f['kind']} | {f['injected']:,} | {f['samples']:,} | {f['max_recovery_s']:.2f} | "
                     f"{1e3 * f['max_deviation_m']:.2f} |")
    write_block(DOC, BEGIN, END, "\n".join(lines))
    print(f"soak: table written to {DOC}", file=sys.stderr)
    if args.no_properties:
        sys.exit(1 if failed else 0)

    env = dict(os.environ, RCM_PROPERTY_SESSIONS=str(args.sessions), RCM_PROPERTY_TRIALS=str(args.trials))
    print("+ test_estimate_properties", file=sys.stderr, flush=True)
    proc = subprocess.run([os.path.join(build, "bin", "test_estimate_properties")], env=env, capture_output=True,
                          text=True)
    sys.stderr.write(proc.stdout[-2000:])
    failed |= proc.returncode != 0
    coverage = [l for l in proc.stdout.splitlines() if l.startswith("coverage of the 95 %")]
    summary = coverage[0] if coverage else "no coverage line: the test failed before its end (see its output)"
    write_block(DOC, PROPERTY_BEGIN, PROPERTY_END,
                f"Run {datetime.date.today().isoformat()} by `make soak` on {cpu_model()}, {os.cpu_count()} cores"
                f" ({'passed' if proc.returncode == 0 else 'FAILED'}): {summary}.")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
