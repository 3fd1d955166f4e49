#!/usr/bin/python3
"""Time to accuracy of the free-space fit on 2 minutes of data: rcm beside
PyTorch (Debian python3-torch) training the same network on the same data.

Per seed S, `rcm simulate --quick --seed S` records 120 s of free-space
teleoperation at 200 Hz; every model is scored on the fit's held-out test
split (the last 10 %, state carried from the recording's start) and on an
independent recording, the free space of seed --eval-seed.

- linear (the default kind): `rcm dynamics fit --json`, wall time of the
  command and of the fit (its summary's seconds).
- lstm, per wall-clock budget B (minutes) and without one (rcm's 10 min,
  which early stopping ends first): `rcm dynamics fit --model lstm
  --max-minutes B --threads 2` with the extra inputs off and a causal output
  (RCM_PLAIN), so that the network sees the z-normalized [q, qdot] alone;
  beside it `train_pytorch`, the same training in PyTorch with 2 threads, in
  a process of its own as each rcm fit is: the defaults of
  src/dynamics/torch/torch_lstm_fit.cpp for < 5 min of data, its seeded
  initialization, streams and their random phases, burn-in, loss balance,
  validation pieces, learning-rate schedule, early stopping and budget rule
  (checked after each epoch, from the start of the fit). The PyTorch network
  goes through `rcm dynamics import` (TorchScript) and is scored by `rcm
  dynamics eval`, as rcm's own.
- replica check, on the fits without a budget: parameter counts, per-epoch
  losses and the weights each keeps.

  /usr/bin/python3 bench/fit_speed.py BUILD (--write | --no-doc) [--seeds 1,2,3]
      [--budgets 0.02,0.04,0.08] [--eval-seed 99] [--json FILE] [--keep DIR]

--write puts the table between the fit-speed markers of docs/benchmarks.md.
(`--pytorch-fit REC SEED BUDGET PREFIX` is the process of one PyTorch fit.)
"""
import argparse
import base64
import datetime
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np
import torch

from doc_tables import cpu_model, run, write_block
from recording_arrays import load
from torch_compare import TorqueLstm

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "benchmarks.md")
BEGIN, END = "<!-- fit-speed:begin -->", "<!-- fit-speed:end -->"
RCM_PLAIN = ["--direction-features", "none", "--acceleration-features", "none", "--dahl-features", "none",
             "--output-delay", "0", "--threads", "2"]
# rcm's lstm defaults for < 60000 training samples (FitOptions, choose_shape in
# src/dynamics/torch/torch_lstm_fit.cpp, get_default_loss_balance).
HIDDEN, LAYERS, HEAD, WINDOW, STREAMS, BURN_IN = 32, 1, 64, 50, 32, 200
LR, WEIGHT_DECAY, BALANCE, CLIP = 2e-3, 1e-4, 0.5, 1.0
PATIENCE, PLATEAU, MIN_LR, MAX_EPOCHS, VAL_LEN = 20, 6, 1e-5, 300, 2000
TRAIN, VALIDATION = 0.7, 0.2
DEFAULT_BUDGET = 10.0  # FitOptions::max_minutes


def split_points(total):
    """split_in_time: llround of the fractions of all samples."""
    return math.floor(TRAIN * total + 0.5), math.floor((TRAIN + VALIDATION) * total + 0.5)


def normalize(rec, train_end):
    """prepare_data: mean and population sd over the training split, summed in
    sample order in double as rcm does, then the float inputs and targets."""
    v = np.concatenate([rec["q"], rec["qd"], rec["tau"]], 1)[:train_end]
    n = len(v)
    mean = np.cumsum(v, 0)[-1] / n
    sd = np.sqrt(np.maximum(np.cumsum(v * v, 0)[-1] / n - mean * mean, 0.0))
    sd[~(sd > 1e-9)] = 1.0
    x = ((np.concatenate([rec["q"], rec["qd"]], 1) - mean[:6]) / sd[:6]).astype(np.float32)
    y = ((rec["tau"] - mean[6:]) / sd[6:]).astype(np.float32)
    return torch.from_numpy(x), torch.from_numpy(y), mean, sd


