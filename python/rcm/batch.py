"""rcm.batch: independent work (studies, fits, evaluations, simulated sessions,
any function of a seed) run on a Dask cluster, one task per session or seed.

    import rcm.batch
    results = rcm.batch.run_studies(["a/session.json", "b/session.json"], workers=2)
    for r in results:
        print(r.task, r.value["summary"] if r.ok else r.error)

    # any function of (seed, ...): a plain map, results in task order
    results = rcm.batch.map_tasks(my_function, [(seed, 0.03) for seed in range(8)], scheduler="tcp://host:8786")
    values = rcm.batch.get_values(results)   # raises BatchError naming every failed task

Where it runs: `scheduler="tcp://HOST:PORT"` (a `dask scheduler` with its `dask
worker`s), an existing `client=`, or else a LocalCluster on this machine bound
to 127.0.0.1 with `workers` processes (default: one per core) of one thread
each. The library releases the GIL in its long calls; the processes are what
makes the tasks run side by side.

Each task is computed exactly as it is alone: the same function on the same
arguments (seeds included), never split or reordered, so its numbers do not
depend on the number of workers or on which worker ran it. A task that raises
is reported as a TaskError (an rcm.InputError keeps its file, line, column and
field) and the others go on. Inputs are read by the workers at the paths given
(made absolute here): on a cluster every machine must see them at those paths.
Results travel back to the caller; `run_sessions` writes the files itself.

The map is in _batch_map.py, `rcm batch`'s sessions and summary in
_batch_sessions.py; this module is their public face and the library's tasks.

`python3 -m rcm.batch SESSIONS... --out DIR` is what `rcm batch` runs
(docs/howto-batch.md).
"""

import os
import sys

import rcm
from rcm._batch_map import BatchError, TaskError, TaskResult, get_values, map_tasks, open_client
from rcm._batch_sessions import _make_study_options, _study_options, compute_session, get_session_names, main, run_sessions

# run_* / fit_* / evaluate_* / simulate_* spread their compute_* (one task, also callable alone) over the cluster.
__all__ = ["TaskError", "TaskResult", "BatchError", "open_client", "map_tasks", "get_values", "run_studies",
           "fit_models", "evaluate_models", "simulate_sessions", "run_sessions", "get_session_names", "main",
           "compute_study", "compute_fit", "compute_evaluation", "compute_simulation", "compute_session"]


# ---- the library's work, one task per session, recording set or seed ----

def compute_study(manifest, options=None):
    """One session's study, as run_study: the rcm-results/1 dict (`rcm run --json`)."""
    session = rcm.load_session(manifest)
    return rcm.run_study(session, _make_study_options(options or {})).to_json()


def run_studies(manifests, options=None, **cluster):
    """run_study on every session manifest; TaskResult.value is its results dict
    (what `rcm run --json` prints). `cluster`: client, scheduler, workers, on_result."""
    opts = _study_options(options)
    return map_tasks(compute_study, [(os.path.abspath(m), opts) for m in manifests], **cluster)


def compute_fit(recordings, fit_options=None):
    """The linear free-space model fitted on recordings (paths): {'model': the
    model file's dict (rcm.dynamics.torque_model_from_json reads it back),
    'summary': FitSummary.to_dict()}."""
    o = rcm.dynamics.FitOptions.from_dict(fit_options or {})
    o.verbose = False
    fit = rcm.dynamics.fit_linear_torque_model([rcm.load_recording(p) for p in recordings], o)
    return {"model": fit.model.to_json(), "summary": fit.summary.to_dict()}


def fit_models(recording_sets, fit_options=None, **cluster):
    """compute_fit on each list of recording paths (one model per list)."""
    opts = fit_options.to_dict() if hasattr(fit_options, "to_dict") else dict(fit_options or {})
    return map_tasks(compute_fit, [([os.path.abspath(p) for p in paths], opts) for paths in recording_sets], **cluster)


def compute_evaluation(model_file, recordings):
    """A saved model's per-joint error on one recording or a list of them, as
    `rcm dynamics eval MODEL RECORDINGS...`: [{'index', 'rmse', 'nrmse_percent', 'range'}]."""
    paths = [recordings] if isinstance(recordings, (str, os.PathLike)) else list(recordings)
    model = rcm.dynamics.load_torque_model(model_file)
    errors = rcm.dynamics.evaluate_torque_model(model, [rcm.load_recording(p) for p in paths])
    return [{"index": e.index, "rmse": e.rmse, "nrmse_percent": e.nrmse_percent, "range": e.range} for e in errors]


def evaluate_models(pairs, **cluster):
    """compute_evaluation on each (model file, recording or list of recordings) pair."""
    def absolute(r):
        return os.path.abspath(r) if isinstance(r, (str, os.PathLike)) else [os.path.abspath(p) for p in r]
    return map_tasks(compute_evaluation, [(os.path.abspath(m), absolute(r)) for m, r in pairs], **cluster)


def compute_simulation(config, out_dir):
    """rcm.sim.simulate_session of a SimConfig dict (SimConfig.to_dict(), with
    its seed) into out_dir, as `rcm simulate --out`; returns the manifest path."""
    c = rcm.sim.SimConfig()
    c.update(config)
    rcm.sim.simulate_session(c, out_dir)
    return os.path.join(out_dir, "session.json")


def simulate_sessions(configs, out_dirs, **cluster):
    """compute_simulation per (config, folder): the folders must be where the
    workers write (this machine for a LocalCluster, a shared file system on a cluster)."""
    tasks = [(c.to_dict() if hasattr(c, "to_dict") else dict(c), os.path.abspath(d)) for c, d in zip(configs, out_dirs)]
    if len(tasks) != len(configs) or len(tasks) != len(out_dirs):
        raise ValueError("simulate_sessions: one output folder per configuration")
    return map_tasks(compute_simulation, tasks, **cluster)


if __name__ == "__main__":
    # Through the module's own name, so that the workers find the task functions under rcm.*.
    import rcm.batch as _batch
    sys.exit(_batch.main())
