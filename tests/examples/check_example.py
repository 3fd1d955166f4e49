#!/usr/bin/env python3
"""Runs one example program (examples/) and checks what it computed.

    check_example.py KIND [options] -- COMMAND ...

The command must exit with status 0; then, by KIND:

  estimate-offset   every trial of the session that the command estimated
                    (lines "NAME [x, y, z] ...", mm) lies within --max-error-mm
                    of the truth in the session manifest, and every trial
                    named with --trial was estimated;
  incision-force    --out holds one finite force row per sample of the
                    session's calibration, and its RMSE against the
                    calibration's force columns, computed here, is below
                    --max-rmse-n on every axis;
  online-monitor    the "final estimate [x, y, z] mm" of --trial lies within
                    --max-error-mm of its truth, the estimate was printed as the
                    stream went, onset was reported, and the last advice is the
                    one the truth calls for: reposition beyond the corrector's
                    10 mm software limit, hold within its 1.5 mm tolerance;
  free-space-model  --out holds one prediction row per sample of --recording,
                    and the per-joint NRMSE against its effort over the last
                    10 % of the samples (the part a model fitted with rcm's
                    70/20/10 time split never saw), computed here, is below
                    --max-nrmse (percent, one per joint).

The truth and the reference data are read from the files, never from the
example's output. --out is deleted before the command runs, so a file left by
an earlier run cannot pass. `--self-test` feeds every check planted good and
bad outputs and fails unless each bad one is caught and each good one passes.
"""

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import tempfile

NUMBER = r"(-?\d+(?:\.\d+)?)"
TRIAL_LINE = re.compile(r"^(\S+)\s+\[" + NUMBER + r", " + NUMBER + r", " + NUMBER + r"\]")
FINAL_LINE = re.compile(r"^final estimate \[" + NUMBER + r", " + NUMBER + r", " + NUMBER + r"\] mm")
RUNNING_LINE = re.compile(r"^\s*\d+\.\d+ s\s+estimate \[")
ADVICE_LINE = re.compile(r"^\s*\d+\.\d+ s\s+advice: (\w+)")
ONSET_LINE = re.compile(r"^\s*\d+\.\d+ s\s+onset:")
# The corrector's defaults (CorrectionOptions): software shifts up to 10 mm,
# hold within 1.5 mm.
COMPENSATE_LIMIT_MM, TOLERANCE_MM = 10.0, 1.5


class CheckFailed(Exception):
    pass


def load_truths(manifest):
    with open(manifest) as f:
        session = json.load(f)
    truths = {}
    for trial in session.get("trials", []):
        truth = trial.get("truth", {}).get("misalignment_m")
        if truth is not None:
            truths[trial["name"]] = [1e3 * v for v in truth]
    return session, truths


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise CheckFailed(f"{path}: empty")
    return rows[0], rows[1:]


def columns(path, names):
    header, rows = read_csv(path)
    missing = [n for n in names if n not in header]
    if missing:
        raise CheckFailed(f"{path}: no column {missing[0]!r} in {header}")
    index = [header.index(n) for n in names]
    out = []
    for number, row in enumerate(rows, 2):
        try:
            out.append([float(row[i]) for i in index])
        except (ValueError, IndexError):
            raise CheckFailed(f"{path}:{number}: not a number in {names}: {row}")
    return out


def distance(a, b):
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)))


def check_estimate_offset(stdout, args):
    _, truths = load_truths(args.session)
    estimates = {}
    for line in stdout.splitlines():
        m = TRIAL_LINE.match(line)
        if m and m.group(1) in truths:
            estimates[m.group(1)] = [float(m.group(i)) for i in (2, 3, 4)]
    if not estimates:
        raise CheckFailed("no trial estimate in the output")
    for name in args.trial:
        if name not in estimates:
            raise CheckFailed(f"trial {name} was not estimated")
    for name, estimate in estimates.items():
        error = distance(estimate, truths[name])
        if not error <= args.max_error_mm:
            raise CheckFailed(f"{name}: estimate {estimate} mm is {error:.2f} mm from the truth {truths[name]} mm "
                              f"(bound {args.max_error_mm} mm)")
    return f"{len(estimates)} trial(s) within {args.max_error_mm} mm of the truth"


