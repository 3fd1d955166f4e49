"""The map of rcm.batch: a function over tasks on a Dask cluster, one task per
call, each one's failure reported as data (docs/howto-batch.md). Nothing here
knows rcm's computations; rcm.batch re-exports it."""

import contextlib
import os
import time
import traceback
import uuid

import rcm


class TaskError:
    """Why a task failed: the exception's type and message; for an rcm.InputError
    also where (file, line, column, field) and the reason without the place."""

    def __init__(self, type, message, file=None, line=None, column=None, field=None, reason=None, traceback=None):
        self.type, self.message = type, message
        self.file, self.line, self.column, self.field, self.reason = file, line, column, field, reason
        self.traceback = traceback

    @property
    def is_input_error(self):
        return self.type == "InputError"

    def to_dict(self):
        return {k: getattr(self, k) for k in ("type", "message", "file", "line", "column", "field", "reason")}

    def __str__(self):
        return self.message if self.is_input_error else f"{self.type}: {self.message}"

    def __repr__(self):
        return f"TaskError({self.type}: {self.message!r})"


class TaskResult:
    """One task's outcome: `value` when it returned, `error` (TaskError) when it raised."""

    def __init__(self, index, task, value=None, error=None, seconds=0.0):
        self.index, self.task, self.value, self.error, self.seconds = index, task, value, error, seconds

    @property
    def ok(self):
        return self.error is None

    def __repr__(self):
        return f"TaskResult({self.index}, {'ok' if self.ok else repr(self.error)})"


class BatchError(RuntimeError):
    """Raised by get_values when tasks failed; `failed` holds their TaskResults."""

    def __init__(self, failed):
        self.failed = failed
        lines = [f"{len(failed)} task(s) failed:"] + [f"  {r.task!r}: {r.error}" for r in failed]
        super().__init__("\n".join(lines))


def _describe(exc):
    """A TaskError from an exception; an rcm.InputError raised by the library keeps its location."""
    error = TaskError(type(exc).__name__, str(exc), traceback="".join(traceback.format_exception(exc)))
    if isinstance(exc, rcm.InputError):
        for name in ("file", "line", "column", "field", "reason"):
            setattr(error, name, getattr(exc, name, None))
    return error


def _run_task(func, args, kwargs):
    """Runs on a worker. Errors come back as data (a TaskError), never as an
    exception, so that one task's failure reaches the caller with its location
    and without Dask retrying it."""
    start = time.perf_counter()
    try:
        return True, func(*args, **kwargs), time.perf_counter() - start
    except Exception as exc:  # noqa: BLE001  (every failure is reported, none stops the batch)
        return False, _describe(exc), time.perf_counter() - start


def require_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise ImportError("rcm.batch needs Dask's distributed scheduler: on Debian, "
                          "apt install python3-dask python3-distributed") from exc
    return distributed


@contextlib.contextmanager
def open_client(scheduler=None, workers=None):
    """A distributed.Client: connected to `scheduler` ("tcp://host:port"), or to
    a LocalCluster of `workers` processes (default: os.cpu_count()) of one thread
    each, listening on 127.0.0.1 only; closed on exit."""
    distributed = require_distributed()
    import dask  # installed with distributed
    if scheduler:
        if workers:
            raise ValueError("give a scheduler address or a number of workers, not both")
        with distributed.Client(scheduler) as client:
            yield client
        return
    n = int(workers) if workers else (os.cpu_count() or 1)
    if n < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    # Every listening socket on the loopback interface: the HTTP servers (health
    # and metrics routes) that the scheduler and each worker start even without
    # a dashboard would otherwise listen on every interface.
    loopback = "127.0.0.1"
    # The workers' environment as a program run alone has it, one core each:
    # Dask's default also sets MALLOC_TRIM_THRESHOLD_, which fixes glibc's
    # thresholds and made a study's allocations cost a third more CPU time.
    # Nor does a worker profile its tasks (a stack sample every 10 ms).
    config = {"distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1,
                                                      "OPENBLAS_NUM_THREADS": 1},
              "distributed.worker.profile.enabled": False}
    with dask.config.set(config), distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host=loopback,
                                  scheduler_kwargs={"dashboard": False, "dashboard_address": f"{loopback}:0"},
                                  worker_dashboard_address=f"{loopback}:0") as cluster, \
            distributed.Client(cluster) as client:
        yield client


def _as_call(task):
    """A task is a tuple of positional arguments, a dict of keyword arguments,
    or one argument."""
    if isinstance(task, tuple):
        return task, {}
    if isinstance(task, dict):
        return (), task
    return (task,), {}


def map_tasks(func, tasks, *, client=None, scheduler=None, workers=None, on_result=None):
    """func(*task) (or func(**task), func(task): see _as_call) for every task on
    the cluster; returns a TaskResult per task, in the tasks' order. A failed
    task does not stop the others. `on_result(result)` is called on the caller's
    thread as each one finishes (progress). func must be importable by the
    workers (a function of a module on their path) or defined in the caller's
    script (sent by value)."""
    tasks = list(tasks)
    if not tasks:
        return []
    if client is None:
        with open_client(scheduler, workers) as own:
            return map_tasks(func, tasks, client=own, on_result=on_result)
    distributed = require_distributed()
    batch = uuid.uuid4().hex[:12]
    futures = {}
    for i, task in enumerate(tasks):
        args, kwargs = _as_call(task)
        future = client.submit(_run_task, func, args, kwargs, key=f"rcm-batch-{batch}-{i}", pure=False, retries=0)
        futures[future] = i
    results = [None] * len(tasks)
    for future in distributed.as_completed(futures):
        i = futures[future]
        try:
            ok, value, seconds = future.result()
            result = TaskResult(i, tasks[i], value if ok else None, None if ok else value, seconds)
        except Exception as exc:  # noqa: BLE001  (the worker died, or the result could not travel)
            result = TaskResult(i, tasks[i], error=_describe(exc))
        results[i] = result
        future.release()
        if on_result is not None:
            on_result(result)
    return results


def get_values(results):
    """The values of successful results, in order; BatchError if any failed."""
    failed = [r for r in results if not r.ok]
    if failed:
        raise BatchError(failed)
    return [r.value for r in results]
