"""Tests of the Python module `rcm`, cross-checked against the C++ CLI.

Run by CTest (python/CMakeLists.txt) with PYTHONPATH=<build>/python and
RCM_CLI=<build>/bin/rcm. By hand:

    cd python/tests && PYTHONPATH=../../build-py/python RCM_CLI=../../build-py/bin/rcm \
        /usr/bin/python3 -m unittest -v test_rcm

One small simulated session (`rcm simulate --quick`, two trials at D = 30 mm) is
written once by the CLI; the linear free-space model is fitted once in Python.
Reference values come from the CLI on the same files, so a binding that passes
the wrong argument, drops a sample or converts a unit fails here.
"""

import base64
import csv
import json
import math
import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

import rcm

CLI = os.environ.get("RCM_CLI", "")
Q0 = [0.0, 0.0, 0.12]
TRUTH = {"D30_r0_0": [0.0, 0.0, 0.03], "D30_r10_15": [0.010, 0.015, 0.030]}
# Two trials instead of the quick session's ten keep the whole run short.
SIM_OVERRIDES = {"protocol": {"coaxial_offsets_m": [0.03], "radial_offsets_m": [[0.0, 0.0], [0.010, 0.015]]}}

_state = {}


def run_cli(*args, json_out=True):
    """Runs the CLI; fails the test with its stderr when it does not exit 0."""
    proc = subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise AssertionError(f"rcm {' '.join(map(str, args))} exited {proc.returncode}:\n{proc.stderr}")
    return json.loads(proc.stdout) if json_out else proc.stdout


def setUpModule():
    if not (CLI and os.access(CLI, os.X_OK)):
        raise RuntimeError(f"RCM_CLI={CLI!r} is not an executable; build rcm_cli and set RCM_CLI")
    tmp = tempfile.mkdtemp(prefix="rcm_python_test_")
    _state["tmp"] = tmp
    config = os.path.join(tmp, "sim_overrides.json")
    with open(config, "w") as f:
        json.dump(SIM_OVERRIDES, f)
    session_dir = os.path.join(tmp, "session")
    run_cli("simulate", "--quick", "--config", config, "--no-truth", "--out", session_dir, "--json")
    _state["session_dir"] = session_dir
    _state["manifest"] = os.path.join(session_dir, "session.json")
    free = rcm.load_recording(os.path.join(session_dir, "free_space.csv"))
    options = rcm.dynamics.FitOptions()
    options.verbose = False
    fit = rcm.dynamics.fit_linear_torque_model([free], options)
    _state["free"] = free
    _state["fit"] = fit
    _state["model_path"] = os.path.join(tmp, "linear.json")
    rcm.dynamics.save_torque_model(_state["model_path"], fit.model)


def tearDownModule():
    if "tmp" in _state:
        shutil.rmtree(_state["tmp"], ignore_errors=True)


def session_file(name):
    return os.path.join(_state["session_dir"], name)


def tmp_path(name):
    return os.path.join(_state["tmp"], name)


def random_arrays(T=40, N=4, seed=3):
    rng = np.random.default_rng(seed)
    time = np.cumsum(rng.uniform(0.004, 0.006, T))
    return time, rng.normal(size=(T, N)), rng.normal(size=(T, N)), rng.normal(size=(T, N)), rng.normal(size=(T, 3))


class TestInputError(unittest.TestCase):
    def test_is_a_value_error_with_location(self):
        self.assertTrue(issubclass(rcm.InputError, ValueError))
        path = tmp_path("bad_cell.csv")
        with open(path, "w") as f:
            f.write("time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,effort_3\n")
            f.write("0,0,0,0.1,0,0,0,0,0,0\n")
            f.write("0.005,0,0,0.1,0,0,0,0,0,0\n")
            f.write("0.010,0,0,0.1,0,0,0,0,abc,0\n")
        with self.assertRaises(rcm.InputError) as cm:
            rcm.load_recording(path)
        e = cm.exception
        self.assertTrue(str(e).startswith(f"{path}:4: "), str(e))
        self.assertIn("effort_2", str(e))
        self.assertEqual(e.file, path)
        self.assertEqual(e.line, 4)
        self.assertEqual(e.field, "effort_2")
        self.assertIn("abc", e.reason)

    def test_cli_and_module_name_the_same_place(self):
        path = tmp_path("nan_cell.csv")
        with open(path, "w") as f:
            f.write("time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,effort_3\n")
            f.write("0,0,0,0.1,0,0,0,0,0,0\n")
            f.write("0.005,0,nan,0.1,0,0,0,0,0,0\n")
        proc = subprocess.run([CLI, "inspect", path], capture_output=True, text=True)
        self.assertNotEqual(proc.returncode, 0)
        with self.assertRaises(rcm.InputError) as cm:
            rcm.load_recording(path)
        self.assertIn(str(cm.exception), proc.stderr)
        self.assertEqual((cm.exception.line, cm.exception.field), (3, "position_2"))

    def test_rosbag_is_refused_with_a_hint(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "run.bag")
            open(path, "wb").write(b"#ROSBAG V2.0\n")
            with self.assertRaises(rcm.InputError) as cm:
                rcm.load_recording(path)
            self.assertEqual(cm.exception.file, path)
            self.assertIn("rcm convert", str(cm.exception))

    def test_missing_column(self):
        with self.assertRaises(rcm.InputError) as cm:
            rcm.parse_recording("time,position_1,position_2,position_3\n0,0,0,0\n", "short.csv")
        self.assertTrue(str(cm.exception).startswith("short.csv:1"), str(cm.exception))

    def test_bad_session_field(self):
        with open(_state["manifest"]) as f:
            manifest = json.load(f)
        manifest["q0"] = [0.0, 0.0, 5.0]
        path = os.path.join(_state["session_dir"], "bad_session.json")
        with open(path, "w") as f:
            json.dump(manifest, f)
        with self.assertRaises(rcm.InputError) as cm:
            rcm.load_session(path)
        self.assertEqual(cm.exception.file, path)
        self.assertTrue(cm.exception.field.startswith("q0"), cm.exception.field)


