"""What the scripts that write measured tables into docs/ share: running rcm
with the command echoed, naming the machine, and replacing the block between
two markers of a document atomically."""
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
