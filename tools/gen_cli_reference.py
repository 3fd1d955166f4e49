#!/usr/bin/env python3
"""Writes docs/cli.md and docs/cli-files.md, the reference, from the programs themselves.

Every section comes from a program: each command and subcommand of `rcm`
(found in `rcm --help`, then in each command's own help), its `--help` with
every flag, default and unit (the study options are the footer of `rcm run
--help`, from their option tables), the `--help` of every other program in
PROGRAMS, and the fields of the model and results files that a quick study
writes. The study options and the files' fields go on docs/cli-files.md, the
rest on docs/cli.md. Nothing in either page is typed by hand.

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
FILES_DOC = os.path.join(ROOT, "docs", "cli-files.md")

# Every program rcm installs, in the order of the page: (name, what it is).
# A new program gets one line here.
PROGRAMS = [
    ("rcm", "the command-line program: every offline step, from a simulated bench to a study"),
    ("rcm_monitor_node", "the online estimator on a live dVRK over ROS 1 (built with ROS 1)"),
    ("rcm_monitor_dds", "the online estimator on a live dVRK over ROS 2, on Cyclone DDS (built with Cyclone DDS)"),
    ("rcm_procedure_dds", "docking to the first estimate on a CRTK arm over ROS 2 (built with Cyclone DDS)"),
    ("rcm_play_dds", "plays a joint trajectory on a CRTK arm over ROS 2 and records it (built with Cyclone DDS)"),
    ("rcm_sim_psm_dds", "a simulated dVRK Classic PSM on CRTK topics over ROS 2 (built with Cyclone DDS)"),
]

HEADER = """# Command reference

Every program, command and flag of rcm, with its default and unit. This page
and [cli-files.md](cli-files.md) (the study options and the fields of the
files rcm writes) are written by `tools/gen_cli_reference.py` from the
programs' own `--help` and from the files of the tutorial's study; `make
docs-cli` rewrites them, and the ctest `docs_cli_reference` fails when they
and the programs disagree. Do not edit them by hand.
"""

FILES_HEADER = """# Reference: options and files

