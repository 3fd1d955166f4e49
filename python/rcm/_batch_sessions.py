"""What `rcm batch` does (rcm.batch.run_sessions and `python3 -m rcm.batch`):
every session as `rcm run` runs it, each one's folder written whole by the
caller, and the summary across sessions (docs/howto-batch.md)."""

import argparse
import contextlib
import csv
import io
import json
import math
import os
import shutil
import sys
import tempfile
import time
import uuid

import rcm
from rcm._batch_map import require_distributed, map_tasks, open_client

# Exit statuses of main(), as the rcm program's: bad input 2, other failures 1.
EXIT_INPUT_ERROR = 2
EXIT_FAILURE = 1


def _study_options(options):
    """StudyOptions from an rcm.StudyOptions, a dict (its to_dict(), the JSON of
    `rcm run --options`) or None. Workers get the dict: options objects do not
    travel between processes."""
    if options is None:
        return {}
    d = options.to_dict() if hasattr(options, "to_dict") else dict(options)
    if d.get("model_file"):  # read by the workers, wherever they run
        d["model_file"] = os.path.abspath(d["model_file"])
    return d


def _make_study_options(options):
    # Workers print nothing (the study's and the fit's progress); results do not depend on it.
    quiet = dict(options, verbose=False, fit=dict(options.get("fit", {}), verbose=False))
    return rcm.StudyOptions.from_dict(quiet)


def _read_tree(root):
    files = {}
    for folder, _, names in os.walk(root):
        for name in names:
            path = os.path.join(folder, name)
            with open(path, "rb") as f:
                files[os.path.relpath(path, root)] = f.read()
    return files


def compute_session(manifest, options=None):
    """One session as `rcm run SESSION --out DIR` runs it (the same checks, fit,
    study and report), plus `rcm setup`'s checks with the study's free-space
    model; computed in a folder of the worker's own and returned as
    {'files': {relative path: bytes}, 'results': results dict, 'setup': setup dict}."""
    opts = _make_study_options(options or {})
    session = rcm.load_session(manifest)
    rcm.check_study_inputs(session, opts)
    rcm.check_study_recordings(session, opts)
    out = tempfile.mkdtemp(prefix="rcm-batch-session-")
    try:
        free_space = rcm.fit_free_space_step(session, opts)
        model_path = os.path.join(out, "free_space_model.json")
        rcm.dynamics.save_torque_model(model_path, free_space.model)
        result = rcm.run_study(session, opts, free_space)
        rcm.write_study_report(result, session, out)
        # Setup's checks on the model the study used (not a second fit): findings only, no learning curve.
        setup_opts = rcm.StudyOptions.from_dict(opts.to_dict())
        if setup_opts.model_file is None:
            setup_opts.model_file = model_path
        try:
            setup = rcm.run_setup(session, setup_opts)
        except rcm.InputError as exc:  # the study ran: its results stand, the summary says why setup did not
            setup = {"ready": None, "findings": [], "error": str(exc)}
        else:
            setup.pop("free_space_model", None)
            setup.pop("text", None)
            with open(os.path.join(out, "setup.json"), "w") as f:
                json.dump(setup, f, indent=2)
                f.write("\n")
        return {"files": _read_tree(out), "results": result.to_json(), "setup": setup}
    finally:
        shutil.rmtree(out, ignore_errors=True)


def get_session_names(manifests):
    """{manifest: name}, the name being the folder that holds the manifest.
    ValueError naming both manifests when two share a name."""
    names, seen = {}, {}
    for manifest in manifests:
        path = os.path.abspath(manifest)
        name = os.path.basename(os.path.dirname(path)) or "session"
        if name in seen:
            other = seen[name]
            what = "is given twice" if other == path else f"and {other} are both in a folder named {name!r}"
            raise ValueError(f"{path} {what}: each session's results go to OUT/<its folder's name>/; "
                             "run such sessions in separate batches")
        seen[name] = path
        names[manifest] = name
    return names