class Phases:
    """std::uniform_int_distribution<Eigen::Index>(0, W - 1) over std::mt19937(seed)
    as libstdc++ 12 draws it (_S_nd, Lemire's method), so that each epoch's
    streams start where rcm's do."""

    def __init__(self, seed):
        self.rs = np.random.RandomState(seed)  # MT19937 seeded as std::mt19937

    def draw(self, n):
        while True:
            product = int(self.rs.randint(0, 2 ** 32, dtype=np.uint32)) * n
            if product % 2 ** 32 >= (2 ** 32 - n) % n:
                return product >> 32


def balanced_loss(mse, p=BALANCE):
    """compute_balanced_loss: the power mean of order 1 - p of per-joint MSEs."""
    mse = np.maximum(np.asarray(mse, float), 1e-300)
    order = 1.0 - p
    return float(np.exp(np.log(mse).mean())) if abs(order) < 1e-9 else float((mse ** order).mean() ** (1 / order))


def train_pytorch(rec, seed, budget_min):
    """train_lstm of rcm, step for step; returns the module and its log."""
    t0 = time.monotonic()
    total = len(rec["t"])
    train_end, val_end = split_points(total)
    x, y, mean, sd = normalize(rec, train_end)
    # LibTorch and PyTorch share one generator: seeded as rcm's setup_torch and
    # drawn in the order of rcm's LstmNet (LSTM, then the head), the initial
    # weights are rcm's.
    torch.manual_seed(seed)
    net = TorqueLstm(inputs=6, hidden=HIDDEN, layers=LAYERS, head=HEAD, outputs=3)
    with torch.no_grad():
        for name, value in (("input_mean", mean[:6]), ("input_scale", sd[:6]), ("output_mean", mean[6:]),
                            ("output_scale", sd[6:])):
            getattr(net, name).copy_(torch.from_numpy(value))
    dt = np.sort(np.diff(rec["t"]))
    net.sample_period_s = float(dt[len(dt) // 2])
    params = list(net.parameters())
    opt = torch.optim.Adam(params, LR, weight_decay=WEIGHT_DECAY)
    phases, running = Phases(seed), None
    streams = STREAMS
    while streams > 1 and train_end // streams < BURN_IN + 4 * WINDOW:
        streams //= 2
    piece = train_end // streams // WINDOW * WINDOW
    vb = [b for b in range(max(train_end, BURN_IN), val_end - VAL_LEN + 1, VAL_LEN)]
    if vb:
        vx = torch.stack([x[b - BURN_IN:b + VAL_LEN] for b in vb])
        vy = torch.stack([y[b:b + VAL_LEN] for b in vb])
    else:  # a validation split shorter than one piece: one piece of what there is
        b = max(train_end, BURN_IN)
        vx, vy = x[b - BURN_IN:val_end][None], y[b:val_end][None]

    def validate():
        with torch.no_grad():
            pred = net.head(net.lstm(vx)[0])[:, BURN_IN:]
            err = (pred - vy).pow(2).sum((0, 1)).double() / (vy.shape[0] * vy.shape[1])
        return balanced_loss(err.numpy())

    best, best_epoch, since_best, since_reduce, lr = math.inf, 0, 0, 0, LR
    best_params = [p.detach().clone() for p in params]
    log, updates = [], 0
    for epoch in range(1, MAX_EPOCHS + 1):
        phase = phases.draw(WINDOW)
        starts = range(phase, train_end - piece + 1, piece)
        X, Y = torch.stack([x[b:b + piece] for b in starts]), torch.stack([y[b:b + piece] for b in starts])
        state, train_sum, train_n = None, np.zeros(3), 0
        for c in range(0, piece - WINDOW + 1, WINDOW):
            out, (h, cell) = net.lstm(X[:, c:c + WINDOW], state)
            state = (h.detach(), cell.detach())
            skip = max(0, min(WINDOW, BURN_IN - c))
            if skip >= WINDOW:
                continue
            pred = net.head(out)[:, skip:]
            mse = (pred - Y[:, c + skip:c + WINDOW]).pow(2).mean((0, 1))
            m = mse.detach().clamp_min(1e-12)
            running = m if running is None else 0.98 * running + 0.02 * m
            loss = (mse / running.pow(BALANCE)).mean()
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, CLIP)
            opt.step()
            train_sum += mse.detach().double().numpy()
            train_n += 1
            updates += 1
        val = validate()
        if val < best * (1.0 - 1e-4):
            best, best_epoch, since_best, since_reduce = val, epoch, 0, 0
            best_params = [p.detach().clone() for p in params]
        else:
            since_best += 1
            since_reduce += 1
            if since_reduce >= PLATEAU and lr > MIN_LR:
                lr, since_reduce = max(lr * 0.5, MIN_LR), 0
                for g in opt.param_groups:
                    g["lr"] = lr
        log.append({"epoch": epoch, "train": balanced_loss(train_sum / max(train_n, 1)), "validation": val,
                    "seconds": time.monotonic() - t0})
        if since_best >= PATIENCE or time.monotonic() - t0 > 60.0 * budget_min:
            break
    with torch.no_grad():
        for p, b in zip(params, best_params):
            p.copy_(b)
    return net, {"seconds": time.monotonic() - t0, "epochs": len(log), "best_epoch": best_epoch,
                 "updates": updates, "best_validation_loss": best, "log": log}


def rcm_json(cmd):
    start = time.monotonic()
    proc = run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return json.loads(proc.stdout), time.monotonic() - start, proc.stderr


def nrmse(joints):
    return [j["nrmse_percent"] for j in joints]


def test_nrmse(rcm, model, recording, work):
    """NRMSE on the last 10 % of `recording` from `rcm dynamics eval`'s predictions
    over the whole of it (state carried from its start), as the fit's `test`."""
    pred_file = os.path.join(work, "predictions.csv")
    run([rcm, "dynamics", "eval", model, recording, "--predictions", pred_file], stdout=subprocess.DEVNULL)
    p = np.genfromtxt(pred_file, delimiter=",", names=True)
    _, val_end = split_points(len(p))
    out = []
    for j in (1, 2, 3):
        m, e = p[f"effort_{j}"][val_end:], p[f"tau_fs_{j}"][val_end:]
        out.append(100.0 * np.sqrt(np.mean((m - e) ** 2)) / (m.max() - m.min()))
    return out


def eval_nrmse(rcm, model, recording):
    return nrmse(rcm_json([rcm, "dynamics", "eval", model, recording, "--json"])[0]["joints"])


def fit_rcm(rcm, train, work, tag, seed, budget):
    """`rcm dynamics fit --model lstm`; budget None: rcm's own (10 min)."""
    model = os.path.join(work, f"{tag}.json")
    extra = [] if budget is None else ["--max-minutes", str(budget)]
    summary, wall, err = rcm_json([rcm, "dynamics", "fit", "--model", "lstm", "--seed", str(seed), "--out", model,
                                   train, "--json"] + RCM_PLAIN + extra)
    log = [{"epoch": int(m[0]), "train": float(m[1]), "validation": float(m[2])}
           for m in re.findall(r"epoch\s+(\d+)\s+train (\S+)\s+validation (\S+)", err)]
    return model, {"wall": wall, "seconds": summary["seconds"], "epochs": summary["epochs"],
                   "best_epoch": summary["best_epoch"], "test": nrmse(summary["test"]), "log": log}


def fit_pytorch(rcm, train, work, tag, seed, budget):
    """train_pytorch in a process of its own, as each rcm fit is; its network
    then goes through `rcm dynamics import`."""
    prefix = os.path.join(work, tag)
    start = time.monotonic()
    run([sys.executable, os.path.abspath(__file__), "--pytorch-fit", train, str(seed),
         str(DEFAULT_BUDGET if budget is None else budget), prefix])
    wall = time.monotonic() - start
    with open(prefix + ".json") as f:
        summary = json.load(f)
    model = prefix + "_model.json"
    run([rcm, "dynamics", "import", prefix + ".pt", "--out", model], stdout=subprocess.DEVNULL)
    summary.update(wall=wall, test=test_nrmse(rcm, model, train, work))
    return model, summary


def pytorch_fit_main(train, seed, budget, prefix):
    torch.set_num_threads(2)
    net, summary = train_pytorch(load(train), int(seed), float(budget))
    summary["parameters"] = sum(p.numel() for p in net.parameters())
    torch.jit.script(net).save(prefix + ".pt")
    with open(prefix + ".json", "w") as f:
        json.dump(summary, f)


def model_weights(path):
    """The network's weights of a model file, in nn.Module parameter order."""
    with open(path) as f:
        p = json.load(f)["parameters"]["lstm"]
    arr = lambda a: np.frombuffer(base64.b64decode(a["data"]), "<f4").reshape(a["shape"])
    out = []
    for layer in p["layers"]:
        out += [arr(layer[k]) for k in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")]
    for layer in p["head"]:
        out += [arr(layer["weight"]), arr(layer["bias"])]
    return out


def replica_check(rcm, train, work, rcm_fit, pytorch_fit):
    """The two fits without a budget: parameter counts, the largest difference
    of their per-epoch losses (rcm prints 5 decimals) and of the weights they
    keep, and rcm's test NRMSE scored as the PyTorch one is."""
    (rcm_model, r), (pytorch_model, p) = rcm_fit, pytorch_fit
    loss = max(max(abs(a["train"] - b["train"]), abs(a["validation"] - b["validation"]))
               for a, b in zip(r["log"], p["log"]))
    w_rcm, w_pytorch = model_weights(rcm_model), model_weights(pytorch_model)
    scale = max(float(np.abs(w).max()) for w in w_rcm)
    return {"rcm_parameters": int(sum(w.size for w in w_rcm)), "pytorch_parameters": p["parameters"],
            "epochs": [r["epochs"], p["epochs"]], "best_epoch": [r["best_epoch"], p["best_epoch"]],
            "loss_difference": loss,
            "weight_difference": max(float(np.abs(a - b).max()) for a, b in zip(w_rcm, w_pytorch)) / scale,
            "scorer_difference": max(abs(a - b) for a, b in zip(test_nrmse(rcm, rcm_model, train, work), r["test"]))}


def one_seed(rcm, seed, budgets, evaluation, work):
    sim = os.path.join(work, f"seed{seed}")
    run([rcm, "simulate", "--quick", "--seed", str(seed), "--no-truth", "--out", sim], stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    train = os.path.join(sim, "free_space.csv")
    out = {"seed": seed, "lstm": []}
    model = os.path.join(work, f"linear_{seed}.json")
    summary, wall, _ = rcm_json([rcm, "dynamics", "fit", "--out", model, train, "--json"])
    out["linear"] = {"wall": wall, "seconds": summary["seconds"], "test": nrmse(summary["test"]),
                     "eval": eval_nrmse(rcm, model, evaluation), "structure": summary.get("structure")}
    for budget in budgets + [None]:
        fits = [fit(rcm, train, work, f"{trainer}_{seed}_{budget}", seed, budget)
                for trainer, fit in (("rcm", fit_rcm), ("pytorch", fit_pytorch))]
        # Every epoch makes the same number of updates (fixed streams and window).
        fits[0][1]["updates"] = fits[1][1]["updates"] // fits[1][1]["epochs"] * fits[0][1]["epochs"]
        for trainer, (model, point) in zip(("rcm", "PyTorch"), fits):
            point.update(trainer=trainer, budget=budget, eval=eval_nrmse(rcm, model, evaluation))
            out["lstm"].append(point)
        if budget is None:
            out["check"] = replica_check(rcm, train, work, *fits)
    return out


def mean(values):
    return float(np.mean(values, 0)) if np.ndim(values) == 1 else np.mean(values, 0)


def fmt3(v, digits=2):
    return " / ".join(f"{x:.{digits}f}" for x in v)


def table(results, args, stamp, load_start, load_end):
    checks = [r["check"] for r in results]
    lines = [f"Measured by `bench/fit_speed.py` on {stamp}, {cpu_model()}, {os.cpu_count()} cores, load average "
             f"{load_start:.1f} at the start and {load_end:.1f} at the end; seeds {args.seeds} "
             f"(`rcm simulate --quick --seed S`: 120 s of free space at 200 Hz), means over the seeds. "
             "NRMSE yaw / pitch / insertion in %: *test* on the fit's held-out last 10 %, *independent* by "
             f"`rcm dynamics eval` on the free space of seed {args.eval_seed}. The lstm rows train the 1 x "
             f"{HIDDEN} network (window {WINDOW}, head {HEAD}, Adam {LR:g}, weight decay {WEIGHT_DECAY:g}, loss "
             f"balance {BALANCE}) on [q, qdot] alone (`{' '.join(RCM_PLAIN)}`), 2 threads each, each fit a "
             "process of its own. *fit*: from the start of the fit to the trained model (rcm: its summary's "
             "seconds); in brackets the whole command (rcm: with loading LibTorch and the recording and saving "
             "the model; PyTorch: with importing torch and saving TorchScript). The budget is checked after each "
             "epoch, so a fit ends up to one epoch past it, or before it by early stopping.",
             "",
             "| model, trainer | budget | fit (whole command) | epochs (updates), best | test NRMSE | "
             "independent NRMSE | target |",
             "|---|---|---|---|---|---|---|"]
    lin = [r["linear"] for r in results]
    lines.append(f"| linear (default), rcm | - | {mean([x['seconds'] for x in lin]):.2f} s "
                 f"({mean([x['wall'] for x in lin]):.2f} s) | - | {fmt3(mean([x['test'] for x in lin]))} | "
                 f"{fmt3(mean([x['eval'] for x in lin]))} | final accuracy < 30 s |")
    for b in args.budget_list + [None]:
        for trainer in ("rcm", "PyTorch"):
            pts = [p for r in results for p in r["lstm"] if p["budget"] == b and p["trainer"] == trainer]
            label = "none (early stopping)" if b is None else f"{b:g} min"
            lines.append(f"| lstm, {trainer} | {label} | {mean([p['seconds'] for p in pts]):.1f} s "
                         f"({mean([p['wall'] for p in pts]):.1f} s) | "
                         f"{mean([p['epochs'] for p in pts]):.0f} ({mean([p['updates'] for p in pts]):.0f}), "
                         f"{mean([p['best_epoch'] for p in pts]):.0f} | {fmt3(mean([p['test'] for p in pts]))} | "
                         f"{fmt3(mean([p['eval'] for p in pts]))} | |")
    lines += ["",
              "Replica check, the fits without a budget, per seed: parameters rcm "
              f"{'/'.join(str(c['rcm_parameters']) for c in checks)}, PyTorch "
              f"{'/'.join(str(c['pytorch_parameters']) for c in checks)}; epochs (best) rcm "
              f"{'/'.join('{} ({})'.format(c['epochs'][0], c['best_epoch'][0]) for c in checks)}, PyTorch "
              f"{'/'.join('{} ({})'.format(c['epochs'][1], c['best_epoch'][1]) for c in checks)}; largest "
              "difference of the per-epoch training and validation losses (rcm prints 5 decimals) "
              f"{max(c['loss_difference'] for c in checks):.1e}, of the weights kept (relative to the "
              f"largest) {max(c['weight_difference'] for c in checks):.1e}; rcm's test NRMSE scored as PyTorch's "
              f"(`rcm dynamics eval --predictions`) against its fit's own: {max(c['scorer_difference'] for c in checks):.1e} "
              "points apart."]
    return "\n".join(lines)


def main():
    if sys.argv[1:2] == ["--pytorch-fit"]:
        return pytorch_fit_main(*sys.argv[2:6])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("build")
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    mode.add_argument("--no-doc", action="store_true", help="print the table only")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--budgets", default="0.02,0.04,0.08", help="lstm wall-clock budgets, minutes")
    ap.add_argument("--eval-seed", type=int, default=99, help="seed of the independent recording")
    ap.add_argument("--json", help="write every point to this file")
    ap.add_argument("--keep", help="keep recordings and models in this directory")
    args = ap.parse_args()
    args.budget_list = [float(b) for b in args.budgets.split(",")]
    rcm = os.path.join(args.build, "bin", "rcm")
    work = args.keep or tempfile.mkdtemp(prefix="rcm_fit_speed_")
    os.makedirs(work, exist_ok=True)
    load_start = os.getloadavg()[0]
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    sim = os.path.join(work, f"eval{args.eval_seed}")
    run([rcm, "simulate", "--quick", "--seed", str(args.eval_seed), "--no-truth", "--out", sim],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    evaluation = os.path.join(sim, "free_space.csv")
    results = [one_seed(rcm, int(s), args.budget_list, evaluation, work)
               for s in args.seeds.split(",")]
    block = table(results, args, stamp, load_start, os.getloadavg()[0])
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"date": stamp, "cpu": cpu_model(), "cores": os.cpu_count(), "seeds": results}, f, indent=1)
    print(block)
    if args.write:
        write_block(DOC, BEGIN, END, block)
        print(f"wrote {DOC}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
