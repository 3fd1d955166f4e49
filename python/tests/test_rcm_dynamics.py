"""Tests of the Python module's torque models (rcm.dynamics) and the incision
force, cross-checked against the C++ CLI (rcm_test_support.py)."""

import base64
import csv
import unittest

import numpy as np

import rcm
from rcm_test_support import (Q0, _state, run_cli, session_file, set_up_session, tmp_path)


def setUpModule():
    set_up_session()


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
        # by the bodies of a remote-centre arm (the simulated arm is one); its
        # offline torque at one sample is rebuilt from the exposed regressors.
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

    def test_coulomb_profile_is_exposed_with_its_range(self):
        # Kept or not by the fit; when kept, one row per joint over the range
        # the joint covered, zero at the first knot; the option table has it.
        p = self.model().parameters
        self.assertEqual(len(p.coulomb_slow), 3)
        self.assertEqual(len(p.sqrt_viscous), 3)
        # The insertion's stiffness comes with the rigid-body structure, on the insertion only.
        self.assertEqual(len(p.stiffness), 3)
        self.assertEqual(p.stiffness[0], 0.0)
        self.assertEqual(p.stiffness[1], 0.0)
        if p.coulomb_profile.size:
            self.assertEqual(p.coulomb_profile.shape[0], 3)
            self.assertGreaterEqual(p.coulomb_profile.shape[1], 2)
            np.testing.assert_array_equal(p.coulomb_profile[:, 0], 0.0)
            self.assertEqual(p.coulomb_profile_range.shape, (3, 2))
            self.assertTrue((p.coulomb_profile_range[:, 1] > p.coulomb_profile_range[:, 0]).all())
        else:
            self.assertEqual(p.coulomb_profile_range.size, 0)
        options = rcm.dynamics.FitOptions()
        self.assertTrue(options.coulomb_profile)

    def test_zero_phase_acceleration_degree(self):
        # A fit takes qddot from the slope of a local cubic, one window per joint.
        p = self.model().parameters
        self.assertEqual(p.batch_acceleration_degree, 3)
        self.assertEqual(len(p.batch_acceleration_window_s), 3)
        self.assertTrue((p.batch_acceleration_window_s > 0).all())

    def test_refit_payload(self):
        # On the recording the model was fitted on there is no payload to find:
        # the residual does not grow, the weight and the inertia found are small
        # (the inertia against the armatures the fit found); the model it
        # returns predicts like any other. A generic potential is refused.
        free = rcm.load_recording(session_file("free_space.csv"))
        out = rcm.dynamics.refit_payload(self.model(), [free])
        self.assertEqual(out["samples"], free.num_samples)
        self.assertLess(abs(out["payload"]["weight_n"]), 0.2)
        armature = self.model().parameters.armature
        for j in range(2):
            self.assertLess(abs(out["payload"]["inertia_kg_m2"][j]), 0.05 * armature[j])
        # The refit minimizes the residual pooled over the joints (one joint's
        # may grow a little while the sum shrinks).
        before = sum(r * r for r in out["rms_before"])
        after = sum(r * r for r in out["rms_after"])
        self.assertLessEqual(after, before + 1e-12)
        self.assertEqual(rcm.dynamics.predict_torque(out["model"], free).shape, (free.num_samples, 3))
        options = rcm.dynamics.FitOptions()
        options.verbose = False
        options.rigid_body = False
        generic = rcm.dynamics.fit_linear_torque_model([free], options).model
        with self.assertRaises(rcm.InputError):
            rcm.dynamics.refit_payload(generic, [free])

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
        # The spread of its bulk: near the RMSE on the bench's spike-free errors (no `rcm setup` spike note, which
        # takes a ratio of 1.5); a streamed evaluation has none.
        for e in summary.test_errors:
            self.assertGreater(e.robust_sd, e.rmse / 1.5)
            self.assertLess(e.robust_sd, 1.05 * e.rmse)
        self.assertTrue(all(np.isnan(e.robust_sd) for e in streaming))

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
        # The default fit runs its zero-phase qddot live: step t is the torque of sample t - d.
        d = model.output_delay
        self.assertTrue(model.parameters.live_zero_phase)
        self.assertGreater(d, 0)
        self.assertAlmostEqual(model.output_delay_s, d * model.info.sample_period_s)
        self.assertTrue(np.array_equal(steps[d:], streamed[:T - d]))
        # The samples each step ran: with a gap in the stream, several at once; every one with its own torque.
        ws = model.create_workspace()
        gap = 1.0
        times = np.concatenate([rec.time[:600], rec.time[600:T] + gap])
        ran_times, ran_torques = [], []
        for t in range(T):
            model.compute_step(ws, times[t], rec.position[t], rec.velocity[t])
            ran_t, ran_tau = model.get_step_runs(ws)
            ran_times.extend(ran_t)
            ran_torques.extend(ran_tau)
        self.assertEqual(len(ran_times), len(ran_torques))
        self.assertTrue(np.all(np.diff(ran_times) > 0))
        self.assertTrue(np.array_equal(ran_times, times[:len(ran_times)]))  # each sample once, in order
        self.assertGreater(len(ran_times), T - 2 * d)
        gapped = rcm.dynamics.predict_torque_streaming(model, times, rec.position[:T], rec.velocity[:T])
        self.assertTrue(np.array_equal(np.array(ran_torques), gapped[:len(ran_torques)]))
        # reset_state forgets the friction memory and the window: the first steps repeat exactly.
        model.reset_state(ws)
        again = np.array([model.compute_step(ws, rec.time[t], rec.position[t], rec.velocity[t]) for t in range(d + 20)])
        self.assertTrue(np.array_equal(again, steps[:d + 20]))
        # Away from the stream's ends, the live torque is the offline one.
        offline = rcm.dynamics.predict_torque(model, rec.time[:T], rec.position[:T], rec.velocity[:T])
        inner = slice(d, T - d)
        self.assertLess(np.max(np.abs(offline[inner] - streamed[inner])), 1e-9 * np.max(np.abs(offline)))
        # Without the flag, the step is causal (no delay) and differs from the offline torque.
        document = model.to_json()
        del document["parameters"]["live_zero_phase"]
        causal = rcm.dynamics.torque_model_from_json(document)
        self.assertEqual(causal.output_delay, 0)
        self.assertIsNone(causal.get_step_runs(causal.create_workspace()))  # one torque per call
        causal_stream = rcm.dynamics.predict_torque_streaming(causal, rec.time[:T], rec.position[:T], rec.velocity[:T])
        self.assertGreater(np.max(np.abs(offline - causal_stream)), 1e-6)
        # With the zero-phase window off too, whole-sequence prediction is the step loop.
        zeros = base64.b64encode(np.zeros(model.num_outputs, dtype="<f8").tobytes()).decode()
        document["parameters"]["batch_acceleration_window_s"]["data"] = zeros
        plain = rcm.dynamics.torque_model_from_json(document)
        self.assertTrue(np.array_equal(rcm.dynamics.predict_torque(plain, rec.time[:T], rec.position[:T],
                                                                   rec.velocity[:T]),
                                       rcm.dynamics.predict_torque_streaming(plain, rec.time[:T], rec.position[:T],
                                                                             rec.velocity[:T])))

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


