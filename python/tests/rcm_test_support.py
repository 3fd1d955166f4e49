"""What the tests of the Python module share: the CLI to cross-check against,
one small simulated session and a linear free-space model fitted on it.

The session (`rcm simulate --quick`, two trials at D = 30 mm) is written once
per process by the CLI, the first time a test module asks for it
(set_up_session, every module's setUpModule); the linear model is fitted once
in Python. Reference values come from the CLI on the same files, so a binding
that passes the wrong argument, drops a sample or converts a unit fails.
"""

import atexit
import json
import os
import shutil
import subprocess
import tempfile

import numpy as np

import rcm

CLI = os.environ.get("RCM_CLI", "")
Q0 = [0.0, 0.0, 0.12]
TRUTH = {"D30_r0_0": [0.0, 0.0, 0.03], "D30_r10_15": [0.010, 0.015, 0.030]}
# Two trials instead of the quick session's ten keep the whole run short.
SIM_OVERRIDES = {"protocol": {"coaxial_offsets_m": [0.03], "radial_offsets_m": [[0.0, 0.0], [0.010, 0.015]]}}

_state = {}


def run_cli(*args, json_out=True):
    """Runs the CLI; fails the test with its stderr when it does not exit 0."""
    proc = subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise AssertionError(f"rcm {' '.join(map(str, args))} exited {proc.returncode}:\n{proc.stderr}")
    return json.loads(proc.stdout) if json_out else proc.stdout


def set_up_session():
    """Simulates the session and fits the model, once per process."""
    if "manifest" in _state:
        return
    if not (CLI and os.access(CLI, os.X_OK)):
        raise RuntimeError(f"RCM_CLI={CLI!r} is not an executable; build rcm_cli and set RCM_CLI")
    tmp = tempfile.mkdtemp(prefix="rcm_python_test_")
    _state["tmp"] = tmp
    config = os.path.join(tmp, "sim_overrides.json")
    with open(config, "w") as f:
        json.dump(SIM_OVERRIDES, f)
    session_dir = os.path.join(tmp, "session")
    run_cli("simulate", "--quick", "--config", config, "--no-truth", "--out", session_dir, "--json")
    _state["session_dir"] = session_dir
    _state["manifest"] = os.path.join(session_dir, "session.json")
    free = rcm.load_recording(os.path.join(session_dir, "free_space.csv"))
    options = rcm.dynamics.FitOptions()
    options.verbose = False
    fit = rcm.dynamics.fit_linear_torque_model([free], options)
    _state["free"] = free
    _state["fit"] = fit
    _state["model_path"] = os.path.join(tmp, "linear.json")
    rcm.dynamics.save_torque_model(_state["model_path"], fit.model)
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)


def session_file(name):
    return os.path.join(_state["session_dir"], name)


def tmp_path(name):
    return os.path.join(_state["tmp"], name)


def random_arrays(T=40, N=4, seed=3):
    rng = np.random.default_rng(seed)
    time = np.cumsum(rng.uniform(0.004, 0.006, T))
    return time, rng.normal(size=(T, N)), rng.normal(size=(T, N)), rng.normal(size=(T, N)), rng.normal(size=(T, 3))


def quiet_study_options(**fields):
    options = rcm.StudyOptions()
    options.verbose = False
    options.model_file = _state["model_path"]
    for key, value in fields.items():
        setattr(options, key, value)
    return options

