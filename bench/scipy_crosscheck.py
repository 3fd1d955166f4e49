#!/usr/bin/python3
"""Cross-check of the coaxial solve (paper Eq. 16-17) against scipy.

The paper solved D~ with MATLAB's lsqnonlin (trust-region-reflective);
scipy.optimize.least_squares(method='trf') is the same algorithm. This script
reads the problems that `rcm run --export-problems DIR` wrote, solves each with
scipy, and compares:
  - the optimum, both solvers at tolerance 1e-15 (must agree to 1e-6 m);
  - the time of one solve at the paper's stopping rule (relative change of cost
    below 1e-6), median of 21 runs, against Ceres' median from the export.

Run with Debian's Python (python3-scipy, python3-sympy):
    /usr/bin/python3 bench/scipy_crosscheck.py PROBLEM_DIR [--write docs/benchmarks.md]
"""
import glob
import json
import os
import statistics
import sys
import time

import numpy as np
import sympy
from scipy.optimize import least_squares

BEGIN, END = "<!-- scipy_crosscheck:begin -->", "<!-- scipy_crosscheck:end -->"


def load(path):
    p = json.load(open(path))
    x = sympy.Symbol("x")
    expr = sympy.sympify(p["g_sympy"])
    g = sympy.lambdify(x, expr, "numpy")
    dg = sympy.lambdify(x, sympy.diff(expr, x), "numpy")
    tan = np.asarray(p["tan_theta"])
    u = np.asarray(p["u"]) - np.asarray(p["radial_u"])
    w = np.asarray(p["w"]) - np.asarray(p["radial_w"])

    def residuals(d):
        D = d[0]
        fc = u / D + w
        return np.broadcast_to(g(D * tan), tan.shape) - np.linalg.norm(fc, axis=1)

    def jacobian(d):
        D = d[0]
        fc = u / D + w
        n = np.linalg.norm(fc, axis=1)
        dn = np.einsum("ij,ij->i", fc, -u / D**2) / np.where(n > 0, n, 1.0)
        return (np.broadcast_to(dg(D * tan), tan.shape) * tan - dn)[:, None]

    return p, residuals, jacobian


def solve(p, residuals, jacobian, tol):
    kw = dict(ftol=tol, xtol=1e-15 if tol < 1e-10 else 1e-8, gtol=1e-15 if tol < 1e-10 else 1e-8)
    r = least_squares(residuals, [p["D_initial"]], jac=jacobian, bounds=([p["D_min"]], [p["D_max"]]),
                      method="trf", **kw)
    return r.x[0], r.nfev


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    files = sorted(glob.glob(os.path.join(sys.argv[1], "*.json")))
    if not files:
        sys.exit(f"{sys.argv[1]}: no exported problems (run `rcm run SESSION --export-problems DIR`)")
    rows, worst, ratios = [], 0.0, []
    for f in files:
        p, res, jac = load(f)
        d_tight, _ = solve(p, res, jac, 1e-15)
        d_paper, nfev = solve(p, res, jac, p["function_tolerance"])
        times = []
        for _ in range(21):
            t0 = time.perf_counter()
            solve(p, res, jac, p["function_tolerance"])
            times.append(time.perf_counter() - t0)
        t_scipy = statistics.median(times)
        diff = abs(d_tight - p["D_tight"])
        worst = max(worst, diff)
        ratio = t_scipy / p["ceres_seconds_median"]
        ratios.append(ratio)
        rows.append((p["trial"], len(p["tan_theta"]), 1e3 * p["D_paper_tolerance"], 1e3 * d_paper, 1e3 * p["D_tight"],
                     1e3 * d_tight, diff, 1e3 * p["ceres_seconds_median"], 1e3 * t_scipy, ratio))
    lines = [
        "| trial | samples | D~ Ceres (mm) | D~ scipy (mm) | optimum Ceres, tol 1e-15 (mm) | optimum scipy (mm) "
        "| difference (m) | Ceres (ms) | scipy trf (ms) | scipy / Ceres |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append("| {} | {} | {:.4f} | {:.4f} | {:.6f} | {:.6f} | {:.1e} | {:.2f} | {:.2f} | {:.1f} |".format(*r))
    lines.append("")
    lines.append(f"Largest difference of the optima: {worst:.1e} m (required <= 1e-6 m). "
                 f"scipy / Ceres time: median {statistics.median(ratios):.1f}x.")
    block = "\n".join(lines)
    print(block)
    if "--write" in sys.argv:
        path = sys.argv[sys.argv.index("--write") + 1]
        text = open(path).read()
        if BEGIN in text:
            head, rest = text.split(BEGIN, 1)
            tail = rest.split(END, 1)[1]
            text = head + BEGIN + "\n" + block + "\n" + END + tail
        else:
            text += f"\n{BEGIN}\n{block}\n{END}\n"
        open(path, "w").write(text)
    if worst > 1e-6:
        sys.exit(f"optima differ by {worst:.2e} m > 1e-6 m")


if __name__ == "__main__":
    main()
