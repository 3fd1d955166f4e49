#!/usr/bin/python3
"""Learning curves of the free-space torque model on the simulated bench.

Per seed S, `rcm simulate --seed S` records one session (900 s of free space,
or the longest length asked, and its trials) and `rcm simulate --seed S+100
--quick --free-space-s 300` a hold-out free-space teleoperation no model is fitted on.
For each free-space length L (minutes) and each kind of free-space data:

  teleoperation  the first L minutes of the session's own free_space.csv;
  excitation     `rcm excite --duration 60 L --seed S`, a trajectory designed
                 for that length, recorded by `rcm simulate --seed S
                 --free-space-trajectory --quick` (only its free_space.csv is
                 kept);

`rcm dynamics fit` (the default kind, or each of --models) is fitted on it,
`rcm dynamics eval` scores it on the hold-out (torque RMSE and NRMSE per joint),
and `rcm run` estimates the session's trials with it (`--model-file`, joint
method), so that every model of a seed is judged on the same trials. The joint
method's bootstrap is turned off there: it sets the intervals, not the
estimate, and is most of the run's time.

The table (mean over the seeds and their range) and a figure go between the
learning-curve markers of docs/validation-free-space.md (with --doc) and into
docs/figures/learning_curve.png, with the date and machine (a run of network
kinds alone: the table only, between the learning-curve-networks markers); `--json FILE` keeps
every point. `--real DIR` adds a torque-only curve on real recordings: DIR holds
pairs NAME_full.csv / NAME_half.csv (one path at two speeds, one payload); the
model is fitted on the first L of one file and scored on the other, for the
lengths the file holds. Nothing of those files is copied.

  /usr/bin/python3 bench/learning_curve.py --build build [--seeds 1,2,3] [--models linear]
      [--data teleoperation,excitation] [--real DIR] [--json FILE] [--no-doc] [--quick]
      [--scheduler ADDR --keep SHARED_DIR | --workers N]

--quick: the first seed, lengths 0.5, 1 and 2 min, torque only, nothing written
to docs/; tests/test_learning_curve.py runs it with --data teleoperation.

Each seed's session, then each (seed, length, kind of data), is a task of
rcm.batch: side by side on a local cluster (--workers, default one per core; 0:
one after another in this process, without Dask) or on a Dask scheduler's
workers (--scheduler, with --keep a folder they all see; docs/howto-batch.md).
A task's figures do not depend on where it ran.
"""
import argparse
import datetime
import glob
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

from doc_tables import add_cluster_flags, cpu_model, open_runner, run, write_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation-free-space.md")
FIGURE = os.path.join(ROOT, "docs", "figures", "learning_curve.png")
# The linear curve's block; a run of network kinds alone (their fits take
# minutes each, so fewer seeds and lengths) goes to its own block.
BEGIN, END = "<!-- learning-curve:begin -->", "<!-- learning-curve:end -->"
NETWORK_BEGIN, NETWORK_END = "<!-- learning-curve-networks:begin -->", "<!-- learning-curve-networks:end -->"
JOINTS = ("yaw", "pitch", "insertion")
DATA_KINDS = ("teleoperation", "excitation")
NO_BOOTSTRAP = {"joint": {"bootstrap_replicates": 0, "calibration_bootstrap_replicates": 0}}
HOLDOUT_S = 300
# The comparison the curve is drawn for: this much excitation against this much
# teleoperation, and the largest ratio of their mean e that counts as met.
TARGET = {"excitation_min": 2.0, "teleoperation_min": 15.0, "ratio": 1.10}


def rcm_json(cmd):
    return json.loads(run(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True).stdout)


def write_head(src, dst, seconds):
    """The rows of `src` within its first `seconds` into `dst`, header kept;
    returns the span written (s)."""
    with open(src) as f, open(dst, "w") as g:
        header = f.readline()
        g.write(header)
        column = header.strip().split(",").index("time")
        t0 = t = None
        for line in f:
            t_row = float(line.split(",", column + 1)[column])
            t0 = t_row if t0 is None else t0
            if t_row - t0 >= seconds:
                break
            t = t_row
            g.write(line)
    return t - t0


