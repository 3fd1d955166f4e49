#!/usr/bin/env python3
"""The documentation holds together and stays short.

Reads README.md and every docs/*.md and fails, printing FILE:LINE: WHAT, on

  - a relative link `[text](path#anchor)` whose file does not exist, or whose
    anchor is not a heading of that page (GitHub's rule for anchors);
  - a path in backquotes that names a file of the repository (`docs/x.md`,
    `src/...`, `bench/x.py`, ...) and does not exist: a page that points at a
    removed page or file;
  - the length targets: README.md at most 150 lines, no paragraph of it longer
    than 6 lines; the pages docs/*.md at most 150 KB in all and 30 KB each;
    the median sentence of README.md and docs/tutorial.md at most 22 words.

It prints the figures it measured (lines, sizes, median sentence lengths), so
that a report can quote them. A sentence is a run of prose words ending in
. ! or ? (code blocks, tables, headings and HTML comments are not prose;
backquoted code counts as one word).

Usage: check_docs.py [--root DIR] [--self-test]
"""

import argparse
import os
import re
import statistics
import sys
import tempfile

README_MAX_LINES = 150
README_MAX_PARAGRAPH = 6
DOCS_MAX_TOTAL = 150 * 1024
DOCS_MAX_PAGE = 30 * 1024
MAX_MEDIAN_SENTENCE = 22
SENTENCE_PAGES = ("README.md", "docs/tutorial.md")

# Top-level directories whose paths, in backquotes, must exist.
TREE_DIRS = ("docs", "include", "src", "apps", "tests", "bench", "python", "ros", "dds", "examples",
             "data", "fuzz", "cmake", "tools")
LINK = re.compile(r"(?<!!)\[([^\]]*)\]\(([^)\s]+)\)|!\[([^\]]*)\]\(([^)\s]+)\)")
CODE_SPAN = re.compile(r"`([^`\n]+)`")
PATH_TOKEN = re.compile(r"^(?:" + "|".join(TREE_DIRS) + r")/[A-Za-z0-9_./+-]*$")


def pages(root):
    out = []
    if os.path.exists(os.path.join(root, "README.md")):
        out.append("README.md")
    docs = os.path.join(root, "docs")
    if os.path.isdir(docs):
        out += sorted("docs/" + n for n in os.listdir(docs) if n.endswith(".md"))
    return out


def github_slug(heading):
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"<[^>]+>", "", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors_of(text):
    seen = {}
    out = set()
    in_code = False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            in_code = not in_code
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m and not in_code:
            slug = github_slug(m.group(1))
            n = seen.get(slug, 0)
            seen[slug] = n + 1
            out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def blocks(text):
    """(kind, first line number, lines): kind is code, table, heading, comment, item or para."""
    out = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        s = line.strip()
        if not s:
            i += 1
            continue
        if s.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith("```"):
                j += 1
            out.append(("code", i + 1, lines[i:j + 1]))
            i = j + 1
            continue
        if s.startswith("<!--"):
            j = i
            while j < len(lines) and "-->" not in lines[j]:
                j += 1
            out.append(("comment", i + 1, lines[i:j + 1]))
            i = j + 1
            continue
        if s.startswith("#"):
            out.append(("heading", i + 1, [line]))
            i += 1
            continue
        if s.startswith("|"):
            j = i
            while j < len(lines) and lines[j].strip().startswith("|"):
                j += 1
            out.append(("table", i + 1, lines[i:j]))
            i = j
            continue
        item = re.match(r"^\s*([-*+]|\d+\.)\s", line) is not None
        j = i + 1
        while j < len(lines):
            t = lines[j].strip()
            if not t or t.startswith(("```", "#", "|", "<!--")) or re.match(r"^\s*([-*+]|\d+\.)\s", lines[j]):
                break
            j += 1
        out.append(("item" if item else "para", i + 1, lines[i:j]))
        i = j
    return out


def sentence_lengths(text):
    prose = []
    for kind, _, lines in blocks(text):
        if kind in ("item", "para"):
            prose.append(" ".join(l.strip() for l in lines))
    words_all = []
    for p in prose:
        p = re.sub(r"^([-*+]|\d+\.)\s+", "", p)
        p = CODE_SPAN.sub("CODE", p)
        p = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", p)
        for s in re.split(r"(?<=[.!?])\s+(?=[A-Z(`\"'*])|(?<=[.!?])$", p):
            words = [w for w in s.split() if re.search(r"\w", w)]
            if words:
                words_all.append(len(words))
    return words_all


