"""Tests of rcm.batch and `rcm batch` (docs/howto-batch.md) on a LocalCluster:
three small sessions give, on 1 and on 2 workers, the files `rcm run` writes for
each alone; a session with a NaN in a trial is reported with its file, line and
column while the others finish; the CLI's exit status and summary; the cluster
listens on 127.0.0.1 only and leaves no process behind.

The sessions are the shared quick session (rcm_test_support.py) and two copies
of it estimating one trial each, so that each session's results differ.
"""

import csv
import json
import os
import shutil
import subprocess
import time
import unittest
import uuid

import rcm
import rcm.batch
from rcm_test_support import CLI, _state, run_cli, set_up_session, tmp_path

# What differs between two runs of the same study: wall-clock times.
TIMING_KEYS = {"seconds", "mean_update_us"}


def setUpModule():
    set_up_session()
    source = _state["session_dir"]
    with open(_state["manifest"]) as f:
        manifest = json.load(f)
    sessions = {}
    for name, trials in (("alpha", None), ("beta", [0]), ("gamma", [1])):
        folder = tmp_path(os.path.join("batch_sessions", name))
        shutil.copytree(source, folder)
        if trials is not None:
            m = dict(manifest, trials=[manifest["trials"][i] for i in trials])
            with open(os.path.join(folder, "session.json"), "w") as f:
                json.dump(m, f)
        sessions[name] = os.path.join(folder, "session.json")
    # The corrupt one: a NaN in the first trial's recording, deep in the file.
    broken = tmp_path(os.path.join("batch_sessions", "broken"))
    shutil.copytree(source, broken)
    trial = os.path.join(broken, os.path.basename(manifest["trials"][0]["recording"]))
    with open(trial) as f:
        lines = f.readlines()
    cells = lines[200].rstrip("\n").split(",")
    column = lines[0].rstrip("\n").split(",").index("effort_2")
    cells[column] = "nan"
    lines[200] = ",".join(cells) + "\n"
    with open(trial, "w") as f:
        f.writelines(lines)
    _state["batch"] = {"sessions": sessions, "broken": os.path.join(broken, "session.json"), "broken_trial": trial,
                       "options": {"model_file": _state["model_path"], "joint": {"bootstrap_replicates": 0,
                                                                                  "calibration_bootstrap_replicates": 0}}}
    # `rcm run` alone on each session, the reference.
    options = tmp_path("batch_options.json")
    with open(options, "w") as f:
        json.dump(_state["batch"]["options"], f)
    _state["batch"]["options_file"] = options
    for name, manifest_path in sessions.items():
        run_cli("run", manifest_path, "--options", options, "--out", tmp_path(os.path.join("batch_alone", name)),
                json_out=False)


def without_timings(value):
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if k not in TIMING_KEYS}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


def read_json(path):
    with open(path) as f:
        return json.load(f)


def child_pids():
    """Processes whose parent is this one, but multiprocessing's resource
    tracker: started with the first worker, it lives until this process ends
    (the CLI's test checks that nothing outlives the batch's own process)."""
    me, out = str(os.getpid()), []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                with open(f"/proc/{pid}/stat") as f:
                    if f.read().rsplit(")", 1)[1].split()[1] != me:
                        continue
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    if b"resource_tracker" not in f.read():
                        out.append(int(pid))
            except OSError:
                pass
    return out


def pids_with_marker(marker):
    """Processes whose environment holds `marker` (a value only the test set)."""
    out = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                with open(f"/proc/{pid}/environ", "rb") as f:
                    if marker.encode() in f.read():
                        out.append(int(pid))
            except OSError:
                pass
    return out


