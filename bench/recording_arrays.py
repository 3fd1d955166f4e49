"""What the bench scripts that study free-space recordings share: a recording
in rcm's CSV format as numpy arrays of joints 1-3, and the zero-phase qddot
estimate rcm's offline fit uses."""
import numpy as np


def load(path):
    d = np.genfromtxt(path, delimiter=",", names=True)
    col = lambda name: np.stack([d[f"{name}_{j}"] for j in (1, 2, 3)], 1)
    return {"t": d["time"], "q": col("position"), "qd": col("velocity"), "tau": col("effort")}


def zero_phase_acceleration(t, qd, window=0.15, degree=3):
    """Slope of a least-squares polynomial through +- window/2 of each sample (rcm's offline estimate: a cubic)."""
    out = np.zeros_like(qd)
    lo = hi = 0
    n = len(t)
    for i in range(n):
        while t[lo] < t[i] - window / 2:
            lo += 1
        hi = max(hi, i + 1)
        while hi < n and t[hi] <= t[i] + window / 2:
            hi += 1
        s = t[lo:hi] - t[i]
        A = np.stack([s ** k for k in range(degree + 1)], 1)
        out[i] = np.linalg.lstsq(A, qd[lo:hi], rcond=None)[0][1]
    return out
