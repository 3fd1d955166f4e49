#!/usr/bin/python3
"""Side-by-side LSTM comparison: PyTorch (Debian python3-torch) vs rcm's LibTorch
training and Eigen streaming kernel, in one run. Run with /usr/bin/python3:

    /usr/bin/python3 bench/torch_compare.py BUILD_DIR [--write docs/benchmarks.md]

Same shapes as bench/bench_torch_lstm.cpp: 12 inputs (6 joints), 1 x 128 (the
default) and 2 x 128 LSTM, head 64 (tanh), 6 outputs; streaming = one sample with
state carried, one thread; training = one Adam update of the 1 x 128 network on
32 streams x 100 samples, 2 threads. Also writes
BUILD_DIR/pytorch_lstm.pt, a TorchScript module in the layout that
`rcm dynamics import` reads (docs/methods.md).
"""
import json
import os
import subprocess
import sys
import time

import torch

torch.set_num_threads(2)
torch.manual_seed(0)


class TorqueLstm(torch.nn.Module):
    """The documented PyTorch layout: lstm, head, normalization buffers."""

    def __init__(self, inputs=12, hidden=128, layers=2, head=64, outputs=6):
        super().__init__()
        self.lstm = torch.nn.LSTM(inputs, hidden, layers, batch_first=True)
        self.head = torch.nn.Sequential(torch.nn.Linear(hidden, head), torch.nn.Tanh(), torch.nn.Linear(head, outputs))
        self.register_buffer("input_mean", torch.zeros(inputs))
        self.register_buffer("input_scale", torch.ones(inputs))
        self.register_buffer("output_mean", torch.zeros(outputs))
        self.register_buffer("output_scale", torch.ones(outputs))
        self.sample_period_s = 0.005

    def forward(self, x):
        out, _ = self.lstm((x - self.input_mean) / self.input_scale)
        return self.head(out) * self.output_scale + self.output_mean


def time_it(fn, min_seconds=2.0):
    fn()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < min_seconds:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n


def python_step_us(layers):
    torch.set_num_threads(1)  # one core, as the Eigen kernel
    m = TorqueLstm(layers=layers).eval()
    state = [None]
    x = torch.zeros(1, 1, 12)

    def step():
        with torch.no_grad():
            out, state[0] = m.lstm(x, state[0])
            m.head(out)

    t = 1e6 * time_it(step)
    torch.set_num_threads(2)
    return t


def python_train_ms():
    m = TorqueLstm(layers=1)
    opt = torch.optim.Adam(m.parameters(), 1e-3)
    x, y = torch.randn(32, 100, 12), torch.randn(32, 100, 6)

    def update():
        loss = torch.nn.functional.mse_loss(m.head(m.lstm(x)[0]), y)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(m.parameters(), 1.0)
        opt.step()

    return 1e3 * time_it(update, 4.0)


def cpp_results(build):
    exe = os.path.join(build, "bin", "bench_torch_lstm")
    out = subprocess.run([exe, "--benchmark_format=json", "--benchmark_min_time=2"], check=True,
                         capture_output=True, text=True).stdout
    res = {}
    for b in json.loads(out)["benchmarks"]:
        scale = {"ns": 1e-3, "us": 1.0, "ms": 1e3}[b["time_unit"]]
        res[b["name"]] = b["real_time"] * scale  # microseconds
    return res


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        sys.exit(2)
    build = sys.argv[1]
    write = sys.argv[sys.argv.index("--write") + 1] if "--write" in sys.argv else None
    torch.jit.script(TorqueLstm()).save(os.path.join(build, "pytorch_lstm.pt"))
    cpp = cpp_results(build)
    rows = []
    for layers in (1, 2):
        py = python_step_us(layers)
        eig, lt = cpp[f"BM_EigenLstmStep/128/{layers}"], cpp[f"BM_LibTorchLstmStep/128/{layers}"]
        rows.append((f"LSTM streaming step, {layers} x 128, 1 sample, state carried, 1 thread", f"{py:.1f} us",
                     f"{lt:.1f} us", f"{eig:.2f} us",
                     f"PyTorch/Eigen {py / eig:.1f}x, LibTorch/Eigen {lt / eig:.1f}x"))
    py_train, lt_train = python_train_ms(), cpp["BM_LibTorchTrainingStep/streams:32/window:100"] / 1e3
    rows.append(("LSTM training update, 1 x 128, 32 x 100 window, Adam, 2 threads", f"{py_train:.1f} ms",
                 f"{lt_train:.1f} ms", "-", f"PyTorch/LibTorch {py_train / lt_train:.2f}x"))
    table = ["| what | PyTorch (python3-torch) | LibTorch (rcm::torch) | Eigen kernel (rcm::core) | ratio |",
             "|---|---|---|---|---|"] + ["| " + " | ".join(r) + " |" for r in rows]
    text = "\n".join(table)
    print(text)
    if write:
        begin, end = "<!-- torch_compare:begin -->", "<!-- torch_compare:end -->"
        doc = open(write).read() if os.path.exists(write) else ""
        block = f"{begin}\n{text}\n{end}"
        if begin in doc and end in doc:
            doc = doc[:doc.index(begin)] + block + doc[doc.index(end) + len(end):]
        else:
            doc += "\n" + block + "\n"
        open(write, "w").write(doc)


if __name__ == "__main__":
    main()
