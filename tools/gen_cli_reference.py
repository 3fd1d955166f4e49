#!/usr/bin/env python3
"""Writes docs/cli.md, the command reference, from the programs themselves.

Every section comes from a program: each command and subcommand of `rcm`
(found in `rcm --help`, then in each command's own help), its `--help` with
every flag, default and unit (the study options are the footer of `rcm run
--help`, from their option tables), the `--help` of every other program in
PROGRAMS, and the fields of the model and results files that a quick study
writes. Nothing in the page is typed by hand.

    /usr/bin/python3 tools/gen_cli_reference.py --build build            # rewrite docs/cli.md
    /usr/bin/python3 tools/gen_cli_reference.py --build build --check    # fail if it differs

--study DIR takes the results.json and free_space_model.json of an `rcm run`
already made (the ctest passes the tutorial's); without it a quick study is
simulated and run in a temporary folder. A program in PROGRAMS that is not
built keeps its section from the current page, and says so.
"""

import argparse
import difflib
import json
import os
import re
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "cli.md")

# Every program rcm installs, in the order of the page: (name, what it is).
# A new program gets one line here.
PROGRAMS = [
    ("rcm", "the command-line program: every offline step, from a simulated bench to a study"),
    ("rcm_monitor_node", "the online estimator on a live dVRK over ROS 1 (built with ROS 1)"),
    ("rcm_monitor_dds", "the online estimator on a live dVRK over ROS 2, on Cyclone DDS (built with Cyclone DDS)"),
]

HEADER = """# Command reference

Every program, command and flag of rcm, with its default and unit, and the
fields of the files rcm writes. This page is written by
`tools/gen_cli_reference.py` from the programs' own `--help` and from the
files of a quick study; `make docs-cli` rewrites it, and the ctest
`docs_cli_reference` fails when it and the programs disagree. Do not edit it
by hand. What the files mean: [formats.md](formats.md).
"""


def run_help(binary, args):
    out = subprocess.run([binary] + args + ["--help"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True, timeout=60)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join([binary] + args)} --help: exit status {out.returncode}\n{out.stdout}")
    # A program that names itself by argv[0] prints the build's path: keep its name.
    text = out.stdout.replace(binary, os.path.basename(binary))
    return "\n".join(line.rstrip() for line in text.strip("\n").splitlines())


def subcommands(help_text):
    """The (name, description) of the `Subcommands:` section of CLI11's help."""
    found, inside = [], False
    for line in help_text.splitlines():
        if line.strip() == "Subcommands:":
            inside = True
            continue
        if inside:
            if not line.strip():
                if found:
                    break
                continue
            m = re.match(r"^  (\S+)\s*(.*)$", line)
            if not m:
                break
            if found and line.startswith("   ") and not m:
                continue
            found.append((m.group(1), m.group(2).strip()))
    return found


def program_sections(binary, name):
    """(heading, summary, help) for the program and each of its commands, depth first."""
    sections = []

    def walk(path, summary):
        text = run_help(binary, path)
        sections.append((" ".join([name] + path), summary, text))
        for sub, what in subcommands(text):
            walk(path + [sub], what)

    walk([], "")
    return sections


def json_fields(value, path="", out=None):
    """{field path: set of JSON types}; arrays of objects as `name[]`."""
    if out is None:
        out = {}

    def kind(v):
        if isinstance(v, bool):
            return "true|false"
        if isinstance(v, (int, float)):
            return "number"
        if isinstance(v, str):
            return "text"
        if v is None:
            return "null"
        if isinstance(v, dict):
            return "object"
        inner = sorted({kind(e) for e in v})
        return "array" + (" of " + "|".join(inner) if inner else "")

    if isinstance(value, dict):
        for k, v in value.items():
            p = f"{path}.{k}" if path else k
            out.setdefault(p, set()).add(kind(v))
            if isinstance(v, dict):
                json_fields(v, p, out)
            elif isinstance(v, list) and any(isinstance(e, dict) for e in v):
                for e in v:
                    if isinstance(e, dict):
                        json_fields(e, p + "[]", out)
    return out