The fields of the JSON files rcm reads and writes, from the programs
themselves: the study options (from their option tables, as `rcm run --help`
prints them), the free-space model file and the results file (from the
tutorial's study). Written by `tools/gen_cli_reference.py`, with
[cli.md](cli.md); what the files mean: [formats.md](formats.md).
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


# Sections of a help that the page names instead of printing: the simulator's
# configuration keys are a file's fields, not flags, and fill pages; the study
# options, which three commands print alike, are on docs/cli-files.md.
NAMED_SECTIONS = {
    "Configuration (--config FILE": "  (every key with its default: `rcm simulate --help` or `rcm simulate --print-config`)",
    "Study options (--options FILE": "  (every field with its default and unit: docs/cli-files.md, \"Study options\")",
}
STUDY_OPTIONS = "Study options (--options FILE"


def compact(text, heading, seen):
    """The help as the page prints it: a section that an earlier command printed alike (the study
    options of `--options FILE`, the bag flags) is named, not repeated; the padding that aligns
    CLI11's columns is cut to two spaces, a wrapped line's indent to six."""
    sections, current = [], []
    for line in text.splitlines():
        if not line.strip():
            if current:
                sections.append(current)
            current = []
            continue
        current.append(line)
    if current:
        sections.append(current)
    out = []
    for lines in sections:
        body = "\n".join(lines)
        head = lines[0]
        if head == "Subcommands:":  # each has its own section: name them only
            out.append("Subcommands (each below): " + ", ".join(l.split()[0] for l in lines[1:] if l.startswith("  ")
                                                                 and not l.startswith("    ")))
            continue
        named = next((v for k, v in NAMED_SECTIONS.items() if head.startswith(k)), None)
        if head.startswith(STUDY_OPTIONS):
            seen.setdefault(STUDY_OPTIONS, "\n".join(re.sub(r"(?<=\S) {3,}", "  ", l) for l in lines[1:]))
        if named is not None:
            out.append("\n".join([head.rstrip(":") + ":" if head.endswith(":") else head, named]))
            continue
        if head.endswith(":") and not head.startswith(" ") and len(lines) > 3:
            if body in seen:
                out.append(f"{head}\n  (the same as under `{seen[body]}`)")
                continue
            seen[body] = heading
        out.append("\n".join(re.sub(r"(?<=\S) {3,}", "  ", re.sub(r"^ {7,}", "      ", l)) for l in lines
                             if l.split() != ["-h,--help", "Print", "this", "help", "message", "and", "exit"]))
    return "\n\n".join(out)


def is_array_record(v):
    return isinstance(v, dict) and set(v) == {"shape", "dtype", "data"}


def json_objects(value, path, out):
    """{object path: {field: set of kinds}}, each object once; the elements of an array of objects
    merged under `name[]`. Kinds: number, text, true|false, null, [] (array), {} (object)."""
    fields = out.setdefault(path, {})
    for k, v in value.items():
        if is_array_record(v):
            kind = "[]"
        elif isinstance(v, dict):
            kind = "{}"
            json_objects(v, f"{path}.{k}" if path else k, out)
        elif isinstance(v, list):
            kind = "[]"
            for e in v:
                if isinstance(e, dict) and not is_array_record(e):
                    kind = "[{}]"
                    json_objects(e, (f"{path}.{k}" if path else k) + "[]", out)
        elif isinstance(v, bool):
            kind = "true|false"
        elif isinstance(v, (int, float)):
            kind = "number"
        elif isinstance(v, str):
            kind = "text"
        else:
            kind = "null"
        fields.setdefault(k, set()).add(kind)
    return out


def describe_field(name, kinds):
    kinds = set(kinds)
    null = "null" in kinds and len(kinds) > 1
    kinds.discard("null") if null else None
    if kinds == {"number"}:
        text = name
    elif kinds == {"[]"}:
        text = name + "[]"
    elif kinds <= {"{}", "[{}]"}:
        text = name + ("[{}]" if "[{}]" in kinds else "{}")
    else:
        text = f"{name} ({'|'.join(sorted(kinds))})"
    return text + (" or null" if null else "")


def field_block(path):
    """One line per object of the file: its path, then its fields (a number unless marked: `x[]`
    an array, `x{}` an object listed on its own line, `x[{}]` an array of objects, `(text)`)."""
    with open(path) as f:
        objects = json_objects(json.load(f), "", {})
    lines, first = [], {}
    for obj, fields in objects.items():
        listed = ", ".join(describe_field(k, v) for k, v in fields.items())
        if listed in first:  # an object laid out as an earlier one (a solver report, an error summary)
            lines.append(f"{obj or '(top level)'}: as {first[listed]}")
            continue
        first[listed] = obj
        lines.append(f"{obj or '(top level)'}: {listed}")
    return "```text\n" + "\n".join(lines) + "\n```"


def make_study(build, work):
    """The tutorial's study, made by running the tutorial (the ctest passes the one it made)."""
    subprocess.run([sys.executable, os.path.join(ROOT, "tests", "check_tutorial.py"), "--build", build,
                    "--work", work], check=True, stdout=subprocess.DEVNULL)
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
    bodies, missing = [], []
    seen = {}
    kept = old_sections(current)
    for name, what in PROGRAMS:
        binary = os.path.join(build, "bin", name)
        if not os.path.exists(binary):
            missing.append(name)
            if name in kept:
                bodies.append(kept[name])
            continue
        # A command whose help holds only its subcommands has no section of its own.
        sections = [sec for sec in program_sections(binary, name)
                    if not (sec[0] != name and "Options:" not in sec[2].replace("Options:\n  -h,--help", "")
                            and "Subcommands:" in sec[2] and "Positionals:" not in sec[2])]
        body = [f"<!-- program:{name}:begin -->"]
        for k, (heading, summary, text) in enumerate(sections):
            text = compact(text, heading, seen)
            summary = summary or what
            if text.splitlines()[0].strip() == summary.strip():
                text = "\n".join(text.splitlines()[1:])
            body.append(f"## {heading}\n\n{summary}\n\n```text\n{text}\n```\n")
        body.append(f"<!-- program:{name}:end -->")
        bodies.append("\n".join(body))
    files = [FILES_HEADER]
    if STUDY_OPTIONS in seen:
        files.append("## Study options (`--options FILE`)\n\nA JSON object of any of these fields, nested as "
                     "the dots say, read by `rcm run`, `rcm setup` and `rcm monitor` (`--options FILE`; the flags "
                     "override it); the same fields are Python's `rcm.StudyOptions`. Each line: the field, what it "
                     "is (unit; limits) [type, default].\n\n```text\n" + seen[STUDY_OPTIONS] + "\n```\n")
    legend = ("One line per object: its path, then its fields. A field is a number unless marked: `x[]` an "
              "array, `x{}` an object with a line of its own, `x[{}]` an array of objects (`x[]` on its line), "
              "`(text)`, `(true|false)`; `or null` when it may be absent.")
    files.append("## Model file (rcm-torque-model/1)\n\nThe fields of `free_space_model.json` (the default "
                 "`linear` kind), as `rcm setup`, `rcm run` and `rcm dynamics fit` write it; arrays of numbers are "
                 "stored as `{shape, dtype, data}`, the data in base64 ([formats.md](formats.md)). " + legend + "\n\n"
                 + field_block(os.path.join(study_dir, "free_space_model.json")) + "\n")
    files.append("## Results file (rcm-results/1)\n\nThe fields of `results.json`, as `rcm run` writes it with its "
                 "defaults (joint method, three-step beside it) and `rcm run --json` prints it. Units are SI "
                 "(m, N, N m, s). The contract's fields: [formats.md](formats.md#results-rcm-results1).\n\n"
                 + field_block(os.path.join(study_dir, "results.json")) + "\n")
    return "\n".join([HEADER] + bodies), "\n".join(files), missing


def slug(heading):
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"), help="build folder whose bin/ holds the programs")
    ap.add_argument("--study", help="folder with results.json and free_space_model.json of the tutorial's study")
    ap.add_argument("--check", action="store_true", help="compare with the pages instead of writing them")
    args = ap.parse_args()
    current = {doc: open(doc).read() if os.path.exists(doc) else "" for doc in (DOC, FILES_DOC)}
    with tempfile.TemporaryDirectory() as work:
        study = args.study or make_study(args.build, os.path.join(work, "tutorial"))
        cli, files, missing = generate(args.build, study, current[DOC])
    for name in missing:
        print(f"{name}: not built here; its section is kept as it was, unchecked", file=sys.stderr)
    status = 0
    for doc, text in ((DOC, cli), (FILES_DOC, files)):
        rel = os.path.relpath(doc, ROOT)
        if args.check:
            if text == current[doc]:
                print(f"{rel} agrees with the programs")
                continue
            diff = difflib.unified_diff(current[doc].splitlines(), text.splitlines(), rel, "the programs",
                                        lineterm="", n=1)
            print("\n".join(list(diff)[:200]))
            print(f"{rel} differs from the programs: run `make docs-cli` and commit it")
            status = 1
            continue
        with open(doc + ".tmp", "w") as f:
            f.write(text)
        os.replace(doc + ".tmp", doc)
        print(f"wrote {rel} ({len(text.encode()) / 1024:.1f} KB)")
    return status


if __name__ == "__main__":
    sys.exit(main())