class TestRecording(unittest.TestCase):
    def test_numpy_save_load_round_trip_is_exact(self):
        time, q, qd, tau, f = random_arrays()
        rec = rcm.Recording(time, q, qd, tau, force=f, source="random")
        self.assertEqual((rec.num_samples, rec.num_joints, rec.has_force), (40, 4, True))
        self.assertEqual(rec.layout, rcm.RecordingLayout.in_memory)
        path = tmp_path("round_trip.csv")
        rcm.save_recording(path, rec)
        back = rcm.load_recording(path)
        self.assertEqual(back.layout, rcm.RecordingLayout.rcm_csv)
        for name, expected in (("time", time), ("position", q), ("velocity", qd), ("effort", tau), ("force", f)):
            self.assertTrue(np.array_equal(getattr(back, name), expected), name)
            self.assertEqual(getattr(back, name).dtype, np.float64)
        self.assertEqual(list(back.line), list(range(2, 42)))

    def test_arrays_are_read_only_views(self):
        time, q, qd, tau, _ = random_arrays()
        rec = rcm.Recording(time, q, qd, tau)
        self.assertIsNone(rec.force)
        with self.assertRaises(ValueError):
            rec.position[0, 0] = 1.0
        q[0, 0] = 99.0  # the recording copied its input
        self.assertNotEqual(rec.position[0, 0], 99.0)

    def test_layouts_and_dtypes_are_converted_exactly(self):
        time, q, qd, tau, _ = random_arrays(T=30, N=3)
        ref = rcm.Recording(time, q, qd, tau)
        fortran = rcm.Recording(time, np.asfortranarray(q), qd, tau)
        strided = rcm.Recording(np.repeat(time, 2)[::2], np.repeat(q, 2, axis=0)[::2], qd, tau)
        self.assertTrue(np.array_equal(fortran.position, ref.position))
        self.assertTrue(np.array_equal(strided.position, ref.position))
        q32 = q.astype(np.float32)
        widened = rcm.Recording(time, q32, qd, tau)
        self.assertTrue(np.array_equal(widened.position, q32.astype(np.float64)))
        ints = rcm.Recording(time, np.arange(90).reshape(30, 3), qd, tau)
        self.assertEqual(ints.position[29, 2], 89.0)

    def test_bad_arrays_raise_input_error_naming_the_argument(self):
        time, q, qd, tau, _ = random_arrays(T=20, N=3)
        cases = {
            "position": lambda: rcm.Recording(time, q[:, 0], qd, tau),  # 1-D where 2-D is expected
            "velocity": lambda: rcm.Recording(time, q, qd[:19], tau),  # wrong T
            "effort": lambda: rcm.Recording(time, q, qd, tau > 0),  # bool: no silent cast
            "force": lambda: rcm.Recording(time, q, qd, tau, force=np.zeros((20, 2))),
        }
        for field, make in cases.items():
            with self.assertRaises(rcm.InputError, msg=field) as cm:
                make()
            self.assertEqual(cm.exception.field, field)
        with self.assertRaises(rcm.InputError):
            rcm.Recording(time, q.astype(np.complex128), qd, tau)
        with self.assertRaises(rcm.InputError):
            rcm.Recording(time, np.full((20, 3), 2**60, dtype=np.int64), qd, tau)
        with self.assertRaises(rcm.InputError):
            rcm.Recording(time, q[:, :2], qd[:, :2], tau[:, :2])  # fewer than 3 joints

    def test_same_validation_as_the_reader(self):
        time, q, qd, tau, _ = random_arrays(T=20, N=3)
        tau = tau.copy()
        tau[7, 1] = np.nan
        with self.assertRaises(rcm.InputError) as cm:
            rcm.Recording(time, q, qd, tau, source="mine")
        self.assertEqual(cm.exception.field, "effort_2")
        self.assertIn("sample 7", str(cm.exception))
        self.assertTrue(str(cm.exception).startswith("mine: "))
        time = time.copy()
        time[5] = time[4]
        with self.assertRaises(rcm.InputError) as cm:
            rcm.Recording(time, q, qd, np.zeros((20, 3)))
        self.assertEqual(cm.exception.field, "time")

    def test_rostopic_layout(self):
        text = (
            "%time,field.header.seq,field.header.stamp,field.header.frame_id,field.name0,field.name1,field.name2,"
            "field.position0,field.position1,field.position2,field.velocity0,field.velocity1,field.velocity2,"
            "field.effort0,field.effort1,field.effort2\n"
            "1000000000,1,1000000000,,outer_yaw,outer_pitch,outer_insertion,0.1,0.2,0.12,0,0,0,0.5,0.6,1.2\n"
            "1005000000,2,1005000000,,outer_yaw,outer_pitch,outer_insertion,0.1,0.2,0.121,0,0,0.2,0.5,0.6,1.3\n"
        )
        path = tmp_path("measured_js.csv")
        with open(path, "w") as f:
            f.write(text)
        rec = rcm.load_recording(path)
        self.assertEqual(rec.layout, rcm.RecordingLayout.rostopic_csv)
        np.testing.assert_allclose(rec.time, [1.0, 1.005], rtol=0, atol=1e-12)
        self.assertEqual(rec.position[1, 2], 0.121)
        self.assertEqual(rec.effort[1, 2], 1.3)

    def test_summary_matches_cli_inspect(self):
        path = session_file("baseline.csv")
        cli = run_cli("inspect", path, "--json")
        summary = rcm.summarize_recording(rcm.load_recording(path))
        self.assertEqual(summary.samples, cli["samples"])
        self.assertEqual(summary.joints, cli["joints"])
        for key in ("duration_s", "dt_median_s", "dt_min_s", "dt_max_s"):
            self.assertAlmostEqual(getattr(summary, key), cli[key], places=12, msg=key)
        d = summary.to_dict()
        np.testing.assert_allclose(np.array(d["effort"]), np.array(cli["effort_range"]), rtol=1e-14)

    def test_session_parts(self):
        session = rcm.load_session(_state["manifest"])
        self.assertEqual(session.robot, "dvrk-psm-classic")
        np.testing.assert_array_equal(session.q0, Q0)
        self.assertEqual([t.name for t in session.trials], list(TRUTH))
        for trial in session.trials:
            np.testing.assert_allclose(trial.truth_misalignment_m, TRUTH[trial.name], atol=1e-15)
            self.assertTrue(os.path.isfile(trial.recording))
            self.assertTrue(os.path.isfile(trial.static_recording))
        self.assertAlmostEqual(session.calibration.coaxial_offset_m, 0.03)
        self.assertEqual(os.path.basename(session.free_space[0]), "free_space.csv")
        self.assertIn("simulator", session.extra)


    def test_rosbag2_mcap_with_topics_and_cli_agreement(self):
        here = os.path.dirname(os.path.abspath(__file__))
        path = os.path.join(here, "..", "..", "tests", "data", "rosbag2", "joint_states_zstd.mcap")
        rec = rcm.load_recording(path, force_topic="/PSM1/body/measured_cf")
        self.assertEqual(rec.layout, rcm.RecordingLayout.rosbag2)
        self.assertEqual(rec.position.shape, (50, 7))
        np.testing.assert_allclose(rec.time, 0.01 * np.arange(50), atol=1e-12)
        np.testing.assert_array_equal(rec.velocity[:, 6], np.full(50, 0.07))
        self.assertTrue(rec.has_force)
        cli = run_cli("inspect", "--json", "--force-topic", "/PSM1/body/measured_cf", path)
        np.testing.assert_array_equal(np.array(rcm.summarize_recording(rec).to_dict()["force"]), np.array(cli["force_range"]))
        with self.assertRaises(rcm.InputError) as cm:
            rcm.load_recording(path, topic="/PSM1/body/measured_cf")
        self.assertIn("expected sensor_msgs/msg/JointState", str(cm.exception))
        with self.assertRaises(rcm.InputError) as cm:
            rcm.load_recording(path, time="bag")
        self.assertIn("'header' or 'receive'", str(cm.exception))
        with self.assertRaises(rcm.InputError) as cm:
            rcm.load_recording(_state["manifest"].replace("session.json", "free_space.csv"), topic="/x")
        self.assertIn("applies to rosbag2 recordings", str(cm.exception))


