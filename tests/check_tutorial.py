#!/usr/bin/env python3
"""The tutorial runs: every command of docs/tutorial.md, in a scratch folder.

The tutorial's ```sh blocks are run in order, each as one bash script (`set -e
-o pipefail`), in one working folder, with the build's programs first on PATH
and RCM_SOURCE set to the repository. A block preceded by the comment
`<!-- tutorial: not run ... -->` is skipped (it needs the reader's own robot or
recordings; the comment says why). Every block that runs must be followed by
a ```text block, what the reader should see, and every line of it that holds
no digit and is not `...` must appear in what the block printed: the wording
may not drift from the program's. A command that fails, or a missing line,
fails the check with the block's line in the page and its output.

Usage: check_tutorial.py --build DIR [--page docs/tutorial.md] [--work DIR] [--self-test]
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


def expected_lines(text):
    return [" ".join(l.split()) for l in text.splitlines()
            if l.strip() and l.strip() != "..." and not re.search(r"\d", l)]


def run_page(page, build, work):
    with open(page) as f:
        blocks = parse(f.read())
    env = dict(os.environ)
    env["PATH"] = os.path.join(os.path.abspath(build), "bin") + os.pathsep + env.get("PATH", "")
    env["RCM_SOURCE"] = ROOT
    env["PYTHONPATH"] = os.path.join(os.path.abspath(build), "python")
    problems, ran, skipped, total = [], 0, 0, 0.0
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
            printed = " ".join(out.stdout.split())
            for want in expected_lines(follow[2]):
                if want not in printed:
                    problems.append(f"{page}:{follow[0]}: the page shows '{want}', which the command did not "
                                    f"print\n--- output ---\n" + "\n".join(out.stdout.splitlines()[-30:]))
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
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    if args.work:
        shutil.rmtree(args.work, ignore_errors=True)
        os.makedirs(args.work)
        problems = run_page(args.page, args.build, args.work)
    else:
        with tempfile.TemporaryDirectory() as work:
            problems = run_page(args.page, args.build, work)
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} problem(s) in the tutorial")
        return 1
    print("the tutorial runs as written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
