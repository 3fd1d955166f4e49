#!/usr/bin/env python3
"""The tutorial runs: every command of docs/tutorial.md, in a scratch folder.

The tutorial's ```sh blocks are run in order, each as one bash script (`set -e
-o pipefail`), in one working folder, with the build's programs first on PATH. A
block preceded by the comment
`<!-- tutorial: not run ... -->` is skipped (it needs the reader's own robot or
recordings; the comment says why). Every block that runs must be followed by
a ```text block, what the reader should see. Every line of it but `...` must
match a line the block printed, with any number in it standing for any number:
the wording and layout may not drift from the program's. A command that
fails, or a line that matches nothing, fails the check with the block's line in
the page and its output. --update rewrites each of those lines with the line it
matched, so that the numbers the page shows come from a run, not from a hand.

Usage: check_tutorial.py --build DIR [--page docs/tutorial.md] [--work DIR] [--update] [--self-test]
--work keeps the outputs there (emptied first; the ctest keeps them for the
CLI reference's check); without it a temporary folder is used.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SKIP = re.compile(r"<!--\s*tutorial:\s*not run\b")


def parse(text):
    """[(line, kind, body, skipped)] of the fenced blocks, kind the info string."""
    blocks, lines, i, skip_next = [], text.splitlines(), 0, False
    while i < len(lines):
        line = lines[i]
        if SKIP.search(line):
            skip_next = True
        m = re.match(r"^```(\w*)\s*$", line)
        if m:
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            blocks.append((i + 1, m.group(1), "\n".join(lines[i + 1:j]), skip_next))
            skip_next = False
            i = j + 1
            continue
        i += 1
    return blocks


# A number, but not the digits of a name (D30_r10_15, effort_1), which stay as written.
NUMBER = re.compile(r"(?<![A-Za-z_])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![A-Za-z_\d])")


def line_pattern(line):
    """A regex for a shown line: its words as they are, any number for its numbers, any spacing."""
    parts, last = [], 0
    for m in NUMBER.finditer(line):
        parts.append(re.escape(line[last:m.start()]))
        parts.append(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
        last = m.end()
    parts.append(re.escape(line[last:]))
    pattern = "".join(parts)
    pattern = re.sub(r"(\\ )+", r"\\s+", pattern)
    return re.compile(r"^\s*" + pattern.strip() + r"\s*$")


def match_lines(shown, printed):
    """[(index in shown, the printed line it matches or None)] for each shown line but `...`."""
    out, start = [], 0
    lines = printed.splitlines()
    for k, line in enumerate(shown.splitlines()):
        if not line.strip() or line.strip() == "...":
            continue
        rx = line_pattern(line)
        hit = next((j for j in range(start, len(lines)) if rx.match(lines[j])), None)
        if hit is None:
            hit = next((j for j in range(0, len(lines)) if rx.match(lines[j])), None)
        out.append((k, lines[hit] if hit is not None else None))
        if hit is not None:
            start = hit + 1
    return out


def run_page(page, build, work, update=False):
    with open(page) as f:
        text = f.read()
    blocks = parse(text)
    env = dict(os.environ)
    env["PATH"] = os.path.join(os.path.abspath(build), "bin") + os.pathsep + env.get("PATH", "")
    env["PYTHONPATH"] = os.path.join(os.path.abspath(build), "python")
    problems, ran, skipped, total = [], 0, 0, 0.0
    page_lines = text.splitlines()
    for k, (line, kind, body, skip) in enumerate(blocks):
        if kind != "sh":
            continue
        if skip:
            skipped += 1
            continue
        follow = blocks[k + 1] if k + 1 < len(blocks) else None
        if follow is None or follow[1] != "text":
            problems.append(f"{page}:{line}: a command block without a ```text block after it (what the reader sees)")
        start = time.monotonic()
        out = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", body], cwd=work, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=600)
        seconds = time.monotonic() - start
        total += seconds
        ran += 1
        first = body.strip().splitlines()[0]
        print(f"{seconds:6.1f} s  {page}:{line}: {first}")
        if out.returncode != 0:
            problems.append(f"{page}:{line}: exit status {out.returncode}\n{body}\n--- output ---\n"
                            + "\n".join(out.stdout.splitlines()[-30:]))
            break
        if follow is not None and follow[1] == "text":
            for index, printed in match_lines(follow[2], out.stdout):
                at = follow[0] + 1 + index  # 1-based line of the shown line in the page
                if printed is None:
                    problems.append(f"{page}:{at}: the page shows '{page_lines[at - 1].strip()}', which matches no "
                                    f"line the command printed\n--- output ---\n"
                                    + "\n".join(out.stdout.splitlines()[-30:]))
                elif update:
                    page_lines[at - 1] = printed.rstrip()
    if update and not problems:
        with open(page + ".tmp", "w") as f:
            f.write("\n".join(page_lines) + "\n")
        os.replace(page + ".tmp", page)
        print(f"updated {page} with the lines of this run")
    print(f"{ran} blocks run in {total:.1f} s, {skipped} skipped (they need the reader's own robot or recordings)")
    return problems


def self_test():
    page = """# T

```sh
echo hello world
```

```text
hello world
```

<!-- tutorial: not run: needs a robot -->
```sh
false
```

```sh
echo something else
```

```text
what the page promised
```

```sh
echo "e = 0.17 mm over 3 trials"
```

```text
e = 9.5 mm over 12 trials
```

```sh
echo no output block
```

```sh
exit 3
```

```text
```
"""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "t.md")
        with open(path, "w") as f:
            f.write(page)
        problems = run_page(path, tmp, tmp)
    for p in problems:
        print(p)
    wanted = ["the page shows 'what the page promised'", "without a ```text block", "exit status 3"]
    # The numbered line matches by its shape, so it is not among the problems.
    missed = [w for w in wanted if not any(w in p for p in problems)]
    if missed or len(problems) != len(wanted):
        print(f"self-test FAILED: missed {missed}")
        return 1
    print(f"self-test passed: {len(wanted)} planted problems found, the skipped block not run")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--page", default=os.path.join(ROOT, "docs", "tutorial.md"))
    ap.add_argument("--work", help="working folder, emptied first and kept")
    ap.add_argument("--update", action="store_true", help="rewrite the shown lines with the lines they matched")
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    if args.work:
        shutil.rmtree(args.work, ignore_errors=True)
        os.makedirs(args.work)
        problems = run_page(args.page, args.build, args.work, args.update)
    else:
        with tempfile.TemporaryDirectory() as work:
            problems = run_page(args.page, args.build, work, args.update)
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} problem(s) in the tutorial")
        return 1
    print("the tutorial runs as written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
