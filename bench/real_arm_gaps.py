#!/usr/bin/python3
"""The free-space model on a real arm, at the same speed and across speeds,
against a plain ridge regression and the generic structure.

Same speed: each recording fitted as `rcm dynamics fit` fits it (the first 70 %
to fit, the next 20 % to choose, coefficients from both) and scored on its
last 10 %, the NRMSE the fit reports (RMSE over the torque's range there).
Across speed: FAST:SLOW pairs fitted on one run and scored on the other.

Models, all through rcm's Python module:
  linear                the default fit;
  linear, no travel     the default fit without the travel terms (FitOptions.travel_terms);
  linear, generic       the free potential and a constant armature (FitOptions.rigid_body off,
                        `rcm dynamics fit --generic-structure`): the yardstick the default's
                        cross-speed error is set against;
  ridge                 a plain ridge regression on the first 90 % on rigid-body and friction
                        features: rcm's 17 gravity and 19 inertia regressors, and per joint
                        qddot (zero-phase cubic, 0.15 s), qdot, a Dahl state at 0.3 % of the
                        joint's range, sqrt(|qdot|) sign(qdot) and a constant; the ridge 1e-3
                        of each column's mean square.

Run with Debian's Python and the built module:
  PYTHONPATH=build/python /usr/bin/python3 bench/real_arm_gaps.py --real DIR
The table goes between the real-arm-gaps markers of docs/validation-free-space.md
(--no-doc: printed only). The recordings stay where they are.
"""
import argparse
import datetime
import os
import sys

import numpy as np

from doc_tables import cpu_model, write_block
from recording_arrays import load, zero_phase_acceleration

import rcm  # build/python on PYTHONPATH

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "validation-free-space.md")
BEGIN, END = "<!-- real-arm-gaps:begin -->", "<!-- real-arm-gaps:end -->"
RUNS = ["105g_insertion_full", "105g_insertion_half", "205g_insertion_full", "205g_insertion_half",
        "105g_parallel_half", "205g_parallel_half"]
PAIRS = [("105g_insertion_full", "105g_insertion_half"), ("105g_insertion_half", "105g_insertion_full"),
         ("205g_insertion_full", "205g_insertion_half"), ("205g_insertion_half", "205g_insertion_full")]


def label(name):
    grams, where, speed = name.split("_")
    return f"{grams[:-1]} g {'insertion' if where == 'insertion' else 'parallelogram'}, {speed}"


def options(kind):
    o = rcm.dynamics.FitOptions()
    o.verbose = False
    if kind == "linear, no travel":
        o.travel_terms = False
    if kind == "linear, generic":
        o.rigid_body = False
    return o


def ridge_features(d):
    """n x 3 x p: the ridge baseline's columns (module docstring)."""
    q, qd = d["q"], d["qd"]
    qdd = zero_phase_acceleration(d["t"], qd, 0.15)
    n = len(q)
    gravity = np.stack([rcm.dynamics.compute_gravity_regressor(q[i]) for i in range(n)], 0)
    inertia = np.stack([rcm.dynamics.compute_inertia_regressor(q[i], qd[i], qdd[i]) for i in range(n)], 0)
    span = q.max(0) - q.min(0)
    blocks = []
    for j in range(3):
        z = np.zeros(n)
        for k in range(1, n):
            z[k] = rcm.dynamics.compute_dahl_state(z[k - 1], q[k, j] - q[k - 1, j], 3e-3 * span[j])
        blocks.append(np.stack([qdd[:, j], qd[:, j], z, np.sign(qd[:, j]) * np.sqrt(np.abs(qd[:, j])), np.ones(n)], 1))
    shared = np.concatenate([gravity, inertia], 2)
    X = np.zeros((n, 3, shared.shape[2] + 15))
    X[:, :, :shared.shape[2]] = shared
    for j in range(3):
        X[:, j, shared.shape[2] + 5 * j:shared.shape[2] + 5 * j + 5] = blocks[j]
    return X


def ridge_same_speed(path):
    d = load(path)
    X, y = ridge_features(d), d["tau"]
    cut = int(0.9 * len(y))
    w = 1.0 / y[:cut].std(0)  # each joint's rows by 1 / its torque's sd, as rcm's fit
    A = np.einsum("njp,j,njq->pq", X[:cut], w ** 2, X[:cut])
    b = np.einsum("njp,j,nj->p", X[:cut], w ** 2, y[:cut])
    A += 1e-3 * np.diag(np.maximum(np.diag(A), 1e-12 * np.diag(A).max()))
    theta = np.linalg.solve(A, b)
    r = y[cut:] - np.einsum("njp,p->nj", X[cut:], theta)
    return 100 * np.sqrt((r ** 2).mean(0)) / (y[cut:].max(0) - y[cut:].min(0))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--real", required=True, help="folder of the six psm1_*.csv recordings")
    ap.add_argument("--no-doc", action="store_true", help="print the table instead of writing the page")
    args = ap.parse_args()
    path = lambda name: os.path.join(args.real, f"psm1_{name}.csv")
    missing = [path(name) for name in RUNS if not os.path.isfile(path(name))]
    if missing:
        sys.exit(f"real_arm_gaps.py: --real {args.real}: no {', '.join(map(os.path.basename, missing))}")
    recordings = {name: rcm.load_recording(path(name)) for name in RUNS}
    kinds = ["linear", "linear, no travel", "linear, generic"]
    models, same = {}, {}
    for name in RUNS:
        for kind in kinds:
            fit = rcm.dynamics.fit_linear_torque_model([recordings[name]], options(kind))
            models[(name, kind)] = fit.model
            same[(name, kind)] = [e.nrmse_percent for e in fit.summary.test_errors]
        same[(name, "ridge")] = ridge_same_speed(path(name))

    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    out = [f"Measured by `bench/real_arm_gaps.py` on {stamp}, {cpu_model()}, {os.cpu_count()} cores."]
    out.append("\n**Same speed**: NRMSE yaw / pitch / insertion (%) on the last 10 % of each recording, fitted on "
               "the rest as `rcm dynamics fit` fits it; `ridge`: a plain ridge regression on rigid-body and friction "
               "features (the script's docstring):\n")
    out.append("| recording | linear | linear, no travel terms | linear, generic | ridge |")
    out.append("|---|---|---|---|---|")
    fmt = lambda v: " / ".join(f"{x:.2f}" for x in v)
    for name in RUNS:
        out.append(f"| {label(name)} | " + " | ".join(fmt(same[(name, k)]) for k in kinds + ["ridge"]) + " |")
    out.append("\n**Across speed**: RMSE yaw / pitch (N m) / insertion (N), fitted on the first run and scored on "
               "the second; last column: `linear` over `linear, generic` per joint:\n")
    out.append("| runs | linear | linear, no travel terms | linear, generic | linear / generic |")
    out.append("|---|---|---|---|---|")
    for fast, slow in PAIRS:
        rmse = {}
        for kind in kinds:
            errors = rcm.dynamics.evaluate_torque_model(models[(fast, kind)], [recordings[slow]], 0.0)
            rmse[kind] = np.array([e.rmse for e in errors])
        ratio = rmse["linear"] / rmse["linear, generic"]
        out.append(f"| {label(fast)} -> {label(slow).split(', ')[1]} | " +
                   " | ".join(" / ".join(f"{x:.3f}" for x in rmse[k]) for k in kinds) + " | " +
                   " / ".join(f"{x:.2f}" for x in ratio) + " |")
    block = "\n".join(out)
    print(block)
    if not args.no_doc:
        write_block(DOC, BEGIN, END, block)


if __name__ == "__main__":
    main()
