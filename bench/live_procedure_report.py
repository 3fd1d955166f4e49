#!/usr/bin/python3
"""The procedure on the robot's own interfaces, measured: for each seed, the
simulated PSM (rcm_sim_psm_dds) and the whole procedure (rcm_procedure_dds:
excitation, baseline, calibration, rcm setup, the live estimate's check, then
the large step with the loop closed across processes) over loopback DDS; beside
it, the in-process closed-loop bench on the same seed (`rcm simulate
--experiment closed-loop`). Also the simulator's cost: its step (bench_sim,
BM_SimulatedPsmStep) and the CPU the program takes at 1.5 kHz in real time.

Writes the block `live-procedure` of docs/validation.md and `simulated-psm` of
docs/benchmarks.md, with the date and machine:

    /usr/bin/python3 bench/live_procedure_report.py --build build [--seeds 1,2,3,4,5,6,7,8]
        [--rate 1500] [--time-scale 2] [--keep DIR] [--no-doc]
"""
import argparse
import datetime
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import cpu_model, write_block  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VALIDATION = os.path.join(ROOT, "docs", "validation.md")
BENCHMARKS = os.path.join(ROOT, "docs", "benchmarks.md")


def env_for(domain):
    return dict(os.environ, ROS_DOMAIN_ID=str(domain),
                CYCLONEDDS_URI="file://" + os.path.join(ROOT, "dds", "cyclonedds-lo.xml"))


def start_sim(bindir, args, log, env):
    return subprocess.Popen([os.path.join(bindir, "rcm_sim_psm_dds")] + args, stdout=log, stderr=subprocess.STDOUT,
                            env=env)