def field_block(path):
    with open(path) as f:
        fields = json_fields(json.load(f))
    width = max(len(p) for p in fields) + 2
    lines = [f"{p.ljust(width)}{' or '.join(sorted(t))}" for p, t in fields.items()]
    return "```text\n" + "\n".join(lines) + "\n```"


def make_study(rcm_binary, work):
    subprocess.run([rcm_binary, "simulate", "--quick", "--seed", "1", "--out", os.path.join(work, "bench")],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    subprocess.run([rcm_binary, "run", os.path.join(work, "bench", "session.json"), "--out",
                    os.path.join(work, "study")], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return os.path.join(work, "study")


def old_sections(text):
    """The current page's program sections, by program, to keep those of programs not built."""
    kept = {}
    for name, _ in PROGRAMS:
        m = re.search(rf"(<!-- program:{re.escape(name)}:begin -->.*?<!-- program:{re.escape(name)}:end -->)",
                      text, re.S)
        if m:
            kept[name] = m.group(1)
    return kept


def generate(build, study_dir, current):
    parts = [HEADER]
    rows = ["| program or command | what it does |", "|---|---|"]
    bodies, missing = [], []
    kept = old_sections(current)
    for name, what in PROGRAMS:
        binary = os.path.join(build, "bin", name)
        if not os.path.exists(binary):
            missing.append(name)
            if name in kept:
                bodies.append(kept[name])
                for heading, summary in re.findall(r"^## (.+)\n\n(.*)$", kept[name], re.M):
                    rows.append(f"| [`{heading}`](#{slug(heading)}) | {summary} |")
            continue
        sections = program_sections(binary, name)
        body = [f"<!-- program:{name}:begin -->"]
        for k, (heading, summary, text) in enumerate(sections):
            summary = summary or what
            rows.append(f"| [`{heading}`](#{slug(heading)}) | {summary} |")
            body.append(f"## {heading}\n\n{summary}\n\n```text\n{text}\n```\n")
        body.append(f"<!-- program:{name}:end -->")
        bodies.append("\n".join(body))
    parts.append("\n".join(rows) + "\n")
    parts += bodies
    parts.append("## Model file (rcm-torque-model/1)\n\nThe fields of `free_space_model.json` (the default "
                 "`linear` kind), as `rcm setup`, `rcm run` and `rcm dynamics fit` write it. Arrays of numbers are "
                 "stored as `{shape, dtype, data}` with the data in base64.\n\n"
                 + field_block(os.path.join(study_dir, "free_space_model.json")) + "\n")
    parts.append("## Results file (rcm-results/1)\n\nThe fields of `results.json`, as `rcm run` writes it with its "
                 "defaults (joint method, three-step beside it), and `rcm run --json` prints it.\n\n"
                 + field_block(os.path.join(study_dir, "results.json")) + "\n")
    return "\n".join(parts), missing


def slug(heading):
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"), help="build folder whose bin/ holds the programs")
    ap.add_argument("--study", help="folder with results.json and free_space_model.json of an `rcm run`")
    ap.add_argument("--check", action="store_true", help="compare with docs/cli.md instead of writing it")
    ap.add_argument("--doc", default=DOC, help="the page (default docs/cli.md)")
    args = ap.parse_args()
    current = open(args.doc).read() if os.path.exists(args.doc) else ""
    with tempfile.TemporaryDirectory() as work:
        study = args.study or make_study(os.path.join(args.build, "bin", "rcm"), work)
        text, missing = generate(args.build, study, current)
    for name in missing:
        print(f"{name}: not built here; its section is kept as it was, unchecked", file=sys.stderr)
    if args.check:
        if text == current:
            print(f"{os.path.relpath(args.doc, ROOT)} agrees with the programs")
            return 0
        diff = difflib.unified_diff(current.splitlines(), text.splitlines(), "docs/cli.md", "the programs",
                                    lineterm="", n=1)
        print("\n".join(list(diff)[:200]))
        print(f"{os.path.relpath(args.doc, ROOT)} differs from the programs: rerun `make docs-cli` and commit it")
        return 1
    tmp = args.doc + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, args.doc)
    print(f"wrote {os.path.relpath(args.doc, ROOT)} ({len(text.encode()) / 1024:.1f} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