def check_incision_force(stdout, args):
    session, _ = load_truths(args.session)
    base = os.path.dirname(os.path.abspath(args.session))
    calibration = os.path.join(base, session["calibration"]["recording"])
    reference = columns(calibration, ["force_x", "force_y", "force_z"])
    force = columns(args.out, ["force_x", "force_y", "force_z"])
    if len(force) != len(reference):
        raise CheckFailed(f"{args.out}: {len(force)} rows for the {len(reference)} samples of {calibration}")
    sums = [0.0, 0.0, 0.0]
    for number, (f, r) in enumerate(zip(force, reference), 2):
        if not all(math.isfinite(v) for v in f):
            raise CheckFailed(f"{args.out}:{number}: force not finite: {f}")
        for i in range(3):
            sums[i] += (f[i] - r[i]) ** 2
    rmse = [math.sqrt(s / len(force)) for s in sums]
    if not all(e <= args.max_rmse_n for e in rmse):
        raise CheckFailed(f"force RMSE x/y/z {rmse} N against {calibration}, bound {args.max_rmse_n} N")
    return f"{len(force)} finite force rows, RMSE " + " / ".join(f"{e:.2f}" for e in rmse) + " N"


def check_online_monitor(stdout, args):
    _, truths = load_truths(args.session)
    if len(args.trial) != 1 or args.trial[0] not in truths:
        raise CheckFailed(f"--trial: one trial with a truth in {args.session} expected")
    truth = truths[args.trial[0]]
    lines = stdout.splitlines()
    finals = [FINAL_LINE.match(line) for line in lines]
    finals = [[float(m.group(i)) for i in (1, 2, 3)] for m in finals if m]
    if len(finals) != 1:
        raise CheckFailed(f"{len(finals)} 'final estimate' lines, 1 expected")
    running = sum(1 for line in lines if RUNNING_LINE.match(line))
    if running < 2:
        raise CheckFailed(f"{running} running estimate line(s): the stream printed no progress")
    if not any(ONSET_LINE.match(line) for line in lines):
        raise CheckFailed("no onset reported")
    error = distance(finals[0], truth)
    if not error <= args.max_error_mm:
        raise CheckFailed(f"final estimate {finals[0]} mm is {error:.2f} mm from the truth {truth} mm "
                          f"(bound {args.max_error_mm} mm)")
    advice = [m.group(1) for m in map(ADVICE_LINE.match, lines) if m]
    offset = math.sqrt(sum(v * v for v in truth))
    expected = "reposition" if offset > COMPENSATE_LIMIT_MM + 2 else "hold" if offset < TOLERANCE_MM / 2 else None
    if expected and (not advice or advice[-1] != expected):
        raise CheckFailed(f"last advice {advice[-1] if advice else None!r} for an offset of {offset:.1f} mm; "
                          f"{expected!r} expected")
    return (f"final estimate {error:.2f} mm from the truth, {running} running estimates, "
            f"last advice {advice[-1] if advice else None}")