class TestKinematics(unittest.TestCase):
    CASES = [
        ([0.3, -0.2, 0.15], [0.0, 0.0, 0.12], 0.03),
        ([-0.5, 0.4, 0.10], [0.1, -0.1, 0.12], 0.05),
        ([0.0, 0.0, 0.12], [0.0, 0.0, 0.12], 0.0),  # at the RCM: J_D singular
    ]

    def test_matches_cli(self):
        for q, q0, D in self.CASES:
            cli = run_cli("kinematics", "--q", ",".join(map(repr, q)), "--q0", ",".join(map(repr, q0)),
                          "--offset", repr(D), "--json")
            k = rcm.compute_incision_kinematics(q, q0=q0, offset=D)
            d = k.to_dict()
            self.assertEqual(d["status"], cli["status"])
            np.testing.assert_allclose(d["z3"], cli["z3"], rtol=1e-14, atol=1e-15)
            self.assertAlmostEqual(d["theta"], cli["theta"], places=14)
            np.testing.assert_allclose(d["frame3"]["position_m"], cli["frame3"]["position_m"], atol=1e-15)
            np.testing.assert_allclose(d["frame3"]["rotation_rows"], cli["frame3"]["rotation_rows"], atol=1e-15)
            if cli["condition"] is None:
                self.assertIsNone(d["condition"])
                self.assertEqual(k.status, rcm.JacobianStatus.singular)
            else:
                self.assertAlmostEqual(d["condition"] / cli["condition"], 1.0, places=12)
                np.testing.assert_allclose(k.J_inc_base, cli["J_inc_base"], rtol=1e-13, atol=1e-15)
                np.testing.assert_allclose(d["J_inc_base"], cli["J_inc_base"], rtol=1e-13, atol=1e-15)

    def test_jacobian_cross_identities(self):
        model = rcm.load_robot_model("dvrk-psm-classic")
        data = rcm.KinematicsData()
        rng = np.random.default_rng(5)
        incision = rcm.make_incision_frame(Q0)
        for _ in range(5):
            q = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.5, 0.5), rng.uniform(0.08, 0.2)])
            s = rcm.compute_shaft_distance(incision, q, 0.04)
            J = rcm.compute_incision_jacobian(q, s)
            np.testing.assert_allclose(J, rcm.compute_incision_jacobian_dh(model, data, q, s), atol=1e-12)
            rcm.compute_forward_kinematics(model, data, q)
            X = rcm.get_frame_pose(data, 3)
            np.testing.assert_allclose(X[:3, 2], rcm.compute_z3_base(q), atol=1e-12)
            # Column 3 of J_D is the insertion axis; columns 1-2 are s dz3/dq (central differences).
            h = 1e-6
            for j in range(2):
                dq = np.zeros(3)
                dq[j] = h
                fd = s * (rcm.compute_z3_base(q + dq) - rcm.compute_z3_base(q - dq)) / (2 * h)
                np.testing.assert_allclose(J[:, j], fd, atol=1e-8)

    def test_bad_input(self):
        with self.assertRaises(rcm.InputError) as cm:
            rcm.compute_incision_kinematics([0.0, 0.0, 5.0])
        self.assertEqual(cm.exception.field, "q[2]")
        with self.assertRaises(rcm.InputError) as cm:
            rcm.compute_incision_kinematics([0.0, 0.0])
        self.assertEqual(cm.exception.field, "q")
        with self.assertRaises(rcm.InputError):
            rcm.compute_incision_kinematics([0.0, 0.0, 0.12], offset=float("nan"))
        with self.assertRaises(rcm.InputError):
            rcm.load_robot_model("no-such-robot")