def stop(p):
    p.send_signal(signal.SIGINT)
    try:
        p.wait(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()


def one_procedure(bindir, seed, work, args, setup=None):
    """The procedure against the simulator. `setup`: (session, model) made before: the live phase only."""
    out = os.path.join(work, f"seed{seed}" + ("_live" if setup else ""))
    os.makedirs(out, exist_ok=True)
    env = env_for(200 + seed)
    start = time.monotonic()
    with open(os.path.join(out, "sim.log"), "w") as log:
        sim = start_sim(bindir, ["--rate", f"{args.rate:g}", "--time-scale", f"{args.time_scale:g}", "--teleop",
                                 "--software-rcm", "--seed", str(seed)], log, env)
        try:
            # A shared machine can keep the simulator off the CPU for a second:
            # the player waits 5 s for measured_js rather than 1.
            cmd = [os.path.join(bindir, "rcm_procedure_dds"), "--simulator", "--power", "--out", out, "--software-rcm",
                   "--incision-motion", "large_step", "--seed", str(seed), "--measured-timeout-s", "5"]
            if setup:
                cmd += ["--session", setup[0], "--model-file", setup[1]]
            with open(os.path.join(out, "procedure.log"), "w") as plog:
                code = subprocess.call(cmd, stdout=plog, stderr=subprocess.STDOUT, env=env)
        finally:
            stop(sim)
    with open(os.path.join(out, "procedure.json")) as f:
        j = json.load(f)
    j["exit"] = code
    # The simulator's own count of the servo stream against its periods.
    with open(os.path.join(out, "sim.log")) as f:
        log = f.read()
    held = re.search(r"(\d+) periods held between two \(no new setpoint; the longest run (\d+)\), (\d+) replaced", log)
    taken = re.search(r"servo_jp (\d+),", log)
    if held and taken:
        j["servo_stream"] = {"servo_jp": int(taken.group(1)), "held": int(held.group(1)),
                             "longest_held": int(held.group(2)), "replaced": int(held.group(3))}
    j["report_wall_s"] = time.monotonic() - start
    print(f"seed {seed}{' (live phase)' if setup else ''}: procedure exited {code} in {j['report_wall_s']:.0f} s",
          file=sys.stderr, flush=True)
    return j


def one_bench(rcm, seed, work, rate):
    """The in-process bench on `seed`, its estimator reading the arm at `rate` as the processes do: its large
    step, closed, and the session and model it prepared."""
    out = os.path.join(work, f"bench{seed}")
    p = subprocess.run([rcm, "simulate", "--experiment", "closed-loop", "--seed", str(seed), "--out", out, "--json",
                        "--no-plot", "--stream-rate", f"{rate:g}"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, check=True)
    j = json.loads(p.stdout)
    return j["scenarios"]["large_step"]["closed"], (j["session"], j["free_space_model_file"])


def sim_cpu_share(bindir, work, seconds=10.0):
    """CPU of rcm_sim_psm_dds at 1.5 kHz in real time while a player streams to it and records it."""
    env = env_for(230)
    traj = os.path.join(work, "cpu_hold.csv")
    with open(os.path.join(work, "cpu_sim.log"), "w") as log:
        sim = start_sim(bindir, ["--rate", "1500"], log, env)
        try:
            player = subprocess.Popen([os.path.join(bindir, "rcm_play_dds"), "--hold", f"{seconds:g}", "--q0",
                                       "0,0,0.12", "--hold-rate", "1500", "--power", "--out", traj],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            time.sleep(3.0)  # discovery, enabling, homing
            with open(f"/proc/{sim.pid}/stat") as f:
                fields = f.read().split(")")[1].split()
            cpu0, wall0 = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK"), time.monotonic()
            player.wait(timeout=120)
            with open(f"/proc/{sim.pid}/stat") as f:
                fields = f.read().split(")")[1].split()
            cpu1, wall1 = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK"), time.monotonic()
        finally:
            stop(sim)
    return (cpu1 - cpu0) / (wall1 - wall0)


def step_cost(build):
    prog = os.path.join(build, "bin", "bench_sim")
    if not os.access(prog, os.X_OK):
        return None
    p = subprocess.run([prog, "--benchmark_filter=SimulatedPsm", "--benchmark_format=json"], stdout=subprocess.PIPE,
                       stderr=subprocess.DEVNULL, text=True, check=True)
    return {b["name"]: b for b in json.loads(p.stdout)["benchmarks"]}


def earlier_whole_procedure():
    """The whole procedure's section of the block in docs/validation.md, under the date it was measured on."""
    text = open(VALIDATION).read() if os.path.exists(VALIDATION) else ""
    block = text.split("<!-- live-procedure:begin -->", 1)[-1].split("<!-- live-procedure:end -->", 1)[0]
    if "| seed | `rcm setup`" not in block or " on 20" not in block:
        return ["The whole procedure from the excitation on: not run in this measurement (`--full-seeds`).", "", ""]
    # Its date: that of the block, or the one it already carries from a run before.
    date = block.split("(measured on 20" if "(measured on 20" in block else " on 20", 1)[1][:14]
    start = block.index("The whole procedure from the excitation on")
    section = block[start:].split(":\n", 1)[1].split("`rcm setup` ready on", 1)
    ready = "`rcm setup` ready on" + section[1].split(". ", 1)[0] + ". "
    return [f"The whole procedure from the excitation on (measured on 20{date}, an earlier build; this run "
            "measured the loop only):", "", *section[0].strip().splitlines(), "", ready]


def fmt_s(v):
    return "never" if v is None else f"{v:.1f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--seeds", default="1,2,3,4,5,6,7,8")
    ap.add_argument("--full-seeds", default="1,2,3,4,5", help="seeds of the whole procedure (the setup's verdict)")
    ap.add_argument("--rate", type=float, default=1500.0)
    ap.add_argument("--time-scale", type=float, default=2.0)
    ap.add_argument("--keep", help="keep every run's folder here")
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--from-json", help="write the tables from the report.json of an earlier run (its --keep folder)")
    ap.add_argument("--add-full-seeds", action="store_true",
                    help="with --from-json: run the whole procedure on the --full-seeds it lacks and keep them with it "
                         "(a new report.json in --keep)")
    args = ap.parse_args()
    bindir = os.path.join(args.build, "bin")
    work = args.keep or tempfile.mkdtemp(prefix="rcm_live_procedure_")
    os.makedirs(work, exist_ok=True)
    seeds = [int(s) for s in args.seeds.split(",")]
    full_seeds = [int(s) for s in args.full_seeds.split(",") if s]
    started = time.monotonic()
    if args.from_json:
        with open(args.from_json) as f:
            saved = json.load(f)
        # The runs' own rate and clock (a report.json without them: the command line's).
        args.rate, args.time_scale = saved.get("rate", args.rate), saved.get("time_scale", args.time_scale)
        runs = {int(k): v for k, v in saved["runs"].items()}
        live = {int(k): v for k, v in saved["live"].items()}
        bench = {int(k): v for k, v in saved["bench"].items()}
        cpu, steps = saved["sim_cpu_share"], saved.get("steps") or step_cost(args.build)
        seeds = [s for s in seeds if s in live]
        started -= saved.get("minutes", 0) * 60
        # With --add-full-seeds, the whole procedure on seeds the earlier run
        # did not cover, kept with its runs (the report's time is then both).
        added = [s for s in full_seeds if s not in runs] if args.add_full_seeds else []
        for s in added:
            runs[s] = one_procedure(bindir, s, work, args)
        full_seeds = [s for s in full_seeds if s in runs]
        if added:
            saved.update(runs=runs, minutes=(time.monotonic() - started) / 60, load=os.getloadavg()[0])
            args.from_json = os.path.join(work, "report.json")
            with open(args.from_json, "w") as f:
                json.dump(saved, f, indent=2)
    else:
        bench, live, runs = {}, {}, {}
        for s in seeds:
            bench[s], setup = one_bench(os.path.join(bindir, "rcm"), s, work, args.rate)
            live[s] = one_procedure(bindir, s, work, args, setup)
        for s in full_seeds:
            runs[s] = one_procedure(bindir, s, work, args)
        cpu = sim_cpu_share(bindir, work)
        steps = step_cost(args.build)
        with open(os.path.join(work, "report.json"), "w") as f:
            json.dump({"runs": runs, "live": live, "bench": bench, "sim_cpu_share": cpu, "steps": steps,
                       "minutes": (time.monotonic() - started) / 60, "load": os.getloadavg()[0],
                       "rate": args.rate, "time_scale": args.time_scale}, f, indent=2)

    # The run's own time: an earlier run's report.json was written when it ended.
    ended = os.path.getmtime(args.from_json) if args.from_json else time.time()
    stamp = datetime.datetime.fromtimestamp(ended).strftime("%Y-%m-%d %H:%M")
    load = saved.get("load", os.getloadavg()[0]) if args.from_json else os.getloadavg()[0]
    minutes = (time.monotonic() - started) / 60
    head = (f"Measured by `bench/live_procedure_report.py --seeds {','.join(map(str, seeds))} --full-seeds "
            f"{','.join(map(str, full_seeds)) or chr(39) * 2} --rate {args.rate:g} --time-scale {args.time_scale:g}` on {stamp}, "
            f"{cpu_model()}, {os.cpu_count()} cores. Load average {load:.1f} at the end, "
            f"{minutes:.0f} min in all. Each run: `rcm_sim_psm_dds --rate {args.rate:g} --time-scale {args.time_scale:g} --teleop --software-rcm` "
            f"and `rcm_procedure_dds --simulator --power "
            "--software-rcm --incision-motion large_step --measured-timeout-s 5` over loopback DDS, three processes "
            "(simulator, monitor, procedure).")
    rows = ["| seed | across processes: onset to < 2 N for good (s) / RMS after settling (N) / wrong moves / peak (N) "
            "| in process (the bench) | the check's live estimate error (mm) |",
            "|---|---|---|---|"]
    for s_ in seeds:
        loop, b = (live[s_].get("closed_loop") or {}), bench[s_]
        err = live[s_].get("estimate_error_m")
        rows.append(
            f"| {s_} | "
            + (f"{fmt_s(loop.get('time_to_below_2n_s'))} / {loop['rms_force_after_settle_n']:.2f} / "
               f"{loop['wrong_direction_moves']} / {loop['peak_force_n']:.1f}" if loop else "-")
            + f" | {fmt_s(b['time_to_below_2n_s'])} / {b['rms_force_after_settle_n']:.2f} / "
              f"{b['wrong_direction_moves']} / {b['peak_force_n']:.1f} | {'-' if err is None else f'{1e3 * err:.2f}'} |")

    def meets(r):
        t = r.get("time_to_below_2n_s")
        return t is not None and t <= 5.0

    loops = [live[s_]["closed_loop"] for s_ in seeds if live[s_].get("closed_loop")]
    benches = [bench[s_] for s_ in seeds]

    def summary(rs, what):
        if not rs:
            return f"{what}: no run."
        t = [r["time_to_below_2n_s"] for r in rs if r["time_to_below_2n_s"] is not None]
        return (f"{what}: force below 2 N for good within 5 s of the step on {sum(meets(r) for r in rs)} of "
                f"{len(rs)} seeds. RMS force after settling below 1 N on "
                f"{sum(r['rms_force_after_settle_n'] < 1.0 for r in rs)}; "
                f"{sum(r['wrong_direction_moves'] for r in rs)} wrong-direction moves in all. Median onset to below "
                f"2 N {statistics.median(t) if t else float('nan'):.1f} s, median RMS after settling "
                f"{statistics.median(r['rms_force_after_settle_n'] for r in rs):.2f} N.")

    full = ["| seed | `rcm setup` (the model's force error) | excitation: samples recorded / rows sent, pacing, RMS "
            "tracking error of yaw (mrad) | servo_jp replaced before a period used it | on its own setup: live "
            "estimate error (mm); loop: below 2 N (s) / RMS (N) / wrong moves |",
            "|---|---|---|---|---|"]
    for s_ in full_seeds:
        j = runs[s_]
        ex = (j.get("phases") or [{}])[0]
        setup = j.get("setup") or {}
        pacing = ex.get("pacing_error")
        rms = (ex.get("rms_tracking_error") or {}).get("outer_yaw")
        missing = ", ".join(m.split(":")[0] for m in setup.get("missing") or [])
        if setup:
            verdict = ("ready" if setup.get("ready") else f"not ready: {missing}") + f" ({setup['force_error_n']:.1f} N)"
        else:  # the procedure stopped before rcm setup: the phase that stopped it says why
            stopped = next((p for p in j.get("phases", []) if p.get("status") == "stopped"), {})
            verdict = f"not run: {stopped.get('name', 'a phase')} stopped ({stopped.get('message', '').split(':')[0]})"
        full.append(f"| {s_} | {verdict} | "
                    f"{ex.get('samples_recorded', '-')} / {ex.get('rows_sent', '-')}, "
                    f"{'-' if pacing is None else f'{100 * pacing:+.3f} %'}, "
                    f"{'-' if rms is None else f'{1e3 * rms:.2f}'} | "
                    + (f"{j['servo_stream']['replaced']} of {j['servo_stream']['servo_jp']} |"
                       if j.get("servo_stream") else "- |")
                    + (f" {1e3 * j['estimate_error_m']:.2f}; " if j.get("estimate_error_m") is not None else " -; ")
                    + (f"{fmt_s(j['closed_loop'].get('time_to_below_2n_s'))} / "
                       f"{j['closed_loop']['rms_force_after_settle_n']:.2f} / {j['closed_loop']['wrong_direction_moves']} |"
                       if j.get("closed_loop") else "- |"))
    ready = [s_ for s_ in full_seeds if (runs[s_].get("setup") or {}).get("ready")]
    phases = [p for j in list(runs.values()) + list(live.values()) for p in j.get("phases", [])]
    rate = args.rate
    lost = sum(abs(p["samples_recorded"] - (round(p["recorded_span_s"] * rate) + 1)) for p in phases
               if p["samples_recorded"])
    pacing = [abs(p["pacing_error"]) for p in phases if p.get("pacing_error") is not None and p.get("status") != "stopped"]
    whole = ["The whole procedure from the excitation on:", "", *full, "",
             f"`rcm setup` ready on {len(ready)} of {len(full_seeds)} seeds. "]
    if not full_seeds:
        # A run of the loop alone (--full-seeds ''): the whole procedure's
        # section of the block already written stays, under its own date.
        whole = earlier_whole_procedure()
    text = [head, "",
            "The loop on the large step runs on the in-process bench's session and model (`rcm_procedure_dds "
            f"--session --model-file`), the estimator reading measured_js at {rate:g} Hz in both. The two runs of a "
            "seed differ in the surgeon's draw and the sensors' noise.", "", *rows, "",
            summary(loops, "Across processes"), summary(benches, "In process (the bench)"), "",
            *whole[:-1],
            whole[-1] + f"The player, every phase of every run ({len(phases)} phases): the samples recorded and the arm's stamps' "
            f"span at {rate:g} Hz differ by {lost} in all."
            + (f" The largest pacing error of a phase played to its end is {100 * max(pacing):.4f} % of a file's "
           "duration." if pacing else "")]
    block = "\n".join(text)
    print(block)
    bench_lines = []
    if steps:
        bench_lines = [f"Measured by `bench/live_procedure_report.py` on {stamp}, {cpu_model()}. "
                       "The benchmark `bench_sim --benchmark_filter=SimulatedPsm` times one publishing period: a servo_jp taken, "
                       "the period's physics steps with the tissue engaged, the sample filled. Then `rcm_sim_psm_dds "
                       "--rate 1500` runs in real time while `rcm_play_dds` holds and records it (CPU "
                       "over wall time, from /proc).", "",
                       "| rate | physics steps per period | time per period | share of the period |",
                       "|---|---|---|---|"]
        scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}
        for name, b in sorted(steps.items(), key=lambda kv: int(kv[0].split("/")[1])):
            rate_hz = int(name.split("/")[1])
            share = b["real_time"] * scale[b["time_unit"]] * rate_hz
            bench_lines.append(f"| {rate_hz} Hz | {b['physics_steps']:.0f} | {b['real_time']:.2f} "
                               f"{b['time_unit']} | {100 * share:.2f} % |")
        bench_lines += ["", f"The program at 1.5 kHz in real time, publishing and taking commands over loopback DDS: "
                            f"{100 * cpu:.0f} % of one core (target: real time with a core to spare)."]
        print("\n".join(bench_lines))
    if not args.no_doc:
        if not os.path.exists(VALIDATION):
            with open(VALIDATION, "w") as f:
                f.write("# Validation\n")
        write_block(VALIDATION, "<!-- live-procedure:begin -->", "<!-- live-procedure:end -->", block)
        if bench_lines:
            write_block(BENCHMARKS, "<!-- simulated-psm:begin -->", "<!-- simulated-psm:end -->",
                        "\n".join(bench_lines))
        print(f"wrote {VALIDATION} and {BENCHMARKS}", file=sys.stderr)


if __name__ == "__main__":
    main()
