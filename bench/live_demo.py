#!/usr/bin/python3
"""`make live-demo`: docking to the first estimate on the robot's own interfaces,
against the simulated PSM, over loopback DDS, in a few minutes:

    rcm_sim_psm_dds --teleop --software-rcm --time-scale X   (the arm, on CRTK topics)
    rcm_procedure_dds --simulator --software-rcm             (excitation, baseline,
                      --incision-motion large_step            calibration, rcm setup,
                                                              the live estimate's check,
                                                              then the large step with the
                                                              loop closed across processes)

The procedure prints its progress (phase, time left, the running estimate); this
script ends with the table of what it measured and writes OUT/live_demo.json
(phases, setup.ready, estimate_error_m, closed_loop.*).

    /usr/bin/python3 bench/live_demo.py [--build build] [--out live-demo-out] [--seed 1]
                                        [--rate 1000] [--time-scale 2]
"""
import argparse
import json
import os
import signal
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def fmt(v, digits=2, scale=1.0, none="n/a"):
    return none if v is None else f"{scale * v:.{digits}f}"


def demo_json(procedure):
    """The keys live_demo.json promises, from procedure.json."""
    loop = procedure.get("closed_loop") or {}
    setup = procedure.get("setup") or {}
    return {
        "phases": [{k: p.get(k) for k in ("name", "status", "recording", "samples_recorded", "rows_sent",
                                          "file_duration_s", "sent_span_s", "pacing_error", "max_tracking_error",
                                          "rms_tracking_error", "rejected", "stalls", "paused_s", "wall_s")}
                   for p in procedure.get("phases", [])],
        "setup": {"ready": setup.get("ready"), "missing": setup.get("missing"),
                  "force_error_n": setup.get("force_error_n")},
        "estimate_error_m": procedure.get("estimate_error_m"),
        "estimate_m": (procedure.get("check") or {}).get("estimate_m"),
        "truth_m": (procedure.get("check") or {}).get("truth_m"),
        "closed_loop": {k: loop.get(k) for k in ("motion", "peak_force_n", "time_to_below_2n_s",
                                                 "rms_force_after_settle_n", "residual_misalignment_m", "moves",
                                                 "wrong_direction_moves")},
        "wall_s": procedure.get("wall_s"),
    }