def listening_addresses(pids):
    """host:port of every TCP socket the processes `pids` listen on (IPv4 and
    IPv6), from /proc/net/tcp{,6} and the processes' file descriptors."""
    inodes = set()
    for pid in pids:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    out = []
    for table, v6 in (("/proc/net/tcp", False), ("/proc/net/tcp6", True)):
        with open(table) as f:
            for line in f.readlines()[1:]:
                cells = line.split()
                if cells[3] != "0A" or cells[9] not in inodes:  # 0A: LISTEN
                    continue
                host, port = cells[1].split(":")
                raw = bytes.fromhex(host)
                if v6:
                    address = ":".join(raw[i:i + 4][::-1].hex() for i in range(0, 16, 4))
                else:
                    address = ".".join(str(b) for b in raw[::-1])
                out.append(f"{address}:{int(port, 16)}")
    return out


def square_or_refuse(x):
    if x < 0:
        raise rcm.InputError(f"x = {x}")
    return x * x


class TestBatch(unittest.TestCase):
    def assert_same_as_alone(self, out_dir, name):
        alone = tmp_path(os.path.join("batch_alone", name))
        mine = os.path.join(out_dir, name)
        self.assertEqual(without_timings(read_json(os.path.join(mine, "results.json"))),
                         without_timings(read_json(os.path.join(alone, "results.json"))), name)
        for f in ("free_space_model.json",):
            with open(os.path.join(mine, f), "rb") as a, open(os.path.join(alone, f), "rb") as b:
                self.assertEqual(a.read(), b.read(), f"{name}/{f}")
        figures = sorted(os.listdir(os.path.join(alone, "figures")))
        self.assertEqual(sorted(os.listdir(os.path.join(mine, "figures"))), figures)
        for f in (f for f in figures if f.endswith(".gp")):  # the figures' data, inline
            with open(os.path.join(mine, "figures", f), "rb") as a, open(os.path.join(alone, "figures", f), "rb") as b:
                self.assertEqual(a.read(), b.read(), f"{name}/figures/{f}")
        self.assertTrue(os.path.isfile(os.path.join(mine, "report.md")))
        self.assertTrue(read_json(os.path.join(mine, "setup.json"))["findings"])

    def test_one_worker_from_python_equals_rcm_run(self):
        b = _state["batch"]
        out = tmp_path("batch_one_worker")
        before = set(child_pids())
        with rcm.batch.open_client(workers=1) as client:
            # A LocalCluster listens on the loopback interface only.
            info = client.scheduler_info()
            addresses = [info["address"]] + list(info["workers"]) + [w["nanny"] for w in info["workers"].values()]
            for address in addresses:
                self.assertTrue(address.startswith("tcp://127.0.0.1:"), address)
            # Every socket they listen on, the HTTP servers included.
            sockets = listening_addresses([os.getpid(), *client.run(os.getpid).values()])
            self.assertGreaterEqual(len(sockets), 4, sockets)  # scheduler, nanny, worker and their HTTP servers
            self.assertEqual([a for a in sockets if not a.startswith("127.0.0.1:")], [])
            self.assertEqual([w["nthreads"] for w in info["workers"].values()], [1])
            summary = rcm.batch.run_sessions(list(b["sessions"].values()), out, b["options"], client=client)
            # The plain map: results in the tasks' order, a failure located and not stopping the others.
            results = rcm.batch.map_tasks(square_or_refuse, [3, -1, 4], client=client)
            # A fit and an evaluation on a worker: the same model and errors as in this process.
            free = os.path.join(_state["session_dir"], "free_space.csv")
            fit = rcm.batch.fit_models([[free]], client=client)[0]
            evaluation = rcm.batch.evaluate_models([(_state["model_path"], free)], client=client)[0]
        self.assertEqual(without_timings(fit.value["model"]), without_timings(_state["fit"].model.to_json()))
        here = rcm.dynamics.evaluate_torque_model(_state["fit"].model, [_state["free"]])
        self.assertEqual([(e["rmse"], e["nrmse_percent"]) for e in evaluation.value],
                         [(e.rmse, e.nrmse_percent) for e in here])
        self.assertEqual([r.value for r in results], [9, None, 16])
        self.assertEqual((results[1].error.type, results[1].error.message), ("InputError", "x = -1"))
        with self.assertRaises(rcm.batch.BatchError):
            rcm.batch.get_values(results)
        self.assertEqual(summary["failed"], [])
        for name in b["sessions"]:
            self.assert_same_as_alone(out, name)
        with open(os.path.join(out, "summary.csv")) as f:
            rows = list(csv.DictReader(f))
        self.assertEqual([(r["session"], r["trial"]) for r in rows],
                         [("alpha", "D30_r0_0"), ("alpha", "D30_r10_15"), ("beta", "D30_r0_0"), ("gamma", "D30_r10_15")])
        alone = read_json(tmp_path(os.path.join("batch_alone", "gamma", "results.json")))
        self.assertAlmostEqual(float(rows[3]["D_mm"]), 1e3 * alone["trials"][0]["misalignment_m"][2], places=2)
        # Every worker process has ended once the client is closed.
        deadline = time.monotonic() + 10
        while set(child_pids()) - before and time.monotonic() < deadline:
            time.sleep(0.2)
        self.assertEqual(set(child_pids()) - before, set())

    def test_cli_two_workers_reports_the_corrupt_session(self):
        b = _state["batch"]
        out = tmp_path("batch_cli")
        marker = f"rcm-batch-test-{uuid.uuid4().hex}"
        env = dict(os.environ, RCM_BATCH_TEST_MARKER=marker)
        manifests = list(b["sessions"].values()) + [b["broken"]]
        proc = subprocess.run([CLI, "batch", "--workers", "2", "--options", b["options_file"], "--out", out, "--json",
                               *manifests], capture_output=True, text=True, env=env)
        self.assertEqual(proc.returncode, 2, proc.stderr)
        # The failed session is listed with the place of its error; the others are whole.
        self.assertIn(f"broken ({b['broken']}): {b['broken_trial']}:201: column effort_2", proc.stderr)
        summary = json.loads(proc.stdout)
        self.assertEqual(summary["failed"], ["broken"])
        self.assertEqual(summary["workers"], 2)
        row = summary["sessions"][3]
        self.assertEqual((row["error"]["file"], row["error"]["line"], row["error"]["field"]),
                         (b["broken_trial"], 201, "effort_2"))
        for name in b["sessions"]:
            self.assert_same_as_alone(out, name)
        self.assertFalse(os.path.exists(os.path.join(out, "broken")))
        self.assertEqual(sorted(f for f in os.listdir(out) if f.startswith(".")), [])
        for f in ("summary.csv", "summary.md", "summary.json"):
            self.assertTrue(os.path.isfile(os.path.join(out, f)), f)
        with open(os.path.join(out, "summary.md")) as f:
            text = f.read()
        self.assertIn("| broken | failed |", text)
        if rcm.is_gnuplot_available():
            self.assertTrue(os.path.isfile(os.path.join(out, "summary.png")))
        deadline = time.monotonic() + 10
        while pids_with_marker(marker) and time.monotonic() < deadline:
            time.sleep(0.2)
        self.assertEqual(pids_with_marker(marker), [])

    def test_cli_refuses_sessions_of_the_same_name_and_a_network_to_fit(self):
        b = _state["batch"]
        twin = tmp_path(os.path.join("batch_twin", "alpha", "session.json"))
        os.makedirs(os.path.dirname(twin), exist_ok=True)
        shutil.copyfile(b["sessions"]["alpha"], twin)
        out = tmp_path("batch_twins")
        proc = subprocess.run([CLI, "batch", "--out", out, b["sessions"]["alpha"], twin], capture_output=True, text=True)
        self.assertEqual(proc.returncode, 2, proc.stderr)
        self.assertIn("both in a folder named 'alpha'", proc.stderr)
        self.assertFalse(os.path.exists(out))
        proc = subprocess.run([CLI, "batch", "--model", "lstm", "--out", out, b["sessions"]["alpha"]],
                              capture_output=True, text=True)
        self.assertEqual(proc.returncode, 2, proc.stderr)
        self.assertIn("--model-file", proc.stderr)


if __name__ == "__main__":
    unittest.main()
