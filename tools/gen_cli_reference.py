#!/usr/bin/env python3
"""Writes the reference pages docs/cli.md, docs/cli-programs.md and docs/cli-files.md from the programs.

Every section comes from a program: each command and subcommand of `rcm`
(found in `rcm --help`, then in each command's own help), its `--help` with
every flag, default and unit (the study options are the footer of `rcm run
--help`, from their option tables), the `--help` of every other program in
PROGRAMS, and the fields of the model and results files that a quick study
writes. `rcm` goes on docs/cli.md, the other programs (the nodes, the DDS
tools) on docs/cli-programs.md, the study options and the files' fields on
docs/cli-files.md. Nothing in them is typed by hand.

    /usr/bin/python3 tools/gen_cli_reference.py --build build            # rewrite the pages
    /usr/bin/python3 tools/gen_cli_reference.py --build build --check    # fail if one differs

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
PROGRAMS_DOC = os.path.join(ROOT, "docs", "cli-programs.md")
FILES_DOC = os.path.join(ROOT, "docs", "cli-files.md")

# Every program rcm installs, in the order of the pages: (name, when it is built). The first
# goes on docs/cli.md, the others on docs/cli-programs.md. A new program gets one line here.
PROGRAMS = [
    ("rcm", "always"),
    ("rcm_monitor_node", "with ROS 1"),
    ("rcm_monitor_dds", "with Cyclone DDS"),
    ("rcm_procedure_dds", "with Cyclone DDS"),
    ("rcm_play_dds", "with Cyclone DDS"),
    ("rcm_sim_psm_dds", "with Cyclone DDS"),
]

GENERATED = """Written by `tools/gen_cli_reference.py` from the programs' `--help` (`make docs-cli`); the
ctest `docs_cli_reference` fails when they disagree. Do not edit by hand."""

HEADER = """# Command reference: `rcm`

Every command and flag of `rcm`, with its default and unit. The live nodes and
the DDS tools: [cli-programs.md](cli-programs.md). The study options and the
files' fields: [cli-files.md](cli-files.md).
""" + GENERATED + "\n"

PROGRAMS_HEADER = """# Command reference: the nodes and DDS tools

Every flag or parameter of the live nodes and the ROS 2 (DDS) tools, with its
default and unit. `rcm` itself: [cli.md](cli.md).
""" + GENERATED + "\n"

FILES_HEADER = """# Reference: options and files

The study options (from their option tables) and the fields of the model and
results files (from the tutorial's study). Written by
`tools/gen_cli_reference.py`, with [cli.md](cli.md); what the files mean:
[formats.md](formats.md).
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
    "Configuration (--config FILE": "Configuration (--config FILE): every key with its default: `rcm simulate --help` or `--print-config`",
    "Study options (--options FILE": "Study options (--options FILE): every field with its default and unit: docs/cli-files.md",
}
STUDY_OPTIONS = "Study options (--options FILE"


def compact(text, heading, seen):
    """The help as the page prints it: a section or a flag that an earlier command printed alike (the
    study options of `--options FILE`, the bag flags, the seed) is named, not repeated; the padding
    that aligns CLI11's columns is cut to two spaces, a wrapped line's indent to six."""
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
            seen.setdefault(STUDY_OPTIONS, "\n".join(implied_type(dedent(re.sub(r"(?<=\S) {3,}", "  ", l)))
                                                     for l in lines[1:]))
        if named is not None:
            out.append(named)
            continue
        if head.endswith(":") and not head.startswith(" ") and len(lines) > 3:
            if body in seen:
                out.append(f"{head} as under `{seen[body]}`")
                continue
            seen[body] = heading
        lines = [re.sub(r"(?<=\S) {3,}", "  ", re.sub(r"^ {7,}", "      ", l)) for l in lines
                 if l.split() != ["-h,--help", "Print", "this", "help", "message", "and", "exit"]]
        out.append("\n".join(name_repeated_flags(lines, heading, seen)))
    return "\n\n".join(out)


def name_repeated_flags(lines, heading, seen):
    """A flag whose whole help an earlier section of the same page printed word for word (the seed,
    the model file, the DDS domain of several commands) keeps its name and type here and points
    there for its help, default and unit, when that is shorter."""
    entries = []
    for line in lines:
        if entries and re.match(r"^ {6}\S", line):  # a wrapped flag's help
            entries[-1].append(line)
        else:
            entries.append([line])
    page = "cli" if heading.split()[0] == PROGRAMS[0][0] else "programs"
    out = []
    for entry in entries:
        text = "\n".join(entry)
        m = re.match(r"^  (-\S+(?: [A-Z][A-Z:]*(?:=\S+)?)?)(?:  |\n|$)", text)
        key = ("flag", page, text)
        if m and key in seen:
            short = f"  {m.group(1)}  (as under `{seen[key]}`)"
            if len(short) + 20 < len(text):
                out.append(short)
                continue
        if m:
            seen.setdefault(key, heading)
        out.extend(entry)
    return out


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
    lines, first, alike = [], {}, {}
    for obj, fields in objects.items():
        listed = ", ".join(describe_field(k, v) for k, v in fields.items())
        if listed in first:  # an object laid out as an earlier one (a solver report, an error summary)
            alike.setdefault(first[listed], []).append(obj)
            continue
        first[listed] = obj
        lines.append((obj, f"{obj or '(top level)'}: {listed}"))
    out = []
    for obj, line in lines:
        out.append(line)
        if obj in alike:
            out.append(f"{', '.join(alike[obj])}: as {obj}")
    return "```text\n" + "\n".join(out) + "\n```"


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