class TestDynamics(unittest.TestCase):
    def model(self):
        return _state["fit"].model

    def test_submodules_import(self):
        import rcm.dynamics
        import rcm.sim
        self.assertIs(rcm.dynamics.TorqueModel, rcm.dynamics.LinearTorqueModel.__mro__[1])
        self.assertIsInstance(rcm.sim.QUICK_PROTOCOL["protocol"]["free_space_s"], float)

    def test_rigid_body_regressors_give_the_model_its_torque(self):
        # The default linear fit has the rigid-body structure, its inertia tied
        # by the bodies of a remote-centre arm (the simulated arm is one); its offline
        # torque at one sample is rebuilt from the exposed regressors.
        model = self.model()
        p = model.parameters
        self.assertEqual(_state["fit"].summary.structure, "remote-center")
        self.assertEqual(len(p.inertia), 19)
        self.assertAlmostEqual(float(np.linalg.norm(p.gravity_direction)), 1.0, places=12)
        q, qd, qdd = [0.2, -0.3, 0.14], [0.5, -0.4, 0.05], [1.0, 2.0, -0.3]
        Y = rcm.dynamics.compute_inertia_regressor(q, qd, qdd)
        self.assertEqual(Y.shape, (3, 19))
        self.assertEqual(rcm.dynamics.compute_gravity_regressor(q).shape, (3, 17))
        P = rcm.dynamics.compute_gravity_moment_map(p.gravity_direction)
        self.assertEqual(P.shape, (17, 7))
        # The fitted potential is one of rigid links under that direction: in P's span.
        v = np.linalg.lstsq(P, p.gravity, rcond=None)[0]
        np.testing.assert_allclose(P @ v, p.gravity, atol=1e-9 * (1 + np.abs(p.gravity).max()))
        # A point mass m on the instrument axis: yaw inertia m q3^2 sin^2 q2.
        m, theta = 0.3, np.zeros(19)
        theta[[1, 4, 15]] = [m / 2, -m / 2, m]
        tau = Y @ theta
        s2 = np.sin(q[1])
        expected_yaw = m * (2 * q[2] * qd[2] * s2 ** 2 * qd[0] + q[2] ** 2 * 2 * s2 * np.cos(q[1]) * qd[1] * qd[0]
                            + q[2] ** 2 * s2 ** 2 * qdd[0])
        self.assertAlmostEqual(tau[0], expected_yaw, places=12)
        with self.assertRaises(rcm.InputError):
            rcm.dynamics.compute_inertia_regressor(q, qd[:2], qdd)

    def test_fit_matches_cli_fit(self):
        out = tmp_path("cli_linear.json")
        run_cli("dynamics", "fit", "--model", "linear", "--out", out, session_file("free_space.csv"), json_out=False)
        cli_model = rcm.dynamics.load_torque_model(out)
        self.assertIsInstance(cli_model, rcm.dynamics.LinearTorqueModel)
        cal = rcm.load_recording(session_file("calibration.csv"))
        np.testing.assert_allclose(rcm.dynamics.predict_torque(self.model(), cal),
                                   rcm.dynamics.predict_torque(cli_model, cal), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(self.model().parameters.gravity, cli_model.parameters.gravity, rtol=1e-9, atol=1e-12)

    def test_eval_matches_cli(self):
        cli = run_cli("dynamics", "eval", _state["model_path"], session_file("free_space.csv"), "--json")
        errors = rcm.dynamics.evaluate_torque_model(self.model(), [_state["free"]])
        self.assertEqual(len(errors), len(cli["joints"]))
        for e, c in zip(errors, cli["joints"]):
            self.assertEqual(e.index, c["index"])
            self.assertAlmostEqual(e.rmse / c["rmse"], 1.0, places=12)
            self.assertAlmostEqual(e.nrmse_percent / c["nrmse_percent"], 1.0, places=12)
        cli_streaming = run_cli("dynamics", "eval", _state["model_path"], session_file("free_space.csv"), "--json",
                                "--streaming")
        self.assertEqual(cli_streaming["mode"], "streaming")
        streaming = rcm.dynamics.evaluate_torque_model(self.model(), [_state["free"]], streaming=True)
        for e, c in zip(streaming, cli_streaming["joints"]):
            self.assertAlmostEqual(e.rmse / c["rmse"], 1.0, places=12)
        measured = _state["free"].effort[:, :3]
        streamed = rcm.dynamics.predict_torque_streaming(self.model(), _state["free"])
        for e, k in zip(streaming, range(3)):
            self.assertAlmostEqual(e.rmse, float(np.sqrt(np.mean((streamed[:, k] - measured[:, k]) ** 2))), places=12)
        # The held-out split of the fit: the linear model's accuracy on the bench.
        summary = _state["fit"].summary
        self.assertEqual([e.index for e in summary.test_errors], [1, 2, 3])
        self.assertLess(summary.test_errors[0].nrmse_percent, 10.0)

    def test_save_load_is_bit_exact(self):
        loaded = rcm.dynamics.load_torque_model(_state["model_path"])
        self.assertEqual(loaded.kind, rcm.dynamics.TorqueModelKind.linear)
        rec = _state["free"]
        self.assertTrue(np.array_equal(rcm.dynamics.predict_torque(loaded, rec), rcm.dynamics.predict_torque(self.model(), rec)))
        self.assertEqual(loaded.to_json()["parameters"], self.model().to_json()["parameters"])

    def test_streaming_step_equals_sequence(self):
        model = self.model()
        rec = rcm.load_recording(session_file("D30_r10_15.csv"))
        T = 1500
        streamed = rcm.dynamics.predict_torque_streaming(model, rec.time[:T], rec.position[:T], rec.velocity[:T])
        ws = model.create_workspace()
        steps = np.array([model.compute_step(ws, rec.time[t], rec.position[t], rec.velocity[t]) for t in range(T)])
        self.assertEqual(steps.shape, (T, model.num_outputs))
        self.assertEqual(model.output_delay, 0)  # so step t is row t
        self.assertTrue(np.array_equal(steps, streamed))
        # reset_state forgets the friction memory: the first steps repeat exactly.
        model.reset_state(ws)
        again = np.array([model.compute_step(ws, rec.time[t], rec.position[t], rec.velocity[t]) for t in range(20)])
        self.assertTrue(np.array_equal(again, steps[:20]))
        # Offline, the fitted model's qddot is zero-phase (uses later samples): not the causal stream.
        offline = rcm.dynamics.predict_torque(model, rec.time[:T], rec.position[:T], rec.velocity[:T])
        self.assertGreater(np.max(np.abs(offline - streamed)), 1e-6)
        # With the zero-phase window off, whole-sequence prediction is the step loop.
        document = model.to_json()
        zeros = base64.b64encode(np.zeros(model.num_outputs, dtype="<f8").tobytes()).decode()
        document["parameters"]["batch_acceleration_window_s"]["data"] = zeros
        causal = rcm.dynamics.torque_model_from_json(document)
        self.assertTrue(np.array_equal(rcm.dynamics.predict_torque(causal, rec.time[:T], rec.position[:T],
                                                                   rec.velocity[:T]), streamed))

    def test_workspace_and_step_checks(self):
        model = self.model()
        other = rcm.dynamics.load_torque_model(_state["model_path"])
        ws = other.create_workspace()
        with self.assertRaises(rcm.InputError) as cm:
            model.compute_step(ws, 0.0, [0, 0, 0.12], [0, 0, 0])
        self.assertEqual(cm.exception.field, "workspace")
        ws = model.create_workspace()
        with self.assertRaises(rcm.InputError) as cm:
            model.compute_step(ws, 0.0, [0, 0], [0, 0, 0])
        self.assertEqual(cm.exception.field, "q")
        with self.assertRaises(rcm.InputError):
            model.compute_step(ws, float("nan"), [0, 0, 0.12], [0, 0, 0])
        with self.assertRaises(rcm.InputError):
            rcm.dynamics.fit_torque_model(rcm.dynamics.TorqueModelKind.lstm, [_state["free"]])
        with self.assertRaises(rcm.InputError):
            rcm.dynamics.predict_torque(model, [0.0, 0.005], np.zeros((2, 2)), np.zeros((2, 2)))
        with self.assertRaises(rcm.InputError) as cm:
            rcm.dynamics.load_torque_model(session_file("session.json"))
        self.assertEqual(cm.exception.file, session_file("session.json"))


class TestForce(unittest.TestCase):
    def test_series_matches_cli(self):
        path = session_file("D30_r10_15.csv")
        out = tmp_path("force.csv")
        cli = run_cli("force", "--model", _state["model_path"], "--offset", "0.03", "--q0", "0,0,0.12", path,
                      "--out", out, "--json")
        rec = rcm.load_recording(path)
        tau_fs = rcm.dynamics.predict_torque(_state["fit"].model, rec)
        incision = rcm.make_incision_frame(Q0)
        series = rcm.compute_incision_force_series(incision, rec, tau_fs, 0.03)
        with open(out) as f:
            rows = list(csv.DictReader(f))
        self.assertEqual(len(rows), rec.num_samples)
        cli_f = np.array([[float(r["force_x"]), float(r["force_y"]), float(r["force_z"])] for r in rows])
        np.testing.assert_allclose(series.f_inc_base, cli_f, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(series.theta, [float(r["theta"]) for r in rows], rtol=1e-14, atol=1e-15)
        self.assertEqual([rcm.JacobianStatus.__members__[r["status"]] for r in rows], list(series.status))
        self.assertEqual(series.num_singular, cli["singular"])
        self.assertEqual(series.num_ill_conditioned, cli["ill_conditioned"])
        rmse = np.sqrt(np.mean((series.f_inc_base - rec.force) ** 2, axis=0))
        np.testing.assert_allclose(rmse, [cli["rmse"]["x"], cli["rmse"]["y"], cli["rmse"]["z"]], rtol=1e-10)
        # One sample through the per-sample function is the same row.
        t = 1234
        one = rcm.compute_incision_force(incision, rec.position[t, :3], 0.03, rec.effort[t, :3] - tau_fs[t, :3])
        np.testing.assert_allclose(one.f_inc_base, series.f_inc_base[t], rtol=1e-14, atol=1e-14)

    def test_tau_fs_shape_is_checked(self):
        rec = rcm.load_recording(session_file("baseline.csv"))
        with self.assertRaises(rcm.InputError):
            rcm.compute_incision_force_series(rcm.make_incision_frame(Q0), rec, np.zeros((rec.num_samples - 1, 3)), 0.03)


def quiet_study_options(**fields):
    options = rcm.StudyOptions()
    options.verbose = False
    options.model_file = _state["model_path"]
    for key, value in fields.items():
        setattr(options, key, value)
    return options


class TestThreeStep(unittest.TestCase):
    def test_run_study_matches_cli_run(self):
        cli = run_cli("run", _state["manifest"], "--model-file", _state["model_path"], "--out", tmp_path("run_cli"),
                      "--json")
        session = rcm.load_session(_state["manifest"])
        result = rcm.run_study(session, quiet_study_options())
        mine = result.to_json()
        self.assertEqual(mine["tissue_model"]["expression"], cli["tissue_model"]["expression"])
        self.assertEqual([t["name"] for t in mine["trials"]], [t["name"] for t in cli["trials"]])
        for a, b in zip(mine["trials"], cli["trials"]):
            np.testing.assert_allclose(a["misalignment_m"], b["misalignment_m"], rtol=1e-9, atol=1e-12)
        for trial in result.trials:
            self.assertTrue(trial.estimate.solver.converged, trial.estimate.solver.brief_report())
            self.assertLess(trial.get_error_m(), 0.005)
        _state["study"] = result

    def test_steps_by_hand_equal_the_study(self):
        if "study" not in _state:
            self.test_run_study_matches_cli_run()
        study = _state["study"]
        session = rcm.load_session(_state["manifest"])
        model = rcm.dynamics.load_torque_model(_state["model_path"])
        incision = rcm.make_incision_frame(session.q0)
        cal = rcm.load_recording(session.calibration.recording)
        pairs = rcm.compute_tissue_pairs(cal, rcm.dynamics.predict_torque(model, cal), session.q0,
                                         session.calibration.coaxial_offset_m)
        self.assertGreater(pairs.report.kept, 100)
        law = rcm.fit_tissue_law(pairs.pairs).law
        self.assertEqual(law.to_string(), study.tissue.law.to_string())
        spec = session.trials[1]
        trial = rcm.load_recording(spec.recording)
        hold_rec = rcm.load_recording(spec.static_recording)
        # As the study does: the static file's encoder chatter removed before the model reads it.
        width = 1.5 * rcm.estimate_position_quantum(hold_rec)
        tau_hold = rcm.dynamics.predict_torque(model, rcm.remove_position_chatter(hold_rec, width))
        hold = rcm.compute_static_hold(hold_rec, tau_hold, session.q0)
        result = rcm.estimate_three_step(incision, law, trial, rcm.dynamics.predict_torque(model, trial), hold.get_dtau())
        self.assertTrue(result.solver.converged)
        np.testing.assert_allclose(result.misalignment_m, study.trials[1].estimate.misalignment_m, rtol=1e-12, atol=1e-15)
        self.assertLess(np.linalg.norm(result.misalignment_m - TRUTH[spec.name]), 0.005)

    def test_session_without_calibration_is_an_input_error(self):
        session = rcm.load_session(_state["manifest"])
        session.calibration = None
        with self.assertRaises(rcm.InputError) as cm:
            rcm.run_study(session, quiet_study_options())
        self.assertEqual(cm.exception.field, "calibration")


class TestOnline(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        session = rcm.load_session(_state["manifest"])
        cls.session = session
        cls.setup = rcm.prepare_monitor(session, quiet_study_options())
        cls.trial = rcm.load_recording(session_file("D30_r10_15.csv"))

    def make_pipeline(self):
        setup = self.setup
        estimator = rcm.OnlineEstimator(setup.incision, setup.tissue, rcm.make_online_options(setup.joint_options))
        return rcm.OnlinePipeline(setup.free_space.model, estimator)

    def test_replay_matches_cli_monitor(self):
        cli = run_cli("monitor", "--session", _state["manifest"], "--model-file", _state["model_path"],
                      session_file("D30_r10_15.csv"), "--json")
        self.assertAlmostEqual(self.setup.tissue.parameters[0] / cli["tissue"]["k1"], 1.0, places=10)
        replay = rcm.replay_online(self.make_pipeline(), self.trial)
        self.assertEqual(replay.samples, cli["samples"])
        np.testing.assert_allclose(replay.final_output.misalignment_m, cli["final"]["misalignment_m"], rtol=1e-9,
                                   atol=1e-12)
        np.testing.assert_allclose(replay.final_output.sd_m, cli["final"]["sd_m"], rtol=1e-9)
        self.assertAlmostEqual(replay.onset_s, cli["onset_s"], places=9)
        self.assertEqual(len(replay.alarms), len(cli["alarms"]))
        for a, b in zip(replay.alarms, cli["alarms"]):
            self.assertAlmostEqual(a.raised_s, b["raised_s"], places=9)
        self.assertLess(np.linalg.norm(replay.final_output.misalignment_m - TRUTH["D30_r10_15"]), 0.002)
        self.assertEqual(replay.regime.flagged, cli["regime"]["flagged"])
        self.assertEqual(replay.regime.samples, cli["regime"]["samples"])

    def test_training_regime_flags_a_faster_replay(self):
        model = self.setup.free_space.model
        regime = model.info.regime
        self.assertTrue(regime.known)
        self.assertEqual(len(regime.position_min), model.num_joints)
        self.assertEqual(rcm.dynamics.compute_regime_summary(model, self.trial).to_dict()["checked"], True)
        # The trial replayed three times as fast: velocities beyond anything in free space.
        rec = self.trial
        fast = rcm.Recording(rec.time / 3.0, rec.position, rec.velocity * 3.0, rec.effort, source="fast")
        summary = rcm.dynamics.compute_regime_summary(model, fast)
        self.assertGreater(summary.flagged, 0)
        self.assertIn("velocity", str(summary))
        pipeline = self.make_pipeline()
        ws = pipeline.create_workspace()
        flagged = 0
        for t in range(fast.num_samples):
            out = pipeline.compute_sample(ws, fast.time[t], fast.position[t], fast.velocity[t], fast.effort[t])
            flagged += out.out_of_regime
            if out.out_of_regime:
                self.assertNotEqual(out.regime_flags, 0)
                self.assertIn("joint", rcm.dynamics.describe_regime_flags(out.regime_flags))
        self.assertEqual(flagged, summary.flagged)

    def test_per_sample_pipeline_equals_replay(self):
        pipeline = self.make_pipeline()
        seen = []
        replay = rcm.replay_online(pipeline, self.trial, on_sample=lambda out: seen.append(out.misalignment_m.copy()))
        self.assertEqual(len(seen), self.trial.num_samples)
        ws = pipeline.create_workspace()
        rec = self.trial
        for t in range(rec.num_samples):
            out = pipeline.compute_sample(ws, rec.time[t], rec.position[t], rec.velocity[t], rec.effort[t])
            if t % 500 == 0:
                self.assertTrue(np.array_equal(out.misalignment_m, seen[t]), t)
        self.assertTrue(np.array_equal(out.misalignment_m, replay.final_output.misalignment_m))
        self.assertEqual(out.onset, replay.final_output.onset)
        # reset: the stream starts over.
        pipeline.reset(ws)
        first = pipeline.compute_sample(ws, rec.time[0], rec.position[0], rec.velocity[0], rec.effort[0])
        self.assertTrue(np.array_equal(first.misalignment_m, seen[0]))
        with self.assertRaises(rcm.InputError):
            self.make_pipeline().compute_sample(ws, 0.0, rec.position[0], rec.velocity[0], rec.effort[0])
        with self.assertRaises(rcm.InputError):
            pipeline.compute_sample(ws, 0.0, rec.position[0, :2], rec.velocity[0], rec.effort[0])

    def test_correction_loop_matches_cli_monitor(self):
        cli = run_cli("monitor", "--session", _state["manifest"], "--model-file", _state["model_path"],
                      session_file("D30_r10_15.csv"), "--json")
        corrector = rcm.RcmCorrector(self.setup.incision, rcm.CorrectionOptions())
        loop = rcm.CorrectionLoop(self.make_pipeline(), corrector)
        rec = self.trial
        changes = []
        for t in range(rec.num_samples):
            # A replay: the recorded RCM never moved, so no shift is in effect.
            estimate, correction = loop.step(rec.time[t], rec.position[t], rec.velocity[t], rec.effort[t])
            if correction.changed:
                changes.append((correction.time, str(correction.action).split(".")[-1], corrector.describe(correction)))
        np.testing.assert_allclose(estimate.misalignment_m, cli["final"]["misalignment_m"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(correction.move_base, cli["correction"]["move_base_m"], rtol=1e-9, atol=1e-12)
        self.assertEqual(str(correction.action).split(".")[-1], cli["correction"]["action"])
        self.assertEqual([c[1] for c in changes], [c["action"] for c in cli["correction"]["changes"]])
        self.assertEqual([c[2] for c in changes], [c["advice"] for c in cli["correction"]["changes"]])
        # 30 mm deep and 18 mm across: beyond the software limit, a re-docking in words.
        self.assertEqual(correction.action, rcm.CorrectionAction.reposition)
        self.assertIn("deeper along the instrument", corrector.describe(correction))
        check = rcm.check_alignment(estimate, self.setup.incision)
        self.assertFalse(check.aligned)
        self.assertEqual(check.message, cli["alignment"]["message"])
        with self.assertRaises(rcm.InputError):
            loop.step(0.0, rec.position[0], rec.velocity[0], rec.effort[0], [float("nan"), 0.0, 0.0])

    def test_joint_estimate_of_a_trial(self):
        setup = self.setup
        spec = self.session.trials[1]
        model = setup.free_space.model
        samples = rcm.make_joint_samples(setup.incision, self.trial, rcm.dynamics.predict_torque(model, self.trial))
        hold_rec = rcm.load_recording(spec.static_recording)
        width = 1.5 * rcm.estimate_position_quantum(hold_rec)
        tau_hold = rcm.dynamics.predict_torque(model, rcm.remove_position_chatter(hold_rec, width))
        samples.extend(rcm.make_joint_samples(setup.incision, hold_rec, tau_hold))
        options = setup.joint_options
        options.bootstrap_replicates = 10  # the interval's width is not under test; its existence is
        estimate = rcm.estimate_joint(setup.incision, setup.tissue, samples, options)
        self.assertTrue(estimate.solver.converged, estimate.solver.brief_report())
        self.assertEqual(estimate.samples, len(samples))
        truth = np.array(TRUTH[spec.name])
        self.assertLess(np.linalg.norm(estimate.misalignment_m - truth), 0.002)
        self.assertTrue(np.all(estimate.ci_low <= estimate.misalignment_m))
        self.assertTrue(np.all(estimate.misalignment_m <= estimate.ci_high))


class TestSim(unittest.TestCase):
    def test_simulate_session_matches_cli(self):
        config = rcm.sim.SimConfig()
        config.update(SIM_OVERRIDES)
        config.update(rcm.sim.QUICK_PROTOCOL)
        config.update({"protocol": {"write_truth": False}})
        out = tmp_path("py_session")
        messages = []
        summary = rcm.sim.simulate_session(config, out, progress=messages.append)
        self.assertEqual(len(summary.recordings), 7)  # free space, baseline, calibration, 2 x (trial + static)
        self.assertEqual(len(messages), 7)
        for name in sorted(os.listdir(_state["session_dir"])):
            if not name.endswith(".csv"):
                continue
            with open(os.path.join(out, name), "rb") as a, open(session_file(name), "rb") as b:
                self.assertTrue(a.read() == b.read(), f"{name} differs from the CLI's")
        self.assertEqual(rcm.load_session(summary.manifest).trials[1].name, "D30_r10_15")

    def test_config_errors(self):
        config = rcm.sim.SimConfig()
        with self.assertRaises(rcm.InputError) as cm:
            config.update({"protocol": {"no_such_field": 1}})
        self.assertIn("no_such_field", str(cm.exception))
        with self.assertRaises(rcm.InputError):
            rcm.sim.apply_tissue_preset(config, "granite")
        self.assertIn("stiffening", rcm.sim.get_tissue_preset_names())
        self.assertEqual(config.to_dict()["protocol"]["free_space_s"], 900.0)


if __name__ == "__main__":
    unittest.main()