class TestExcitation(unittest.TestCase):
    def test_design_matches_cli_and_respects_its_limits(self):
        # A short design, so that the test stays quick; the CLI's CSV for the
        # same options holds the same samples.
        o = rcm.dynamics.ExcitationOptions(duration_s=12.0, period_s=6.0, harmonics=3, max_iterations=15, seed=4)
        t = rcm.dynamics.design_excitation(o)
        self.assertEqual(t.position.shape, (len(t.time), 3))
        self.assertEqual(t.velocity.shape, t.acceleration.shape)
        self.assertTrue(t.summary.limits_satisfied)
        self.assertEqual(t.summary.periods, 2)
        np.testing.assert_allclose(t.position[0], o.q0, atol=1e-12)
        np.testing.assert_allclose(t.position[-1], o.q0, atol=1e-9)
        np.testing.assert_allclose(t.velocity[[0, -1]], 0.0, atol=1e-9)
        self.assertTrue(np.all(np.abs(t.velocity).max(axis=0) <= np.asarray(o.velocity_max) * (1 + 1e-9)))
        self.assertTrue(np.all(np.abs(t.acceleration).max(axis=0) <= np.asarray(o.acceleration_max) * (1 + 1e-9)))
        self.assertFalse(t.position.flags.writeable)
        out = tmp_path("excitation.csv")
        cli = run_cli("excite", "--duration", 12, "--period", 6, "--harmonics", 3, "--max-iterations", 15, "--seed", 4,
                      "--out", out, "--json")
        self.assertAlmostEqual(cli["condition_number"], t.summary.condition_number, delta=1e-6 * t.summary.condition_number)
        with open(out) as f:
            rows = list(csv.DictReader(f))
        self.assertEqual(len(rows), len(t.time))
        for k in range(3):
            np.testing.assert_allclose([float(r[f"position_{k + 1}"]) for r in rows], t.position[:, k], atol=1e-9)
            np.testing.assert_allclose([float(r[f"velocity_{k + 1}"]) for r in rows], t.velocity[:, k], atol=1e-9)

    def test_bad_options_and_start_are_refused(self):
        with self.assertRaises(ValueError):
            rcm.dynamics.ExcitationOptions(speed_coverage=1.5)
        with self.assertRaises(rcm.InputError):
            rcm.dynamics.design_excitation(rcm.dynamics.ExcitationOptions(duration_s=2.0, q0=[0.0, 0.0, 0.5]))
        with self.assertRaises(rcm.InputError):
            rcm.dynamics.design_excitation(robot="no-such-robot")


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


if __name__ == "__main__":
    unittest.main()
