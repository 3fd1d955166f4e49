#!/usr/bin/env python3
"""More free-space data never makes the free-space model much worse.

Runs `bench/learning_curve.py --quick --data teleoperation` (seed 1; 0.5, 1
and 2 min of random teleoperation; the linear model; held-out torque only, no
`rcm run`; through rcm.batch on two local workers when the build has the
Python package) and fails unless every point is finite and, per joint, each length's
held-out NRMSE is at most TOLERANCE (relative, per joint) above the previous
length's.
The excitation curve is left to the script's full run: designing its three
trajectories would triple the test's time. `--self-test` plants a rising curve and a NaN and fails
unless the check reports both.

Usage: test_learning_curve.py --rcm PATH | --self-test
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "bench", "learning_curve.py")

# Per joint (yaw, pitch, insertion), relative. The hold-out recording is the
# same for every length, so what moves a point is only which motion the fit
# saw, and how the fit's discrete choices fall on the validation fifth of a
# short recording (its Dahl displacement, its qddot window, whether the slow
# Coulomb and square-root velocity terms enter), and on pitch the travel the
# recording covers, an eighth of which its slow friction state spans. Those
# move yaw's and pitch's held-out error by up to about a fifth from one length
# of teleoperation to the next on a seed, the insertion's (which sits on the
# effort sensor's noise) by well under a per cent: the "Largest rise" line of
# docs/validation-free-space.md, measured over three seeds. 10 % is far
# above what the insertion shows; yaw and pitch need 25 % to stay above their
# own noise. A rise beyond them is what a fit that loses data, or a truncation
# that feeds it the wrong rows, produces.
TOLERANCE = (0.25, 0.25, 0.10)


def check(points, tolerance=TOLERANCE):
    """Messages for every non-finite figure and every rise beyond `tolerance`."""
    problems = []
    curves = {}
    for p in points:
        for key in ("rmse", "nrmse_percent", "fit_s"):
            values = p[key] if isinstance(p[key], list) else [p[key]]
            if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
                problems.append(f"{p['data']}, {p['minutes']:g} min: {key} not finite: {values}")
        curves.setdefault((p["model"], p["data"], p["seed"]), []).append(p)
    for (model, data, seed), ps in curves.items():
        ps.sort(key=lambda p: p["minutes"])
        for a, b in zip(ps, ps[1:]):
            for j, name in enumerate(("yaw", "pitch", "insertion")):
                x, y = a["nrmse_percent"][j], b["nrmse_percent"][j]
                if math.isfinite(x) and math.isfinite(y) and y > (1 + tolerance[j]) * x:
                    problems.append(f"{model}, {data}, seed {seed}, {name}: NRMSE {y:.3f} % at {b['minutes']:g} min "
                                    f"against {x:.3f} % at {a['minutes']:g} min (more than {tolerance[j]:.0%} above)")
    if not points:
        problems.append("no points")
    return problems


def self_test():
    def point(data, minutes, nrmse):
        return {"model": "linear", "data": data, "seed": 1, "minutes": minutes, "fit_s": 0.5,
                "rmse": [0.02, 0.03, 0.2], "nrmse_percent": nrmse}
    good = [point("teleoperation", 0.5, [0.60, 0.85, 4.1]), point("teleoperation", 1, [0.65, 0.80, 4.1]),
            point("teleoperation", 2, [0.55, 0.80, 4.0])]
    rising = good[:2] + [point("teleoperation", 2, [0.55, 1.08, 4.0])]
    nan = good[:2] + [point("teleoperation", 2, [0.55, float("nan"), 4.0])]
    failures = []
    if check(good):
        failures.append(f"a curve within tolerance was flagged: {check(good)}")
    if not any("pitch" in m and "2 min" in m for m in check(rising)):
        failures.append("a rise of 35 % on pitch was not flagged")
    if not any("yaw" in m for m in check(good[:1] + [point("teleoperation", 1, [0.80, 0.85, 4.1])])):
        failures.append("a rise of 33 % on yaw was not flagged")
    if not any("not finite" in m for m in check(nan)):
        failures.append("a NaN was not flagged")
    for f in failures:
        print("self-test:", f)
    print("self-test:", "failed" if failures else "passed")
    return 1 if failures else 0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rcm", help="the rcm program")
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    if not args.rcm:
        ap.error("--rcm is required")
    # Through rcm.batch on a local cluster when the program's build has the
    # Python package (and Dask is installed); else, as in the instrumented
    # build, which has none, in the script's own process (--workers 0).
    build = os.path.dirname(os.path.dirname(os.path.abspath(args.rcm)))
    try:
        import distributed  # noqa: F401
        has_dask = True
    except ImportError:
        has_dask = False
    if has_dask and os.path.isfile(os.path.join(build, "python", "rcm", "batch.py")):
        where = ["--build", build, "--workers", "2"]
    else:
        where = ["--workers", "0"]
    with tempfile.TemporaryDirectory(prefix="rcm_test_learning_curve_") as work:
        out = os.path.join(work, "curve.json")
        subprocess.run([sys.executable, SCRIPT, "--quick", "--data", "teleoperation", "--rcm", args.rcm, "--json", out,
                        *where], check=True, stderr=subprocess.DEVNULL)
        with open(out) as f:
            points = json.load(f)["points"]
    kinds = {p["data"] for p in points}
    problems = check(points)
    if kinds != {"teleoperation"} or len(points) != 3:
        problems.append(f"expected 3 teleoperation points, got {len(points)} of {sorted(kinds)}")
    for p in problems:
        print("FAIL:", p)
    print(f"{len(points)} points, {'failed' if problems else 'passed'}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
