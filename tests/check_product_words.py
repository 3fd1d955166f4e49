#!/usr/bin/env python3
"""The product speaks of itself alone.

Scans every tracked text file of the repository (`git ls-files`; without git,
a directory walk that skips build directories) for

  (a) words that tell the story of how the product was made instead of what it
      is: a numbered working session or issue, "the brief", the names of the
      tools it was developed with, and references to the specification files
      that live outside the repository (docs/formats.md is the product's own);
  (b) paths outside the repository: absolute paths into a developer's machine
      (/work/, /home/, /root/) and relative paths whose "../" steps climb out
      of the repository from the file that holds them.

Prints FILE:LINE: WHAT: TEXT for every hit and exits with status 1 when there
is one. `--self-test` plants one hit of each kind in a scratch tree and fails
unless every one is found.

Usage: check_product_words.py [--root DIR] [--self-test]

This file is not scanned: it has to name what it looks for, in its patterns and
in the hits its self-test plants. The development tools' names are still
assembled from pieces, so that they appear nowhere in the repository.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile

# (a) Development history. Case-insensitive; each with what it means.
HISTORY_PATTERNS = [
    (r"\bsession [0-9]+\b", "a numbered working session"),
    (r"\bissue [0-9#]", "a numbered issue"),
    (r"\bissue" + "'s\\b", "an issue's wording"),
    (r"\bthe " + "brief\\b", "the working brief"),
    (r"\bfarm" + "-(studio|bench)\\b", "a development tool"),
    (r"`(" + "dupli" + "cates|" + "iss" + "ues)`", "a development tool's command"),
    (r"\b(" + "dupli" + "cates|" + "iss" + "ues) (command|tool)\b", "a development tool's command"),
    (r"shared" + "/spec", "the specification outside the repository (use docs/formats.md)"),
    (r"\.\./" + "shared\\b", "a path outside the repository"),
]

# (b) Absolute paths into a developer's machine. /tmp and system paths such as
# /usr/bin/python3 are legitimate instructions and are not flagged.
ABSOLUTE_PATH = re.compile(r"(?<![A-Za-z0-9_.~-])/(" + "work|home|root" + r")/[A-Za-z0-9_.-]+")
RELATIVE_UP = re.compile(r"(?<![A-Za-z0-9_.])((?:\.\./)+)")

# What starts a continued line: indentation and comment or list markers.
CONTINUATION = re.compile(r"^[\s/#*>-]*")

SKIP_SUFFIXES = (".csv", ".mcap", ".db3", ".bag", ".png", ".svg", ".pdf", ".pt", ".zst", ".lz4")
# This file, relative to the repository root (see the docstring).
SELF = "tests/" + os.path.basename(__file__)

SKIP_DIRS = {".git", "node_modules", "__pycache__", "demo-out"}


def list_files(root):
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z"], check=True,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL).stdout
        files = [f for f in out.decode("utf-8", "replace").split("\0") if f]
        if files:
            return files
    except (OSError, subprocess.CalledProcessError):
        pass
    files = []
    for d, dirs, names in os.walk(root):
        # What .gitignore leaves out: build trees and the outputs of make demo.
        dirs[:] = [x for x in dirs if x not in SKIP_DIRS and not x.startswith(("build", "out"))]
        for n in names:
            files.append(os.path.relpath(os.path.join(d, n), root))
    return files


def read_text(path):
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError:
        return None
    if b"\0" in data:
        return None
    return data.decode("utf-8", "replace")


def escapes_root(rel_file, ups):
    """True when `ups` ("../" repeated) climbs above the repository root from
    the directory of `rel_file` (a path relative to the root)."""
    depth = len([p for p in os.path.dirname(rel_file).split("/") if p])
    return ups.count("../") > depth


def scan(root):
    history = [(re.compile(p, re.IGNORECASE), why) for p, why in HISTORY_PATTERNS]
    hits = []
    for rel in sorted(list_files(root)):
        rel = rel.replace(os.sep, "/")
        if rel.lower().endswith(SKIP_SUFFIXES) or rel == SELF:
            continue
        text = read_text(os.path.join(root, rel))
        if text is None:
            continue
        lines = text.splitlines()
        for number, line in enumerate(lines, 1):
            # A phrase may be wrapped onto the next line (of prose or of a
            # comment): the line is also read joined to the start of the next.
            following = lines[number] if number < len(lines) else ""
            joined = line.rstrip() + " " + CONTINUATION.sub("", following)
            for rx, why in history:
                m = rx.search(line)
                if m is None:
                    m = rx.search(joined)
                    if m is not None and m.start() >= len(line.rstrip()):
                        m = None  # wholly on the next line: reported there
                if m is not None:
                    hits.append((rel, number, why, line.strip()))
            if ABSOLUTE_PATH.search(line):
                hits.append((rel, number, "an absolute path outside the repository", line.strip()))
            for m in RELATIVE_UP.finditer(line):
                if escapes_root(rel, m.group(1)):
                    hits.append((rel, number, "a relative path that leaves the repository", line.strip()))
                    break
    return hits


def report(hits):
    for rel, number, why, text in hits:
        print(f"{rel}:{number}: {why}: {text[:160]}")


def self_test():
    planted = {
        "README.md": "Measured in " + "session " + "8 of the work.\n",
        "docs/a.md": "As " + "issue " + "7 asks.\n",
        "docs/b.md": "The " + "issue" + "'s targets.\n",
        "src/c.cpp": "// what " + "the " + "brief says\n",
        "src/d.cpp": "// run farm" + "-studio first\n",
        "e.md": "run `" + "dupli" + "cates` on it\n",
        "f.md": "[spec](../" + "shared/spec/x.md)\n",
        "g/h.md": "see /" + "work/main/x\n",
        "g/i.md": "see ../../" + "outside.txt\n",
        "j.cpp": "// the inertias of the\n// " + "brief at q0\n",
    }
    clean = {
        "ok/a.md": "A bench session writes rcm-session/1; `--sessions 50`; 12 duplicates dropped.\n",
        "ok/b/c.cpp": "#include \"../d.hpp\"  // /usr/bin/python3, /tmp/x\n",
    }
    with tempfile.TemporaryDirectory() as tmp:
        for rel, text in {**planted, **clean}.items():
            path = os.path.join(tmp, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w") as f:
                f.write(text)
        hits = scan(tmp)
    found = {h[0] for h in hits}
    missed = sorted(set(planted) - found)
    false = sorted(found - set(planted))
    report(hits)
    if missed or false:
        print(f"self-test FAILED: missed {missed}, flagged clean {false}")
        return 1
    print(f"self-test passed: {len(planted)} planted hits found, clean files not flagged")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    root = os.path.abspath(args.root)
    hits = scan(root)
    report(hits)
    if hits:
        print(f"{len(hits)} line(s) speak of how the product was made or point outside the repository")
        return 1
    print("no development-history words and no paths outside the repository")
    return 0


if __name__ == "__main__":
    sys.exit(main())
