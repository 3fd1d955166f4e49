#!/usr/bin/env python3
"""Layer check: a file may include its own layer and the layers below it only.

Layers, bottom up (docs/architecture.md):

    common < kinematics < io < dynamics < force < tissue < estimation < live < sim
           < apps, python, ros, dds, examples   (the top: each of these includes
                                                 the library, none includes another)

A file's layer is its directory: include/rcm/<layer>/ and src/<layer>/ for the
library, apps/ (the CLI), python/ (the module), ros/ and dds/ (the nodes),
examples/ (programs for users to copy). Every `#include "rcm/<layer>/..."` or
`#include "<layer>/..."` (also with <...>) of every C/C++ file under include/,
src/, apps/, python/, ros/, dds/ and examples/ is checked.
An include of a layer above the file's own, of another top-level part, or of
an rcm/<name>/ that is not a layer fails with FILE:LINE.

Known violations are listed in ALLOWED, one line each with the reason; an
entry that no longer occurs fails too, so that the list stays true.

Usage: check_layers.py [--root DIR] [--self-test]
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile

LIBRARY = ["common", "kinematics", "io", "dynamics", "force", "tissue", "estimation", "live", "sim"]
TOP = ["apps", "python", "ros", "dds", "examples"]
RANK = {name: i for i, name in enumerate(LIBRARY)}
RANK.update({name: len(LIBRARY) for name in TOP})

SCANNED = ("include/", "src/", "apps/", "python/", "ros/", "dds/", "examples/")
SOURCE_SUFFIXES = (".h", ".hh", ".hpp", ".hxx", ".c", ".cc", ".cpp", ".cxx", ".ipp", ".inl")

# (file, included layer): why the include is allowed for now. Keep one line
# per file and layer, and remove the entry when the include goes.
ALLOWED = {
    # The CLI reads ROS 1 bags through the rcm::ros library (ros/, needs
    # roscpp and rosbag), compiled in only with RCM_WITH_ROS; the reader has no
    # home in the library, which does not depend on ROS.
    ("apps/rcm/cmd_convert.cpp", "ros"):
        "rcm convert reads .bag files with rcm::load_bag_recording (ros/bag_reader.hpp)",
    ("apps/rcm/message_cli.cpp", "ros"):
        "the CLI registers the .bag reader and its --topic options (ros/bag_reader.hpp)",
}

INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^">]+)[">]')


def layer_of_file(rel):
    parts = rel.split("/")
    if parts[0] == "include" and len(parts) > 3 and parts[1] == "rcm":
        return parts[2]
    if parts[0] == "src" and len(parts) > 2:
        return parts[1]
    if parts[0] in TOP:
        return parts[0]
    return None


def layer_of_include(target):
    """The layer an include names, None when it names none (a system header,
    a file beside the includer), or ("?", name) for an unknown rcm/<name>/."""
    path = target
    while path.startswith("../"):
        path = path[3:]
    for prefix in ("include/", "src/"):
        if path.startswith(prefix):
            path = path[len(prefix):]
    parts = path.split("/")
    if len(parts) >= 3 and parts[0] == "rcm":
        return parts[1] if parts[1] in RANK else ("?", parts[1])
    if len(parts) >= 2 and parts[0] in LIBRARY:
        return parts[0]
    return None


def list_files(root):
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z", "--"] + list(SCANNED), check=True,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL).stdout
        files = [f for f in out.decode("utf-8", "replace").split("\0") if f]
        if files:
            return files
    except (OSError, subprocess.CalledProcessError):
        pass
    files = []
    for top in SCANNED:
        for d, dirs, names in os.walk(os.path.join(root, top)):
            dirs[:] = [x for x in dirs if not x.startswith("build") and x != ".git"]
            files += [os.path.relpath(os.path.join(d, n), root) for n in names]
    return files


def check(root, allowed):
    problems, used = [], set()
    for rel in sorted(f.replace(os.sep, "/") for f in list_files(root)):
        if not rel.endswith(SOURCE_SUFFIXES):
            continue
        own = layer_of_file(rel)
        if own is None:
            continue
        if own not in RANK:
            problems.append(f"{rel}: directory '{own}' is not a layer (add it to check_layers.py and docs/architecture.md)")
            continue
        with open(os.path.join(root, rel), encoding="utf-8", errors="replace") as f:
            for number, line in enumerate(f, 1):
                m = INCLUDE.match(line)
                if not m:
                    continue
                target = layer_of_include(m.group(1))
                if target is None or target == own:
                    continue
                if isinstance(target, tuple):
                    problems.append(f"{rel}:{number}: includes \"{m.group(1)}\": rcm/{target[1]}/ is not a layer")
                    continue
                if RANK[target] < RANK[own]:
                    continue
                if (rel, target) in allowed:
                    used.add((rel, target))
                    continue
                where = "above it" if RANK[target] > RANK[own] else "beside it at the top"
                problems.append(f"{rel}:{number}: layer '{own}' includes \"{m.group(1)}\" of layer '{target}', {where}")
    for key in sorted(set(allowed) - used):
        problems.append(f"{key[0]}: allowed include of layer '{key[1]}' no longer occurs; remove it from ALLOWED")
    return problems


def self_test():
    tree = {
        "include/rcm/common/a.hpp": "#include <vector>\n",
        "include/rcm/io/b.hpp": '#include "rcm/common/a.hpp"\n#include "rcm/kinematics/k.hpp"\n',
        "include/rcm/kinematics/k.hpp": '#include "rcm/io/b.hpp"\n',          # planted: io above kinematics
        "src/dynamics/d.cpp": '#include "io/rosbag2/cdr.hpp"\n#include "kernels.hpp"\n',
        "src/force/f.cpp": '#include <rcm/estimation/e.hpp>\n',             # planted: estimation above force
        "apps/rcm/main.cpp": '#include "rcm/sim/bench.hpp"\n#include "rcm/ros/bag.hpp"\n',  # planted: top to top
        "dds/node/n.cpp": '#include "rcm/live/monitor_node.hpp"\n#include "rcm/gui/w.hpp"\n',  # planted: no layer
        "src/io/allowed.cpp": '#include "rcm/sim/x.hpp"\n',                 # allowed below
    }
    expected = ["include/rcm/kinematics/k.hpp:1:", "src/force/f.cpp:1:", "apps/rcm/main.cpp:2:",
                "dds/node/n.cpp:2:", "src/io/gone.cpp: allowed include"]
    allowed = {("src/io/allowed.cpp", "sim"): "test", ("src/io/gone.cpp", "sim"): "stale"}
    with tempfile.TemporaryDirectory() as tmp:
        for rel, text in tree.items():
            path = os.path.join(tmp, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w") as f:
                f.write(text)
        problems = check(tmp, allowed)
    for p in problems:
        print(p)
    missed = [e for e in expected if not any(p.startswith(e) for p in problems)]
    if missed or len(problems) != len(expected):
        print(f"self-test FAILED: expected {len(expected)} problems, got {len(problems)}; missed {missed}")
        return 1
    print(f"self-test passed: {len(expected)} planted problems found, nothing else")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    problems = check(os.path.abspath(args.root), ALLOWED)
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} layer problem(s); the rule and the layers: docs/architecture.md")
        return 1
    print(f"every include respects the layers ({len(ALLOWED)} known exceptions, listed in {os.path.basename(__file__)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