IMPLIED_TYPES = {  # a default written so shows its type
    "number": r"-?\d+(\.\d+)?(e[-+]?\d+)?", "integer": r"-?\d+", "true|false": r"true|false", "text": r'".*"'}


def implied_type(line):
    """A study option's `[type, default V]` as `[default V]` when the default's form says the type: a number
    with a point or an exponent, an integer without, true or false, a quoted text."""
    m = re.search(r"\[(number|integer|true\|false|text), default (.*)\]$", line)
    if not m or not re.fullmatch(IMPLIED_TYPES[m.group(1)], m.group(2)):
        return line
    if m.group(1) == "number" and re.fullmatch(r"-?\d+", m.group(2)):
        return line  # an integer-looking default of a number field keeps its type
    return line[:m.start()] + f"[default {m.group(2)}]"


def dedent(line):
    """An entry of a help section (a flag, a parameter) starts the line, its wrapped help four spaces in:
    the section's heading, ending in a colon, says what the entries are."""
    return re.sub(r"^ {6}(?=\S)", "    ", re.sub(r"^  (?=\S)", "", line))


def usage_only(line, heading):
    """A usage line that says no more than the section's heading: the command takes flags only."""
    return line.strip() == f"Usage: {heading} [OPTIONS]"


def generate(build, study_dir, current):
    bodies, missing = {}, []
    seen = {}
    kept = old_sections(current)
    for name, built in PROGRAMS:
        binary = os.path.join(build, "bin", name)
        if not os.path.exists(binary):
            missing.append(name)
            if name in kept:
                bodies[name] = kept[name]
            continue
        # A command whose help holds only its subcommands has no section of its own.
        sections = [sec for sec in program_sections(binary, name)
                    if not (sec[0] != name and "Options:" not in sec[2].replace("Options:\n  -h,--help", "")
                            and "Subcommands:" in sec[2] and "Positionals:" not in sec[2])]
        body = [f"<!-- program:{name}:begin -->"]
        for heading, summary, text in sections:
            lines = compact(text, heading, seen).splitlines()
            if not summary:
                # A program's banner, "name: what it is" (rcm: "rcm VERSION -- what it is"), is its summary.
                banner = re.match(rf"^{re.escape(name)}(?::| \S+ --) (.*)$", lines[0])
                summary = banner.group(1) if banner else ""
                lines = lines[1:] if banner else lines
                if built != "always":
                    summary = (summary + f" (built {built})").strip()
            elif lines[0].strip() == summary.strip():
                lines = lines[1:]
            lines = [dedent(l) for l in lines if not usage_only(l, heading)]
            while lines and not lines[0].strip():
                lines = lines[1:]
            body.append(f"## {heading}\n\n{summary}\n\n```text\n" + "\n".join(lines) + "\n```\n")
        body.append(f"<!-- program:{name}:end -->")
        bodies[name] = "\n".join(body)
    files = [FILES_HEADER]
    if STUDY_OPTIONS in seen:
        files.append("## Study options (`--options FILE`)\n\nAny of these fields, nested as the dots say, for "
                     "`rcm run`, `rcm setup`, `rcm monitor` and Python's `rcm.StudyOptions`. Each line: the field, "
                     "what it is (unit; limits) [type, default]; the type goes unsaid where the default shows it "
                     "(`2.0` a number, `2` an integer).\n\n```text\n" + seen[STUDY_OPTIONS] + "\n```\n")
    legend = ("One line per object: its path, then its fields, numbers unless marked: `x[]` an array, `x{}` "
              "an object (its own line), `x[{}]` an array of objects, `(text)`, `(true|false)`, `or null`.")
    files.append("## Model file (rcm-torque-model/1)\n\n`free_space_model.json` of the default `linear` kind; arrays "
                 "of numbers are `{shape, dtype, data}` ([formats.md](formats.md)). " + legend + "\n\n"
                 + field_block(os.path.join(study_dir, "free_space_model.json")) + "\n")
    files.append("## Results file (rcm-results/1)\n\nThe fields of `results.json` from `rcm run` with its "
                 "defaults. Units are SI (m, N, N m, s). The contract's fields: "
                 "[formats.md](formats.md#results-rcm-results1).\n\n"
                 + field_block(os.path.join(study_dir, "results.json")) + "\n")
    first = [PROGRAMS[0][0]]
    others = [name for name, _ in PROGRAMS[1:]]
    return ("\n".join([HEADER] + [bodies[n] for n in first if n in bodies]),
            "\n".join([PROGRAMS_HEADER] + [bodies[n] for n in others if n in bodies]), "\n".join(files), missing)


def slug(heading):
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"), help="build folder whose bin/ holds the programs")
    ap.add_argument("--study", help="folder with results.json and free_space_model.json of the tutorial's study")
    ap.add_argument("--check", action="store_true", help="compare with the pages instead of writing them")
    args = ap.parse_args()
    current = {doc: open(doc).read() if os.path.exists(doc) else "" for doc in (DOC, PROGRAMS_DOC, FILES_DOC)}
    with tempfile.TemporaryDirectory() as work:
        study = args.study or make_study(args.build, os.path.join(work, "tutorial"))
        cli, programs, files, missing = generate(args.build, study, current[DOC] + current[PROGRAMS_DOC])
    for name in missing:
        print(f"{name}: not built here; its section is kept as it was, unchecked", file=sys.stderr)
    status = 0
    for doc, text in ((DOC, cli), (PROGRAMS_DOC, programs), (FILES_DOC, files)):
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