def check_free_space_model(stdout, args):
    names = [f"effort_{j}" for j in range(1, len(args.max_nrmse) + 1)]
    effort = columns(args.recording, names)
    predicted = columns(args.out, [f"tau_fs_{j}" for j in range(1, len(args.max_nrmse) + 1)])
    if len(predicted) != len(effort):
        raise CheckFailed(f"{args.out}: {len(predicted)} rows for the {len(effort)} samples of {args.recording}")
    start = len(effort) - len(effort) // 10
    nrmse = []
    for j in range(len(names)):
        measured = [row[j] for row in effort[start:]]
        if not all(math.isfinite(row[j]) for row in predicted):
            raise CheckFailed(f"{args.out}: tau_fs_{j + 1} not finite")
        rmse = math.sqrt(sum((p[j] - e) ** 2 for p, e in zip(predicted[start:], measured)) / len(measured))
        nrmse.append(100 * rmse / (max(measured) - min(measured)))
    if not all(e <= bound for e, bound in zip(nrmse, args.max_nrmse)):
        raise CheckFailed(f"NRMSE {nrmse} % on the last 10 % of {args.recording}, bounds {args.max_nrmse} %")
    return f"{len(predicted)} rows, held-out NRMSE " + " / ".join(f"{e:.2f}" for e in nrmse) + " %"


CHECKS = {
    "estimate-offset": check_estimate_offset,
    "incision-force": check_incision_force,
    "online-monitor": check_online_monitor,
    "free-space-model": check_free_space_model,
}


def parser():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("kind", choices=sorted(CHECKS))
    ap.add_argument("--session")
    ap.add_argument("--trial", action="append", default=[])
    ap.add_argument("--recording")
    ap.add_argument("--out")
    ap.add_argument("--max-error-mm", type=float, default=1.0)
    ap.add_argument("--max-rmse-n", type=float, default=1.5)
    ap.add_argument("--max-nrmse", type=lambda s: [float(v) for v in s.split(",")], default=[2.0, 2.0, 8.0])
    return ap


def run(argv):
    if "--" not in argv:
        print("usage: check_example.py KIND [options] -- COMMAND ...", file=sys.stderr)
        return 2
    split = argv.index("--")
    args = parser().parse_args(argv[:split])
    command = argv[split + 1:]
    if args.out and os.path.exists(args.out):
        os.remove(args.out)
    proc = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sys.stdout.write(proc.stdout)
    sys.stderr.write(proc.stderr)
    if proc.returncode != 0:
        print(f"FAILED: {' '.join(command)} exited with status {proc.returncode}")
        return 1
    try:
        summary = CHECKS[args.kind](proc.stdout, args)
    except CheckFailed as e:
        print(f"FAILED: {e}")
        return 1
    print(f"passed: {summary}")
    return 0


