"""Tests of the Python module `rcm`, cross-checked against the C++ CLI: its
errors, recordings and sessions, kinematics. The torque models and the
incision force are in test_rcm_dynamics.py, the estimators, the study and the
simulator in test_rcm_estimation.py; the session they share in
rcm_test_support.py.

Run by CTest (python/CMakeLists.txt) with PYTHONPATH=<build>/python and
RCM_CLI=<build>/bin/rcm. By hand:

    cd python/tests && PYTHONPATH=../../build-py/python RCM_CLI=../../build-py/bin/rcm \
        /usr/bin/python3 -m unittest -v test_rcm test_rcm_dynamics test_rcm_estimation
"""

import json
import os
import subprocess
import tempfile
import unittest

import numpy as np

import rcm
from rcm_test_support import (CLI, Q0, TRUTH, _state, random_arrays, run_cli, session_file, set_up_session, tmp_path)


def setUpModule():
    set_up_session()


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
            d = rcm.compute_shaft_directions(q)
            np.testing.assert_allclose(np.column_stack([d.x3, d.y3, d.z3]), X[:3, :3], atol=1e-12)
            np.testing.assert_allclose(np.column_stack([s * d.dz3_dq1, s * d.dz3_dq2, d.z3]), J, atol=1e-12)

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


if __name__ == "__main__":
    unittest.main()


class TestIterRecording(unittest.TestCase):
    def test_chunks_are_the_whole_recording(self):
        path = session_file("D30_r10_15.csv")
        whole = rcm.load_recording(path)
        chunks = list(rcm.iter_recording(path, chunk_rows=1000))
        self.assertEqual([len(c) for c in chunks[:-1]], [1000] * (len(chunks) - 1))
        for name in ("time", "position", "velocity", "effort", "force", "line"):
            np.testing.assert_array_equal(np.concatenate([getattr(c, name) for c in chunks]), getattr(whole, name))

    def test_a_defect_in_a_later_chunk_names_its_line(self):
        path = tmp_path("late_defect.csv")
        with open(path, "w") as f:
            f.write("time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,effort_3\n")
            for k in range(100):
                f.write(f"{0.005 * k},0,0,0.1,0,0,0,0,{'x' if k == 90 else 0},0\n")
        chunks = rcm.iter_recording(path, chunk_rows=16)
        self.assertEqual(len(next(chunks)), 16)
        with self.assertRaises(rcm.InputError) as cm:
            list(chunks)
        self.assertEqual((cm.exception.line, cm.exception.field), (92, "effort_2"))

    def test_torque_stream_and_steps_take_chunks(self):
        path = session_file("D30_r10_15.csv")
        model = rcm.dynamics.load_torque_model(_state["model_path"])
        whole = rcm.dynamics.predict_torque(model, rcm.load_recording(path))
        stream = rcm.dynamics.RecordingTorqueStream(model)
        rows = [stream.add(c)[1] for c in rcm.iter_recording(path, chunk_rows=500)] + [stream.finish()[1]]
        np.testing.assert_array_equal(np.concatenate(rows), whole)
        # compute_steps carries the state from block to block: blocks give one pass's outputs.
        ws = model.create_workspace()
        steps = [model.compute_steps(ws, c.time, c.position, c.velocity) for c in rcm.iter_recording(path, 300)]
        rec = rcm.load_recording(path)
        one_pass = model.compute_steps(model.create_workspace(), rec.time, rec.position, rec.velocity)
        np.testing.assert_array_equal(np.concatenate(steps), one_pass)
        if model.output_delay == 0:
            np.testing.assert_array_equal(one_pass, rcm.dynamics.predict_torque_streaming(model, rec))