def check(root):
    problems, notes = [], []
    listed = pages(root)
    texts = {}
    for rel in listed:
        with open(os.path.join(root, rel), encoding="utf-8") as f:
            texts[rel] = f.read()
    for rel, text in texts.items():
        base = os.path.dirname(rel)
        in_code = False
        for number, line in enumerate(text.splitlines(), 1):
            if line.lstrip().startswith("```"):
                in_code = not in_code
                continue
            if in_code:
                continue
            for m in LINK.finditer(line):
                target = m.group(2) or m.group(4)
                if re.match(r"^[a-z]+:", target):
                    continue  # http:, https:, mailto:
                path, _, anchor = target.partition("#")
                if path:
                    full = os.path.normpath(os.path.join(root, base, path))
                    if not os.path.exists(full):
                        problems.append(f"{rel}:{number}: link to a missing file: {target}")
                        continue
                    linked = os.path.relpath(full, root).replace(os.sep, "/")
                else:
                    linked = rel
                if anchor and linked.endswith(".md"):
                    if linked not in texts:
                        with open(os.path.join(root, linked), encoding="utf-8") as f:
                            texts[linked] = f.read()
                    if anchor not in anchors_of(texts[linked]):
                        problems.append(f"{rel}:{number}: no heading '#{anchor}' in {linked}")
            for m in CODE_SPAN.finditer(line):
                token = m.group(1).strip().rstrip(",.;:")
                token = token.split(":")[0] if re.match(r"^[\w./+-]+:\d", token) else token
                if not PATH_TOKEN.match(token) or any(c in token for c in "<>*{}$"):
                    continue
                if not os.path.exists(os.path.join(root, token)):
                    problems.append(f"{rel}:{number}: names a missing file: {token}")

    if "README.md" in texts:
        readme = texts["README.md"]
        n = len(readme.splitlines())
        notes.append(f"README.md: {n} lines (at most {README_MAX_LINES})")
        if n > README_MAX_LINES:
            problems.append(f"README.md: {n} lines, more than {README_MAX_LINES}")
        for kind, first, lines in blocks(readme):
            if kind in ("para", "item") and len(lines) > README_MAX_PARAGRAPH:
                problems.append(f"README.md:{first}: a paragraph of {len(lines)} lines, more than "
                                f"{README_MAX_PARAGRAPH}")
    sizes = {rel: len(texts[rel].encode("utf-8")) for rel in listed if rel.startswith("docs/")}
    total = sum(sizes.values())
    if sizes:
        largest = max(sizes, key=sizes.get)
        notes.append(f"docs/*.md: {len(sizes)} pages, {total / 1024:.1f} KB in all (at most "
                     f"{DOCS_MAX_TOTAL // 1024}); largest {largest}, {sizes[largest] / 1024:.1f} KB (at most "
                     f"{DOCS_MAX_PAGE // 1024})")
    if total > DOCS_MAX_TOTAL:
        problems.append(f"docs/: {total / 1024:.1f} KB of pages, more than {DOCS_MAX_TOTAL // 1024} KB")
    for rel, size in sizes.items():
        if size > DOCS_MAX_PAGE:
            problems.append(f"{rel}: {size / 1024:.1f} KB, more than {DOCS_MAX_PAGE // 1024} KB")
    for rel in SENTENCE_PAGES:
        if rel in texts:
            lengths = sentence_lengths(texts[rel])
            if lengths:
                median = statistics.median(lengths)
                notes.append(f"{rel}: median sentence {median:g} words over {len(lengths)} sentences "
                             f"(at most {MAX_MEDIAN_SENTENCE})")
                if median > MAX_MEDIAN_SENTENCE:
                    problems.append(f"{rel}: median sentence of {median:g} words, more than {MAX_MEDIAN_SENTENCE}")
    return problems, notes


def self_test():
    long_sentence = "Word " + " ".join(["word"] * 29) + "."
    tree = {
        "README.md": "# A\n\n[ok](docs/a.md#b-c) [bad](docs/none.md) [anchor](docs/a.md#nope)\n\n"
                     + "\n".join(["line"] * 7) + "\n\n" + " ".join([long_sentence] * 3) + "\n",
        "docs/a.md": "# A\n\n## B, c\n\nSee `docs/gone.md` and `src/x.cpp` and [self](#b-c).\n",
        "docs/big.md": "x" * (DOCS_MAX_PAGE + 10) + "\n",
        "src/x.cpp": "\n",
    }
    expected = ["docs/none.md", "#nope", "docs/gone.md", "paragraph of 7", "median sentence", "docs/big.md"]
    with tempfile.TemporaryDirectory() as tmp:
        for rel, text in tree.items():
            path = os.path.join(tmp, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w") as f:
                f.write(text)
        problems, _ = check(tmp)
    for p in problems:
        print(p)
    missed = [e for e in expected if not any(e in p for p in problems)]
    false = [p for p in problems if "src/x.cpp" in p or "#b-c" in p]
    if missed or false or len(problems) != len(expected):
        print(f"self-test FAILED: missed {missed}, wrongly flagged {false}")
        return 1
    print(f"self-test passed: {len(expected)} planted problems found, good links not flagged")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    problems, notes = check(os.path.abspath(args.root))
    for n in notes:
        print(n)
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} documentation problem(s)")
        return 1
    print("every link and path resolves; the length targets hold")
    return 0


if __name__ == "__main__":
    sys.exit(main())