def _write_atomic(path, data):
    tmp = f"{path}.tmp-{uuid.uuid4().hex[:8]}"
    with open(tmp, "wb" if isinstance(data, bytes) else "w") as f:
        f.write(data)
    os.replace(tmp, path)


def _install_folder(out_dir, name, files):
    """DIR/<name>/ whole or not at all: written beside it, then renamed into place
    (an earlier folder of that name is replaced)."""
    staging = os.path.join(out_dir, f".{name}.partial-{uuid.uuid4().hex[:8]}")
    try:
        for rel, data in files.items():
            path = os.path.join(staging, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "wb") as f:
                f.write(data)
        final = os.path.join(out_dir, name)
        if os.path.exists(final):
            old = os.path.join(out_dir, f".{name}.old-{uuid.uuid4().hex[:8]}")
            os.rename(final, old)
            os.rename(staging, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(staging, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _session_row(name, manifest, result):
    """The summary's record of one session."""
    row = {"name": name, "session": manifest, "ok": result.ok, "seconds": result.seconds}
    if not result.ok:
        row["error"] = result.error.to_dict()
        return row
    res, setup = result.value["results"], result.value["setup"]
    fs = res["free_space_model"]
    row["method"] = res["method"]
    row["free_space_model"] = {"kind": fs["kind"], "test_errors": fs["test_errors"]}
    row["trials"] = [{k: t[k] for k in ("name", "misalignment_m", "truth_m", "error_m") if k in t}
                     for t in res["trials"]]
    findings = setup.get("findings", [])
    row["setup"] = {"ready": setup.get("ready"),
                    "missing": [f for f in findings if f.get("severity") == "missing"],
                    "notes": [f for f in findings if f.get("severity") == "note"]}
    if "error" in setup:
        row["setup"]["error"] = setup["error"]
    return row


def _mm(value):
    return "" if value is None else f"{1e3 * value:.2f}"


def _joint_errors(row):
    return {e["index"]: e for e in row["free_space_model"]["test_errors"]["joints"]}


CSV_COLUMNS = ["session", "status", "trial", "dr_x_mm", "dr_y_mm", "D_mm", "error_mm", "model", "fs_rmse_1",
               "fs_rmse_2", "fs_rmse_3", "fs_nrmse_1_percent", "fs_nrmse_2_percent", "fs_nrmse_3_percent",
               "setup_ready", "setup_missing", "setup_notes", "error"]


def _summary_csv(rows):
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for row in rows:
        if not row["ok"]:
            w.writerow([row["name"], "failed"] + [""] * (len(CSV_COLUMNS) - 3) + [row["error"]["message"]])
            continue
        errors = _joint_errors(row)
        fs = [f"{errors[j]['rmse']:.6g}" if j in errors else "" for j in (1, 2, 3)]
        fs += [f"{errors[j]['nrmse_percent']:.4g}" if j in errors else "" for j in (1, 2, 3)]
        setup = row["setup"]
        tail = [row["free_space_model"]["kind"], *fs, "" if setup["ready"] is None else str(setup["ready"]).lower(), len(setup["missing"]),
                len(setup["notes"]), ""]
        for t in row["trials"]:
            m = t["misalignment_m"]
            w.writerow([row["name"], "ok", t["name"], _mm(m[0]), _mm(m[1]), _mm(m[2]), _mm(t.get("error_m")), *tail])
    return out.getvalue()


def _summary_markdown(rows, header):
    lines = [header, "", "| session | status | trials | free-space model | held-out RMSE joints 1 / 2 / 3 | "
             "NRMSE (%) | setup | seconds |", "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        if not row["ok"]:
            lines.append(f"| {row['name']} | failed | | | | | | {row['seconds']:.1f} |")
            continue
        errors = _joint_errors(row)
        rmse = " / ".join(f"{errors[j]['rmse']:.3g}" for j in sorted(errors))
        nrmse = " / ".join(f"{errors[j]['nrmse_percent']:.2f}" for j in sorted(errors))
        s = row["setup"]
        setup = "ready" if s["ready"] else f"not ready ({len(s['missing'])} missing)"
        if "error" in s:
            setup = f"not checked: {s['error']}"
        if s["notes"]:
            setup += f", {len(s['notes'])} note(s)"
        lines.append(f"| {row['name']} | ok | {len(row['trials'])} | {row['free_space_model']['kind']} | {rmse} | "
                     f"{nrmse} | {setup} | {row['seconds']:.1f} |")
    lines += ["", "Estimates, mm (dr_x, dr_y across the shaft; D along it; e = |estimate - truth| when the session "
              "states the truth):", "", "| session | trial | dr_x | dr_y | D | e |", "|---|---|---|---|---|---|"]
    for row in rows:
        for t in row.get("trials", []):
            m = t["misalignment_m"]
            lines.append(f"| {row['name']} | {t['name']} | {_mm(m[0])} | {_mm(m[1])} | {_mm(m[2])} | "
                         f"{_mm(t.get('error_m'))} |")
    findings = [(row["name"], f) for row in rows if row["ok"] for f in row["setup"]["missing"] + row["setup"]["notes"]]
    if findings:
        lines += ["", "Setup findings (`rcm setup`'s checks with the study's model; docs/setup.md):", ""]
        lines += [f"- {name}: {f['severity']}: {f['check']}: {f['message']}" for name, f in findings]
    failed = [row for row in rows if not row["ok"]]
    if failed:
        lines += ["", "Failed sessions (nothing written for them):", ""]
        lines += [f"- {row['name']} ({row['session']}): {row['error']['message']}" for row in failed]
    return "\n".join(lines) + "\n"


def _summary_plot(rows, stem):
    """Each trial's estimate (and its error when the truth is known) against the
    session's number in the summary's order."""
    ok = [(i + 1, row) for i, row in enumerate(rows) if row["ok"]]
    series = []
    for label, value in (("D (mm)", lambda t: 1e3 * t["misalignment_m"][2]),
                         ("|dr| across the shaft (mm)", lambda t: 1e3 * math.hypot(*t["misalignment_m"][:2])),
                         ("e = |estimate - truth| (mm)", lambda t: 1e3 * t["error_m"] if "error_m" in t else None)):
        x = [i for i, row in ok for t in row["trials"] if value(t) is not None]
        y = [value(t) for _, row in ok for t in row["trials"] if value(t) is not None]
        if x:
            series.append(rcm.PlotSeries(label, x, y, rcm.PlotStyle.points))
    if not series:
        return []
    files = rcm.save_plot(stem, series, title="Each trial's estimate, by session (numbered in the order of summary.md)",
                          x_label="session", y_label="mm", legend="below", x_range=(0.5, len(rows) + 0.5))
    return [str(files["png"]), str(files["svg"]), str(files["script"])]


def run_sessions(manifests, out_dir, options=None, *, client=None, scheduler=None, workers=None, on_result=None):
    """`rcm batch`: every session as `rcm run` runs it, into out_dir/<name>/
    (name: the folder holding its manifest), each folder whole or not at all,
    and summary.csv, summary.md, summary.json and summary.png/.svg across them.
    Returns the summary dict; its 'failed' lists the sessions that failed."""
    start = time.perf_counter()
    names = get_session_names(manifests)
    opts = _study_options(options)
    tasks = [(os.path.abspath(m), opts) for m in manifests]
    os.makedirs(out_dir, exist_ok=True)
    rows = [None] * len(tasks)

    def finished(result):
        manifest = manifests[result.index]
        if result.ok:
            _install_folder(out_dir, names[manifest], result.value["files"])
        rows[result.index] = _session_row(names[manifest], tasks[result.index][0], result)
        if on_result is not None:
            on_result(result, names[manifest])

    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(open_client(scheduler, workers))
        n_workers = len(client.scheduler_info().get("workers", {}))
        map_tasks(compute_session, tasks, client=client, on_result=finished)
    wall = time.perf_counter() - start
    failed = [row["name"] for row in rows if not row["ok"]]
    summary = {"format": "rcm-batch/1", "rcm_version": rcm.__version__, "sessions": rows, "failed": failed,
               "workers": n_workers, "wall_s": wall, "options": opts}
    header = (f"# rcm batch: {len(rows)} session(s), {len(rows) - len(failed)} estimated, {len(failed)} failed\n\n"
              f"{n_workers} worker(s), {wall:.1f} s. Each session's own results: `<session>/report.md`.")
    _write_atomic(os.path.join(out_dir, "summary.json"), json.dumps(summary, indent=2) + "\n")
    _write_atomic(os.path.join(out_dir, "summary.csv"), _summary_csv(rows))
    _write_atomic(os.path.join(out_dir, "summary.md"), _summary_markdown(rows, header))
    if rcm.is_gnuplot_available():
        summary["plot"] = _summary_plot(rows, os.path.join(out_dir, "summary"))
    return summary


def main(argv=None):
    """`python3 -m rcm.batch` (what `rcm batch` runs). Exit 0 when every session
    was estimated; 2 when some failed, all on bad input; 1 otherwise."""
    ap = argparse.ArgumentParser(prog="rcm batch", description="Many sessions as `rcm run` runs one, on Dask.")
    ap.add_argument("sessions", nargs="+", metavar="SESSION", help="rcm-session/1 manifests")
    ap.add_argument("--out", default="rcm-batch", help="output folder (default rcm-batch)")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786")
    where.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    ap.add_argument("--options", help="JSON file of StudyOptions fields, as `rcm run --options`")
    ap.add_argument("--options-json", help="the same as JSON text (applied after --options)")
    ap.add_argument("--json", action="store_true", help="print summary.json on stdout")
    a = ap.parse_args(argv)
    options = {}
    try:
        if a.options:
            with open(a.options) as f:
                options.update(json.load(f))
        if a.options_json:
            options.update(json.loads(a.options_json))
        rcm.StudyOptions.from_dict(options).validate()
        get_session_names(a.sessions)
        for manifest in a.sessions:
            if not os.path.isfile(manifest):
                raise ValueError(f"{manifest}: no such session manifest")
    except (OSError, ValueError) as exc:  # rcm.InputError is a ValueError
        print(f"rcm batch: {exc}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    try:
        require_distributed()
    except ImportError as exc:
        print(f"rcm batch: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    done = [0]

    def progress(result, name):
        done[0] += 1
        state = f"done in {result.seconds:.1f} s" if result.ok else f"FAILED: {result.error}"
        print(f"[{done[0]}/{len(a.sessions)}] {name}: {state}", file=sys.stderr, flush=True)

    try:
        summary = run_sessions(a.sessions, a.out, options, scheduler=a.scheduler, workers=a.workers,
                               on_result=progress)
    except OSError as exc:  # no scheduler at that address, or the output folder cannot be written
        print(f"rcm batch: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"rcm batch: interrupted; the sessions finished before are in {a.out}, each whole; no summary written",
              file=sys.stderr)
        return 130
    if a.json:
        print(json.dumps(summary, indent=2))
    else:
        with open(os.path.join(a.out, "summary.md")) as f:
            print(f.read(), end="")
    failed = [row for row in summary["sessions"] if not row["ok"]]
    if not failed:
        return 0
    print(f"rcm batch: {len(failed)} of {len(summary['sessions'])} session(s) failed:", file=sys.stderr)
    for row in failed:
        print(f"  {row['name']} ({row['session']}): {row['error']['message']}", file=sys.stderr)
    return EXIT_INPUT_ERROR if all(row["error"]["type"] == "InputError" for row in failed) else EXIT_FAILURE
