"""What the scripts that write measured tables into docs/ share: running rcm
with the command echoed, naming the machine, and replacing the block between
two markers of a document atomically."""
import contextlib
import os
import platform
import subprocess
import sys


def run(cmd, **kw):
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, check=True, **kw)


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def write_block(path, begin, end, block):
    """Put `block` between the markers of the document at `path` (appended with
    them when absent); the document is replaced whole or not at all."""
    with open(path) as f:
        text = f.read()
    if begin in text:
        head, rest = text.split(begin, 1)
        text = head + begin + "\n" + block + "\n" + end + rest.split(end, 1)[1]
    else:
        text += f"\n{begin}\n{block}\n{end}\n"
    with open(path + ".tmp", "w") as f:
        f.write(text)
    os.replace(path + ".tmp", path)


def publish_block(path, begin, end, block, write=True):
    """Print `block`; with `write`, also put it between the markers of `path`
    (write_block) and say so on stderr."""
    print(block)
    if write:
        write_block(path, begin, end, block)
        print(f"wrote {path}", file=sys.stderr)


def add_cluster_flags(parser):
    """--scheduler / --workers of the scripts whose independent runs go through
    rcm.batch (docs/howto-batch.md)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--scheduler", help="a Dask scheduler's address, e.g. tcp://10.0.0.5:8786 (default: a local "
                                           "cluster on 127.0.0.1)")
    group.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core; 0: "
                                                   "in this process, one after another, without Dask)")


def import_rcm_batch(build):
    """rcm.batch from the build tree's package (BUILD/python) when it is there,
    else the installed one. The build tree goes on PYTHONPATH too, for the
    workers of a local cluster, with this folder; on a cluster, start `dask worker` with
    PYTHONPATH=<repository>/bench:<build>/python (docs/howto-batch.md)."""
    package = os.path.abspath(os.path.join(build, "python"))
    paths = [os.path.dirname(os.path.abspath(__file__))]  # this folder: the scripts' helpers, for the workers
    if os.path.isfile(os.path.join(package, "rcm", "batch.py")):
        sys.path.insert(0, package)
        paths.insert(0, package)
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (*paths, os.environ.get("PYTHONPATH")) if p)
    try:
        import rcm.batch
    except ImportError as exc:
        raise SystemExit(f"{sys.argv[0]}: rcm.batch not found in {package} nor installed ({exc}); build the target "
                         "rcm_python, and install python3-dask python3-distributed")
    return rcm.batch


@contextlib.contextmanager
def open_runner(build, scheduler=None, workers=None):
    """run(func, tasks) -> [func(*task) for task in tasks], in the tasks' order:
    through rcm.batch on a Dask cluster (scheduler, or a local one of `workers`
    processes), or with workers == 0 in this process one after another (no Dask
    and no rcm package needed: the instrumented test build has none). A failed
    task raises, naming it, once the others have finished."""
    if workers == 0:
        yield lambda func, tasks: [func(*task) for task in tasks]
        return
    batch = import_rcm_batch(build)
    with batch.open_client(scheduler, workers) as client:
        yield lambda func, tasks: batch.get_values(batch.map_tasks(func, [tuple(t) for t in tasks], client=client))