def duration(path):
    with open(path) as f:
        column = f.readline().strip().split(",").index("time")
        rows = [line for line in f if line.strip()]
    return float(rows[-1].split(",")[column]) - float(rows[0].split(",")[column])


def fit_and_score(args, rcm, model_kind, train, test, model):
    cmd = [rcm, "dynamics", "fit", "--out", model, train, "--json"]
    if model_kind != "linear":
        cmd += ["--model", model_kind, "--max-minutes", str(args.max_minutes)]
    fit = rcm_json(cmd)
    ev = rcm_json([rcm, "dynamics", "eval", model, test, "--json"])
    # A network fit that ran into its wall-clock budget was still improving.
    budget = model_kind != "linear" and fit["seconds"] >= 0.98 * 60 * args.max_minutes
    return {"fit_s": fit["seconds"], "train_samples": fit["train_samples"], "budget_reached": budget,
            "epochs": fit.get("epochs", 0),
            "rmse": [j["rmse"] for j in ev["joints"]], "nrmse_percent": [j["nrmse_percent"] for j in ev["joints"]],
            "range": [j["range"] for j in ev["joints"]]}


def training_data(rcm, seed, minutes, kinds, session, work):
    """{(data kind, L): free-space CSV} for one seed."""
    data = {}
    for L in minutes:
        if "teleoperation" in kinds:
            data[("teleoperation", L)] = os.path.join(work, f"teleoperation_{L:g}min.csv")
            write_head(os.path.join(session, "free_space.csv"), data[("teleoperation", L)], 60 * L)
        if "excitation" not in kinds:
            continue
        traj = os.path.join(work, f"excitation_{L:g}min_trajectory.csv")
        run([rcm, "excite", "--duration", f"{60 * L:g}", "--seed", str(seed), "--out", traj],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        recorded = os.path.join(work, f"excitation_{L:g}min")
        # --quick shortens the trials only: the free space follows the file, and
        # it is the same recording whatever the trials' settings.
        run([rcm, "simulate", "--seed", str(seed), "--free-space-trajectory", traj, "--quick", "--no-truth",
             "--out", recorded], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        data[("excitation", L)] = recorded + ".csv"
        os.replace(os.path.join(recorded, "free_space.csv"), data[("excitation", L)])
        shutil.rmtree(recorded)  # its trials are the session's, which every model is run on
    return data


def prepare_seed(args, rcm, seed, work):
    """A seed's session and hold-out teleoperation (a task); returns the hold-out's effort noise."""
    session, holdout = os.path.join(work, "session"), os.path.join(work, "holdout")
    # The first minutes of a simulated teleoperation depend on its whole length,
    # so every run takes them from the same 900 s: --quick's points are the
    # full run's points of that seed.
    run([rcm, "simulate", "--seed", str(seed), "--free-space-s", f"{max(900, 60 * max(args.minutes)):g}",
         "--no-truth", "--out", session], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    run([rcm, "simulate", "--seed", str(seed + 100), "--quick", "--free-space-s", str(HOLDOUT_S), "--no-truth",
         "--out", holdout], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(os.path.join(work, "run_options.json"), "w") as f:
        json.dump(NO_BOOTSTRAP, f)
    with open(os.path.join(holdout, "sim_config.json")) as f:
        return json.load(f)["sensors"]["effort_noise"]


def bench_length(args, rcm, seed, data_kind, L, work, noise):
    """One kind and length of a seed's free-space data (a task, after prepare_seed): every model kind fitted on
    it, scored on the hold-out and, unless --quick, run on the session's trials; one point per model kind."""
    session, holdout = os.path.join(work, "session"), os.path.join(work, "holdout")
    train = training_data(rcm, seed, [L], [data_kind], session, work)[(data_kind, L)]
    points = []
    for model_kind in args.models:
        model = os.path.join(work, f"{model_kind}_{data_kind}_{L:g}min.json")
        p = {"seed": seed, "model": model_kind, "data": data_kind, "minutes": L, "train_s": duration(train),
             "effort_noise": noise, **fit_and_score(args, rcm, model_kind, train,
                                                    os.path.join(holdout, "free_space.csv"), model)}
        if not args.quick:
            s = rcm_json([rcm, "run", os.path.join(session, "session.json"), "--model-file", model, "--options",
                          os.path.join(work, "run_options.json"), "--out", model[:-5] + "_run", "--json"])["summary"]
            p["e_above_20mm_mm"] = 1e3 * s["error_D_above_20mm"]["mean_m"]
            p["e_up_to_20mm_mm"] = 1e3 * s["error_D_up_to_20mm"]["mean_m"]
        points.append(p)
    return points


def bench_seeds(args, rcm, seeds, work):
    """Every seed's points, in the order seed, model kind, length, data kind: each seed's session first, then
    every (seed, length, data kind) at once, through rcm.batch (--scheduler, --workers)."""
    folders = {seed: os.path.join(work, f"seed{seed}") for seed in seeds}
    for folder in folders.values():
        os.makedirs(folder, exist_ok=True)
    jobs = [(seed, data, L) for seed in seeds for L in args.minutes for data in DATA_KINDS if data in args.data]
    with open_runner(args.build, args.scheduler, args.workers) as run_all:
        noise = dict(zip(seeds, run_all(prepare_seed, [(args, rcm, seed, folders[seed]) for seed in seeds])))
        done = dict(zip(jobs, run_all(bench_length, [(args, rcm, seed, data, L, folders[seed], noise[seed])
                                                      for seed, data, L in jobs])))
    return [done[job][m] for seed in seeds for m in range(len(args.models)) for job in jobs if job[0] == seed]


def real_curve(args, rcm, work):
    """Torque only: fitted on the first L of one file of a pair, scored on the other."""
    out = []
    for full in sorted(glob.glob(os.path.join(args.real, "*_full.csv"))):
        half = full[:-len("_full.csv")] + "_half.csv"
        if not os.path.exists(half):
            continue
        name = os.path.basename(full)[:-len("_full.csv")]
        for split, train, test in (("half -> full", half, full), ("full -> half", full, half)):
            span = duration(train)
            for L in args.minutes:
                if 60 * L > 1.01 * span:  # the file holds L to within a sample or two
                    continue
                head = os.path.join(work, "real_head.csv")
                write_head(train, head, 60 * L)
                for model_kind in args.models:
                    out.append({"recording": name, "split": split, "model": model_kind, "minutes": L,
                                **fit_and_score(args, rcm, model_kind, head, test, os.path.join(work, "real.json"))})
    return out


def stats(values):
    return {"mean": sum(values) / len(values), "min": min(values), "max": max(values)}


def summarize(points, quick):
    groups = {}
    for p in points:
        groups.setdefault((p["model"], p["data"], p["minutes"]), []).append(p)
    out = []
    for (model, data, L), ps in groups.items():
        s = {"model": model, "data": data, "minutes": L, "seeds": [p["seed"] for p in ps],
             "fit_s": stats([p["fit_s"] for p in ps]),
             "budget_reached": any(p.get("budget_reached") for p in ps),
             "epochs": stats([p.get("epochs", 0) for p in ps]),
             "nrmse_percent": [stats([p["nrmse_percent"][j] for p in ps]) for j in range(3)],
             "rmse": [stats([p["rmse"][j] for p in ps]) for j in range(3)],
             # The NRMSE the effort sensor's noise alone gives on the hold-out.
             "noise_nrmse_percent": [stats([100 * p["effort_noise"][j] / p["range"][j] for p in ps])["mean"]
                                     for j in range(3)]}
        if not quick:
            s["e_above_20mm_mm"] = stats([p["e_above_20mm_mm"] for p in ps])
            s["e_up_to_20mm_mm"] = stats([p["e_up_to_20mm_mm"] for p in ps])
        out.append(s)
    return out


def largest_rise(points, model):
    """Per kind of data and joint: the largest rise (%) of one seed's held-out
    NRMSE from one length to the next longer one (negative: it never rose)."""
    out = {}
    for data in DATA_KINDS:
        rises = [[-math.inf] * 3]
        for seed in {p["seed"] for p in points}:
            ps = sorted((p for p in points if (p["model"], p["data"], p["seed"]) == (model, data, seed)),
                        key=lambda p: p["minutes"])
            rises += [[100 * (b["nrmse_percent"][j] / a["nrmse_percent"][j] - 1) for j in range(3)]
                      for a, b in zip(ps, ps[1:])]
        if len(rises) > 1:
            out[data] = [max(r[j] for r in rises) for j in range(3)]
    return out


def ratios(summary):
    """Per model kind: mean e of the target's excitation over the target's teleoperation."""
    out = {}
    for model in {s["model"] for s in summary}:
        pick = {(s["data"], s["minutes"]): s for s in summary if s["model"] == model}
        exc, tel = pick.get(("excitation", TARGET["excitation_min"])), pick.get(("teleoperation", TARGET["teleoperation_min"]))
        if exc and tel and "e_above_20mm_mm" in exc:
            r = {k: exc[k]["mean"] / tel[k]["mean"] for k in ("e_above_20mm_mm", "e_up_to_20mm_mm")}
            r["met"] = all(v <= TARGET["ratio"] for v in r.values())
            out[model] = r
    return out


def fit_note(s):
    """Epochs of a network fit, and whether it stopped at its budget."""
    if s["model"] == "linear":
        return ""
    return f" ({s['epochs']['mean']:.0f} epochs{', budget reached' if s['budget_reached'] else ''})"


def f3(values, digits=2):
    return " / ".join(f"{v:.{digits}f}" for v in values)


def table(summary, ratio, rise, real, args, header):
    lines = [header, ""]
    for model in args.models:
        rows = [s for s in summary if s["model"] == model]
        lines += ([""] if len(lines) > 2 else []) + [f"**{model}**: held-out NRMSE and RMSE on the hold-out teleoperation, mean e of the session's "
                  "trials (joint method); mean over the seeds, range in brackets.", "",
                  "| free space | data | NRMSE yaw / pitch / insertion (%) | NRMSE range over seeds (%) | "
                  "RMSE yaw / pitch (N m) / insertion (N) | mean e, D > 20 mm | mean e, D <= 20 mm | fit (s) |",
                  "|---|---|---|---|---|---|---|---|"]
        for s in sorted(rows, key=lambda s: (s["minutes"], DATA_KINDS.index(s["data"]))):
            n = s["nrmse_percent"]
            e = [f"{s[k]['mean']:.2f} mm ({s[k]['min']:.2f}-{s[k]['max']:.2f})" if k in s else ""
                 for k in ("e_above_20mm_mm", "e_up_to_20mm_mm")]
            lines.append(f"| {s['minutes']:g} min | {s['data']} | {f3([x['mean'] for x in n])} | "
                         f"{f3([x['min'] for x in n])} .. {f3([x['max'] for x in n])} | "
                         f"{f3([x['mean'] for x in s['rmse']], 3)} | {e[0]} | {e[1]} | {s['fit_s']['mean']:.1f}"
                         f"{fit_note(s)} |")
        lines.append(f"\nThe effort sensor's noise alone (the simulator's `sensors.effort_noise` over the hold-out's "
                     f"torque range): NRMSE {f3(rows[0]['noise_nrmse_percent'])} %.")
        if rise.get(model) and model == "linear":
            lines.append("\nLargest rise of one seed's held-out NRMSE from one length to the next, yaw / pitch / "
                         "insertion (the tolerance of tests/test_learning_curve.py rests on it): " +
                         "; ".join(f"{d} {' / '.join(f'{v:+.1f}' for v in r)} %" for d, r in rise[model].items()) + ".")
        if model in ratio:
            r = ratio[model]
            lines.append(f"\n**{TARGET['excitation_min']:g} min of excitation against {TARGET['teleoperation_min']:g} "
                         f"min of teleoperation**, mean e: {r['e_above_20mm_mm']:.2f} times for D > 20 mm, "
                         f"{r['e_up_to_20mm_mm']:.2f} times for D <= 20 mm (target: at most "
                         f"{TARGET['ratio']:.2f}): {'met' if r['met'] else 'not met'}.")
    if real:
        lines += ["", "**Real Classic PSM1** (`--real`: the public recordings of \"A real Classic PSM\", one "
                  "excitation path at full and half speed per payload): fitted on the first L of one recording, "
                  "scored on the other recording of the same payload and path.", "",
                  "| recording | fitted on -> scored on | model | first | NRMSE yaw / pitch / insertion (%) | "
                  "RMSE yaw / pitch (N m) / insertion (N) |", "|---|---|---|---|---|---|"]
        for p in real:
            lines.append(f"| {p['recording']} | {p['split']} | {p['model']} | {60 * p['minutes']:g} s | "
                         f"{f3(p['nrmse_percent'])} | {f3(p['rmse'], 3)} |")
    return "\n".join(lines)


def figure(summary, model, kinds, path, work):
    """NRMSE per joint and mean e against the length, seeds' range as bars."""
    files = {}
    for data in kinds:
        rows = sorted((s for s in summary if s["model"] == model and s["data"] == data), key=lambda s: s["minutes"])
        f = files[data] = os.path.join(work, f"curve_{data}.dat")
        with open(f, "w") as out:
            for s in rows:
                cols = [s["minutes"]]
                for x in s["nrmse_percent"] + [s["e_above_20mm_mm"], s["e_up_to_20mm_mm"]]:
                    cols += [x["mean"], x["min"], x["max"]]
                out.write(" ".join(f"{c:.6g}" for c in cols) + "\n")
    tmp = path + ".tmp.png"
    script = ["set terminal pngcairo size 1200,900 font ',10'", f"set output '{tmp}'", "set multiplot layout 2,2",
              "set grid", "set logscale x", "set xrange [0.4:19]", "set xtics (0.5, 1, 2, 5, 10, 15)", "set key top right font ',9'",
              "set xlabel 'free-space data (min)'"]
    styles = {"teleoperation": "lt 1 pt 7", "excitation": "lt 2 pt 5 dt 2"}
    noise = next(s["noise_nrmse_percent"] for s in summary if s["model"] == model)
    for j, name in enumerate(JOINTS):
        c = 2 + 3 * j
        script += [f"set title 'held-out NRMSE, {name}'", "set ylabel 'NRMSE (%)'",
                   "plot " + ", ".join(f"'{files[d]}' using 1:{c}:{c + 1}:{c + 2} with yerrorlines {styles[d]} "
                                       f"title '{d}'" for d in kinds) +
                   f", {noise[j]:.6g} with lines lt 0 lw 2 title 'effort noise alone'"]
    script += ["set title 'estimate error of the trials (joint method)'", "set ylabel 'mean e (mm)'",
               "set logscale y",
               "plot " + ", ".join(f"'{files[d]}' using 1:{c}:{c + 1}:{c + 2} with yerrorlines {styles[d]} "
                                   f"{'lw 2' if c == 11 else ''} title '{d}, D {'> 20' if c == 11 else '<= 20'} mm'"
                                   for d in kinds for c in (11, 14)),
               "unset multiplot"]
    run(["gnuplot"], input="\n".join(script), text=True)
    os.replace(tmp, path)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--rcm", help="the rcm program (default: BUILD/bin/rcm)")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--minutes", help="free-space lengths, min (default 0.5,1,2,5,10,15; --quick: 0.5,1,2)")
    ap.add_argument("--data", default=",".join(DATA_KINDS), help="kinds of free-space data: teleoperation, excitation")
    ap.add_argument("--models", default="linear",
                    help="comma-separated model kinds (linear, mlp, lstm, hybrid); a network's fit takes its budget")
    ap.add_argument("--max-minutes", type=float, default=10.0, help="wall-clock budget of each network fit")
    ap.add_argument("--real", help="a folder of real recordings, NAME_full.csv and NAME_half.csv pairs")
    ap.add_argument("--quick", action="store_true", help="the first seed, 0.5-2 min, torque only, no docs")
    ap.add_argument("--json", help="write every point to this file")
    ap.add_argument("--keep", help="keep the recordings and models in this directory (on a cluster: one every worker "
                                   "sees at the same path; the default, a temporary directory here, serves a local "
                                   "cluster only)")
    add_cluster_flags(ap)
    ap.add_argument("--no-doc", action="store_true", help="print the table only (the default; kept for scripts)")
    ap.add_argument("--doc", action="store_true",
                    help="also write the table and figure into docs/validation-free-space.md")
    args = ap.parse_args()
    rcm = os.path.abspath(args.rcm or os.path.join(args.build, "bin", "rcm"))
    seeds = [int(s) for s in args.seeds.split(",")][:1 if args.quick else None]
    args.minutes = [float(x) for x in (args.minutes or ("0.5,1,2" if args.quick else "0.5,1,2,5,10,15")).split(",")]
    args.models = args.models.split(",")
    args.data = args.data.split(",")
    for d in args.data:
        if d not in DATA_KINDS:
            ap.error(f"--data: unknown kind {d!r}: {', '.join(DATA_KINDS)}")
    start = time.monotonic()
    work = args.keep or tempfile.mkdtemp(prefix="rcm_learning_curve_")
    try:
        points = bench_seeds(args, rcm, seeds, work)
        real = real_curve(args, rcm, work) if args.real else []
        summary = summarize(points, args.quick)
        ratio = ratios(summary)
        rise = {model: largest_rise(points, model) for model in args.models}
        wall = time.monotonic() - start
        flags = [f"--seeds {','.join(map(str, seeds))}", f"--minutes {','.join(f'{L:g}' for L in args.minutes)}"]
        flags += [f"--data {','.join(args.data)}"] if tuple(args.data) != DATA_KINDS else []
        flags += [f"--models {','.join(args.models)}"] if args.models != ["linear"] else []
        flags += [f"--max-minutes {args.max_minutes:g}"] if args.models != ["linear"] else []
        flags += ["--real DIR"] if args.real else []
        header = (f"Measured by `bench/learning_curve.py {' '.join(flags)}` on {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}, "
                  f"{os.cpu_count()} cores of {cpu_model()}, load average {os.getloadavg()[0]:.1f} at the end, "
                  f"{wall / 60:.0f} min in all. Per seed S: the session of `rcm simulate --seed S`, its first L "
                  "minutes of free space (teleoperation) or `rcm excite --duration 60L --seed S` recorded by "
                  "`rcm simulate --seed S --free-space-trajectory --quick` (excitation); `rcm dynamics fit` "
                  f"({', '.join(args.models)}) on it, `rcm dynamics eval` on the {HOLDOUT_S} s free-space "
                  "teleoperation of `rcm simulate --seed S+100 --quick`, `rcm run` on the session's 10 trials with "
                  "the fitted model (`--model-file`; joint method; no bootstrap, which sets the intervals only).")
        block = table(summary, ratio, rise, real, args, header)
        print(block)
        for model, r in ratio.items():
            print(f"{model}: {TARGET['excitation_min']:g} min excitation / {TARGET['teleoperation_min']:g} min "
                  f"teleoperation, mean e: D > 20 mm {r['e_above_20mm_mm']:.3f}, D <= 20 mm "
                  f"{r['e_up_to_20mm_mm']:.3f} (target <= {TARGET['ratio']:.2f}: {'met' if r['met'] else 'not met'})",
                  file=sys.stderr)
        if args.json:
            with open(args.json, "w") as f:
                json.dump({"command": sys.argv, "seeds": seeds, "minutes": args.minutes, "models": args.models,
                           "machine": f"{os.cpu_count()} cores of {cpu_model()}", "wall_s": wall,
                           "points": points, "summary": summary, "ratio": ratio, "largest_rise_percent": rise,
                           "real": real}, f, indent=1)
        if args.doc and not (args.no_doc or args.quick):
            if "linear" in args.models:
                figure(summary, "linear", args.data, FIGURE, work)
                block += ("\n\n![held-out NRMSE and mean e against the length of free-space data, linear model]"
                          "(figures/learning_curve.png)")
            if "linear" in args.models:
                write_block(DOC, BEGIN, END, block)
            else:
                write_block(DOC, NETWORK_BEGIN, NETWORK_END, block)
            print(f"wrote {DOC}", file=sys.stderr)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
