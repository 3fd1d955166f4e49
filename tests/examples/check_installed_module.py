#!/usr/bin/env python3
"""Checks the Python module that `cmake --install` put in place.

    check_installed_module.py --python PY --prefix P --site-dir REL --destdir D
                              --configured-prefix C --version V

1. `--prefix P` install: with PYTHONPATH=P/REL and nothing else, PY imports
   the package rcm from P/REL/rcm (not from the build tree, nor from another
   install), at version V, and computes with it; the installed `P/bin/rcm batch`
   (with --rcm P/bin/rcm) finds that package and Dask by itself, without
   PYTHONPATH, and reports a bad session with its location (exit 2).
2. DESTDIR=D install at the configured prefix C: the module lies in D/C/REL,
   and C/REL is on PY's own sys.path (no PYTHONPATH), so that a plain
   `cmake --install` makes `import rcm` work; imported from D/C/REL, it works.
   When PY searches no C/lib*/ directory at all, part 2 cannot hold and the
   script exits 77 (skipped) after part 1.
"""

import argparse
import glob
import os
import subprocess
import sys

PROBE = """
import json, rcm, rcm.dynamics
k = rcm.compute_incision_kinematics([0.3, -0.2, 0.15], q0=[0, 0, 0.12], offset=0.03)
print(json.dumps({"file": rcm.__file__, "core": rcm._core.__file__, "version": rcm.__version__, "theta": k.theta,
                  "error": rcm.InputError.__module__ + "." + rcm.InputError.__name__,
                  "dynamics": rcm.dynamics.__name__}))
"""


def run_python(python, pythonpath, code):
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath
    # -s: no user site directory; the working directory is not the build tree.
    return subprocess.run([python, "-s", "-c", code], env=env, cwd="/", stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True)


def check_import(python, site_dir, version):
    import json
    proc = run_python(python, site_dir, PROBE)
    if proc.returncode != 0:
        return f"import rcm with PYTHONPATH={site_dir} failed:\n{proc.stderr}"
    info = json.loads(proc.stdout)
    package = os.path.join(os.path.realpath(site_dir), "rcm")
    if os.path.dirname(os.path.realpath(info["file"])) != package:
        return f"rcm came from {info['file']}, not from {package}"
    if os.path.dirname(os.path.realpath(info["core"])) != package:
        return f"rcm._core came from {info['core']}, not from {package}"
    if (info["error"], info["dynamics"]) != ("rcm.InputError", "rcm.dynamics"):
        return f"the package names its members {info['error']}, {info['dynamics']}"
    if info["version"] != version:
        return f"rcm.__version__ is {info['version']!r}, the project's is {version!r}"
    if not 0.0 < info["theta"] < 3.2:
        return f"compute_incision_kinematics gave theta = {info['theta']}"
    print(f"imported {info['file']} (rcm {info['version']})")
    return None


def check_package_files(site_dir):
    modules = glob.glob(os.path.join(site_dir, "rcm", "_core.*.so"))
    if len(modules) != 1:
        return f"{len(modules)} rcm/_core.*.so in {site_dir}"
    for name in ("__init__.py", "batch.py"):
        if not os.path.isfile(os.path.join(site_dir, "rcm", name)):
            return f"no rcm/{name} in {site_dir}"
    return None


def check_batch(rcm):
    """The installed `rcm batch` on a manifest that is no session: Python, the
    package and Dask found without PYTHONPATH, the session's error located."""
    import tempfile
    with tempfile.TemporaryDirectory(prefix="rcm_install_batch_") as tmp:
        manifest = os.path.join(tmp, "broken", "session.json")
        os.makedirs(os.path.dirname(manifest))
        with open(manifest, "w") as f:
            f.write("{}\n")
        env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "RCM_PYTHON"}
        proc = subprocess.run([rcm, "batch", "--workers", "1", "--out", os.path.join(tmp, "out"), manifest], env=env,
                              cwd="/", stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if proc.returncode != 2 or f"broken ({manifest}): {manifest}" not in proc.stderr:
            return f"{rcm} batch on a manifest without fields exited {proc.returncode}:\n{proc.stderr}"
        if not os.path.isfile(os.path.join(tmp, "out", "summary.json")):
            return f"{rcm} batch wrote no summary.json"
    print(f"{rcm} batch ran the installed package and located the bad session")
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for name in ("python", "prefix", "site-dir", "destdir", "configured-prefix", "version"):
        ap.add_argument("--" + name, required=True)
    ap.add_argument("--rcm", help="the installed rcm program: check that `rcm batch` finds the installed package")
    a = ap.parse_args()
    a.prefix, a.destdir = os.path.abspath(a.prefix), os.path.abspath(a.destdir)

    installed = os.path.join(a.prefix, a.site_dir)
    problem = check_package_files(installed) or check_import(a.python, installed, a.version)
    if not problem and a.rcm:
        problem = check_batch(a.rcm)
    if problem:
        print(f"FAILED: {problem}")
        return 1

    target = os.path.join(a.configured_prefix, a.site_dir)
    staged = os.path.join(a.destdir, target.lstrip("/"))
    problem = check_package_files(staged)
    if problem:
        print(f"FAILED: DESTDIR install: {problem}")
        return 1
    proc = run_python(a.python, None, "import sys; print('\\n'.join(sys.path))")
    search = [os.path.realpath(p) for p in proc.stdout.splitlines() if p]
    prefix = os.path.realpath(a.configured_prefix)
    under_prefix = [p for p in search if os.path.relpath(p, prefix).split(os.sep)[0].startswith("lib")]
    if not under_prefix:
        print(f"skipped: {a.python} searches no {a.configured_prefix}/lib*/ directory ({search}): "
              f"a module installed under that prefix needs PYTHONPATH")
        return 77
    if os.path.realpath(target) not in search:
        print(f"FAILED: the module installs to {target}, which is not on {a.python}'s sys.path; "
              f"under {a.configured_prefix} it searches {under_prefix}")
        return 1
    print(f"{target} is on {a.python}'s sys.path")
    problem = check_import(a.python, staged, a.version)
    if problem:
        print(f"FAILED: {problem}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