def self_test():
    """Every check on planted outputs: the good ones pass, the bad ones fail."""
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        def write(name, text):
            path = os.path.join(tmp, name)
            with open(path, "w") as f:
                f.write(text)
            return path

        calibration_rows = "".join(f"{0.005 * t},{0.1 * t},0.5,-1\n" for t in range(40))
        write("calibration.csv", "time,force_x,force_y,force_z\n" + calibration_rows)
        session = write("session.json", json.dumps({
            "calibration": {"recording": "calibration.csv", "coaxial_offset_m": 0.03},
            "trials": [{"name": "D30_r10_15", "truth": {"misalignment_m": [0.010, 0.015, 0.030]}},
                       {"name": "D10_r0_0", "truth": {"misalignment_m": [0.0, 0.0, 0.010]}},
                       {"name": "D0", "truth": {"misalignment_m": [0.0, 0.0, 0.0005]}}]}))
        recording = write("free.csv", "time,effort_1\n" + "".join(f"{t},{math.sin(t)}\n" for t in range(100)))

        def case(kind, good, stdout, files=(), **options):
            for name, text in files:
                write(name, text)
            argv = [kind, "--session", session, "--recording", recording]
            for key, value in options.items():
                for v in value if isinstance(value, list) else [value]:
                    argv += ["--" + key.replace("_", "-"), str(v)]
            args = parser().parse_args(argv)
            try:
                CHECKS[kind](stdout, args)
                passed = True
            except CheckFailed as e:
                passed, why = False, str(e)
            if passed != good:
                failures.append(f"{kind}: {'good' if good else 'bad'} case {stdout[:60]!r} "
                                f"{'failed: ' + why if not passed else 'passed'}")

        table = "trial  estimate\nD30_r10_15   [10.04, 14.90, 29.97]  [9.5, 10.6]\n"
        case("estimate-offset", True, table, trial="D30_r10_15")
        case("estimate-offset", False, table.replace("29.97", "32.10"))           # 2 mm off
        case("estimate-offset", False, table, trial="D10_r0_0")                   # a trial missing
        case("estimate-offset", False, "free-space model: linear\n")              # nothing estimated

        def force_csv(rows):
            return "time,force_x,force_y,force_z,theta,status\n" + "".join(rows)
        good_rows = [f"{0.005 * t},{0.1 * t + 0.2},0.4,-1.1,0.1,ok\n" for t in range(40)]
        case("incision-force", True, "", [("force.csv", force_csv(good_rows))], out=os.path.join(tmp, "force.csv"))
        case("incision-force", False, "", [("force.csv", force_csv(good_rows[:-1]))],            # a row short
             out=os.path.join(tmp, "force.csv"))
        case("incision-force", False, "", [("force.csv", force_csv(good_rows[:-1] + ["0.195,nan,0,0,0,singular\n"]))],
             out=os.path.join(tmp, "force.csv"))                                                  # NaN
        case("incision-force", False, "", [("force.csv", force_csv([r.replace(",0.4,", ",3.0,") for r in good_rows]))],
             out=os.path.join(tmp, "force.csv"))                                                  # 2.5 N off in y

        stream = ("  0.00 s  estimate [0.0, 0.0, 10.0] mm  sd [20.0, 20.0, 30.0] mm  force 0.0 N\n"
                  "  0.14 s  onset: the incision is off the RCM (detected at 0.14 s)\n"
                  "  0.47 s  advice: reposition: re-dock, move the RCM 29 mm deeper\n"
                  "  5.00 s  estimate [10.1, 14.9, 29.9] mm  sd [0.4, 0.4, 0.4] mm  force 22.3 N\n"
                  "final estimate [10.04, 15.01, 30.08] mm  sd [0.39, 0.33, 0.40] mm after 6000 samples\n")
        case("online-monitor", True, stream, trial="D30_r10_15")
        case("online-monitor", False, stream.replace("30.08", "33.08"), trial="D30_r10_15")    # 3 mm off
        case("online-monitor", False, stream.replace("advice: reposition", "advice: hold"), trial="D30_r10_15")
        case("online-monitor", False, stream.replace("onset:", "note:"), trial="D30_r10_15")    # no onset
        case("online-monitor", False, stream.replace("  5.00 s  estimate", "  5.00 s  value"), trial="D30_r10_15")
        case("online-monitor", False, stream.replace("final estimate", "last"), trial="D30_r10_15")
        case("online-monitor", False, stream, trial="D0")                                         # hold expected

        def model_csv(rows):
            return "time,tau_fs_1\n" + "".join(rows)
        good = [f"{t},{math.sin(t) + 0.01}\n" for t in range(100)]
        case("free-space-model", True, "", [("tau.csv", model_csv(good))], out=os.path.join(tmp, "tau.csv"),
             max_nrmse="2")
        case("free-space-model", False, "", [("tau.csv", model_csv(good[:-1]))], out=os.path.join(tmp, "tau.csv"),
             max_nrmse="2")                                                                         # a row short
        case("free-space-model", False, "", [("tau.csv", model_csv(good[:95] + [f"{t},0.5\n" for t in range(95, 100)]))],
             out=os.path.join(tmp, "tau.csv"), max_nrmse="2")                                       # wrong held-out part
    for f in failures:
        print(f)
    if failures:
        print(f"self-test FAILED: {len(failures)} case(s)")
        return 1
    print("self-test passed: every planted bad output caught, every good one passed")
    return 0


if __name__ == "__main__":
    if sys.argv[1:] == ["--self-test"]:
        sys.exit(self_test())
    sys.exit(run(sys.argv[1:]))