def table(d):
    lines = ["", "| phase | status | samples recorded | rows sent | pacing (arm time vs file) | "
                 "largest tracking error, yaw / pitch / insertion (mrad, mrad, mm) |",
             "|---|---|---|---|---|---|"]
    for p in d["phases"]:
        err = p.get("max_tracking_error") or {}
        vals = " / ".join(f"{1e3 * err[j]:.2f}" if j in err else "-"
                          for j in ("outer_yaw", "outer_pitch", "outer_insertion"))
        pacing = "-" if p["pacing_error"] is None else f"{100 * p['pacing_error']:+.3f} %"
        if p.get("stalls"):
            pacing += f" ({p['stalls']} stalls, paused {1e3 * p['paused_s']:.0f} ms)"
        lines.append(f"| {p['name']} | {p['status']} | {p['samples_recorded']} | {p['rows_sent']} | {pacing} | "
                     f"{vals} |")
    s, loop = d["setup"], d["closed_loop"]
    lines += ["",
              ("rcm setup: not run (the procedure stopped before it)" if s.get("ready") is None and
               not s.get("missing") else
               f"rcm setup: {'READY' if s['ready'] else 'NOT READY'}"
               + (f" (the model's force error {s['force_error_n']:.2f} N)" if s.get("force_error_n") else "")
               + ("" if s["ready"] else "; missing: " + "; ".join(s.get("missing") or []))),
              f"live estimate against the simulator's truth: error {fmt(d['estimate_error_m'], 2, 1e3)} mm"
              + (f" (estimate {', '.join(f'{1e3 * v:.1f}' for v in d['estimate_m'])} mm, truth "
                 f"{', '.join(f'{1e3 * v:.1f}' for v in d['truth_m'])} mm)" if d.get("estimate_m") else ""),
              ""]
    if loop.get("motion") is None:
        lines.append("closed loop across processes: not run (the procedure stopped before it)")
    else:
        below = loop.get("time_to_below_2n_s")
        lines += [f"| closed loop across processes ({loop['motion']}) | |",
                  "|---|---|",
                  f"| peak force | {fmt(loop.get('peak_force_n'), 1)} N |",
                  f"| onset to force below 2 N for good | {'never' if below is None else f'{below:.1f} s'} |",
                  f"| RMS force after settling | {fmt(loop.get('rms_force_after_settle_n'))} N |",
                  f"| residual misalignment | {fmt(loop.get('residual_misalignment_m'), 1, 1e3)} mm |",
                  f"| moves / wrong-direction moves | {loop.get('moves')} / {loop.get('wrong_direction_moves')} |"]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default="live-demo-out")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rate", type=float, default=1000.0, help="the simulator's measured_js rate (Hz)")
    # At 3 the excitation's servo stream misses the arm's periods so often that
    # rcm setup finds the free-space model 8 N off (1.2 N at 2, on an idle
    # 2-core machine).
    ap.add_argument("--time-scale", type=float, default=2.0, help="the arm's clock against the wall")
    ap.add_argument("--domain", type=int, default=200 + os.getpid() % 30)
    args = ap.parse_args()
    bindir = os.path.join(args.build, "bin")
    for p in ("rcm", "rcm_sim_psm_dds", "rcm_procedure_dds", "rcm_monitor_dds"):
        if not os.access(os.path.join(bindir, p), os.X_OK):
            raise SystemExit(f"live-demo: {os.path.join(bindir, p)} is missing: build first (make build)")
    os.makedirs(args.out, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain),
               CYCLONEDDS_URI="file://" + os.path.join(ROOT, "dds", "cyclonedds-lo.xml"))
    start = time.monotonic()
    print(f"live-demo: the simulated PSM at {args.rate:g} Hz, its clock {args.time_scale:g} times the wall's; "
          f"loopback DDS, domain {args.domain}; output in {args.out}/", flush=True)
    with open(os.path.join(args.out, "sim.log"), "w") as sim_log:
        sim = subprocess.Popen([os.path.join(bindir, "rcm_sim_psm_dds"), "--rate", f"{args.rate:g}", "--time-scale",
                                f"{args.time_scale:g}", "--teleop", "--software-rcm", "--seed", str(args.seed)],
                               stdout=sim_log, stderr=subprocess.STDOUT, env=env)
        try:
            code = subprocess.call([os.path.join(bindir, "rcm_procedure_dds"), "--simulator", "--power", "--out",
                                    args.out, "--software-rcm", "--incision-motion", "large_step", "--check-s",
                                    "20", "--loop-s", "60", "--seed", str(args.seed)], env=env)
        finally:
            sim.send_signal(signal.SIGINT)
            try:
                sim.wait(timeout=20)
            except subprocess.TimeoutExpired:
                sim.kill()
    path = os.path.join(args.out, "procedure.json")
    if not os.path.exists(path):
        raise SystemExit(f"live-demo: the procedure exited {code} without procedure.json")
    with open(path) as f:
        d = demo_json(json.load(f))
    d["wall_s_with_simulator"] = time.monotonic() - start
    with open(os.path.join(args.out, "live_demo.json") + ".tmp", "w") as f:
        json.dump(d, f, indent=2)
    os.replace(os.path.join(args.out, "live_demo.json") + ".tmp", os.path.join(args.out, "live_demo.json"))
    print(table(d))
    print(f"\nlive-demo: {d['wall_s_with_simulator']:.0f} s of wall time; wrote {args.out}/live_demo.json", flush=True)
    sys.exit(code)


if __name__ == "__main__":
    main()
