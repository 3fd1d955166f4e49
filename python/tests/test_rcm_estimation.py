"""Tests of the Python module's estimators (three-step, joint, online and the
correction), the study and the simulator, cross-checked against the C++ CLI
(rcm_test_support.py)."""

import json
import os
import unittest

import numpy as np

import rcm
from rcm_test_support import (SIM_OVERRIDES, TRUTH, _state, quiet_study_options, run_cli, session_file, set_up_session,
                              tmp_path)


def setUpModule():
    set_up_session()


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


class TestSetup(unittest.TestCase):
    def test_ready_and_what_is_missing(self):
        session = rcm.load_session(_state["manifest"])
        study = quiet_study_options(model_file=None)
        report = rcm.run_setup(session, study)
        self.assertTrue(report["ready"], report["text"])
        self.assertEqual(len(report["joints"]), 3)
        self.assertIsNotNone(report["free_space_model"])
        self.assertIn("ready", report["text"])
        demanding = rcm.SetupOptions()
        demanding.min_free_space_s = 1e4
        demanding.workspace_half_range = [0.0, 1.2, 0.0]
        poor = rcm.run_setup(session, study, demanding)
        self.assertFalse(poor["ready"])
        missing = {f["check"]: f["message"] for f in poor["findings"] if f["severity"] == "missing"}
        self.assertIn("free_space.duration", missing)
        self.assertIn("s more", missing["free_space.duration"])
        self.assertIn("toward outer_pitch -1.20 rad and 1.20 rad", missing["free_space.position.outer_pitch"])
        bad = rcm.SetupOptions()
        with self.assertRaises(Exception):
            bad.curve_fractions = [0.5, 0.8]
            rcm.run_setup(session, study, bad)


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
        self.assertEqual(replay.estimates, cli["estimates"])
        self.assertEqual(self.setup.free_space.model.output_delay_s, cli["output_delay_s"])
        np.testing.assert_allclose(replay.final_output.misalignment_m, cli["final"]["misalignment_m"], rtol=1e-9,
                                   atol=1e-12)
        np.testing.assert_allclose(replay.final_output.sd_m, cli["final"]["sd_m"], rtol=1e-9)
        C = np.asarray(replay.final_output.covariance_m2)
        self.assertEqual(C.shape, (3, 3))
        np.testing.assert_allclose(C, C.T, atol=1e-18)
        np.testing.assert_allclose(np.sqrt(np.diag(C)), replay.final_output.sd_m, rtol=1e-12)
        self.assertAlmostEqual(replay.onset_s, cli["onset_s"], places=9)
        self.assertEqual(len(replay.alarms), len(cli["alarms"]))
        for a, b in zip(replay.alarms, cli["alarms"]):
            self.assertAlmostEqual(a.raised_s, b["raised_s"], places=9)
        self.assertLess(np.linalg.norm(replay.final_output.misalignment_m - TRUTH["D30_r10_15"]), 0.002)
        self.assertEqual(replay.regime.flagged, cli["regime"]["flagged"])
        self.assertEqual(replay.regime.samples, cli["regime"]["samples"])

    def test_saved_tissue_model_is_the_identified_one(self):
        origin = rcm.get_tissue_model_origin(self.session, _state["model_path"])
        path = tmp_path("tissue_model.json")
        rcm.save_joint_tissue_model(path, self.setup.tissue, origin)
        loaded = rcm.load_joint_tissue_model(path, origin)
        np.testing.assert_array_equal(loaded.parameters, self.setup.tissue.parameters)
        np.testing.assert_array_equal(loaded.covariance, self.setup.tissue.covariance)
        setup = rcm.prepare_monitor(self.session, quiet_study_options(tissue_model_file=path))
        np.testing.assert_array_equal(setup.tissue.torque_offset, self.setup.tissue.torque_offset)
        other = tmp_path("other_model.json")
        with open(_state["model_path"]) as f, open(other, "w") as g:
            g.write(f.read() + "\n")
        with self.assertRaises(rcm.InputError) as caught:
            rcm.load_joint_tissue_model(path, rcm.get_tissue_model_origin(self.session, other))
        self.assertEqual(caught.exception.field, "made_from.free_space_model_digest")

    def test_replay_of_chunks_equals_the_whole_replay(self):
        path = session_file("D30_r10_15.csv")
        whole = rcm.replay_online(self.make_pipeline(), self.trial)
        chunked = rcm.replay_online(self.make_pipeline(), rcm.iter_recording(path, chunk_rows=777))
        self.assertEqual(chunked.samples, whole.samples)
        self.assertEqual(chunked.estimates, whole.estimates)
        np.testing.assert_array_equal(chunked.final_output.misalignment_m, whole.final_output.misalignment_m)
        self.assertEqual(chunked.settled_after_s, whole.settled_after_s)
        self.assertEqual(chunked.onset_s, whole.onset_s)

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
        # The same effort at three times the speed is also a torque residual no incision force explains: the
        # online path adds that flag, which the offline summary (joint ranges only) does not know.
        residual = rcm.dynamics.get_residual_regime_flag()
        flagged_by_joint = 0
        flagged_by_residual = 0
        for t in range(fast.num_samples):
            out = pipeline.compute_sample(ws, fast.time[t], fast.position[t], fast.velocity[t], fast.effort[t])
            self.assertEqual(out.out_of_regime, out.regime_flags != 0)
            joint_flags = out.regime_flags & ~residual
            flagged_by_joint += joint_flags != 0
            flagged_by_residual += (out.regime_flags & residual) != 0
            if joint_flags:
                self.assertIn("joint", rcm.dynamics.describe_regime_flags(joint_flags))
            if out.regime_flags & residual:
                self.assertIn("torque residual", rcm.dynamics.describe_regime_flags(out.regime_flags))
        # The model's torque trails (its zero-phase qddot live): the outputs are for the samples up to the
        # last one paired, which the offline summary of those samples matches.
        last = int(np.searchsorted(fast.time, out.time))
        self.assertEqual(fast.time[last], out.time)
        paired = rcm.Recording(fast.time[:last + 1], fast.position[:last + 1], fast.velocity[:last + 1],
                               fast.effort[:last + 1], source="fast")
        self.assertEqual(flagged_by_joint, rcm.dynamics.compute_regime_summary(model, paired).flagged)
        self.assertGreater(flagged_by_residual, 0)

    def test_per_sample_pipeline_equals_replay(self):
        pipeline = self.make_pipeline()
        seen = []
        replay = rcm.replay_online(pipeline, self.trial, on_sample=lambda out: seen.append(out.misalignment_m.copy()))
        rec = self.trial
        # One call per estimate: every sample but those of the model's delay at the end.
        self.assertEqual(len(seen), replay.estimates)
        delay = pipeline.model.output_delay_s
        period = float(np.median(np.diff(rec.time)))
        self.assertLessEqual(rec.num_samples - replay.estimates, int(np.ceil(delay / period)) + 1)
        if delay > 0:
            self.assertLess(replay.estimates, rec.num_samples)
        ws = pipeline.create_workspace()
        updates = 0
        for t in range(rec.num_samples):
            out = pipeline.compute_sample(ws, rec.time[t], rec.position[t], rec.velocity[t], rec.effort[t])
            self.assertIn(out.updates, (updates, updates + 1))
            if out.updates == updates:  # no new estimate: the delay is filling
                continue
            updates = out.updates
            if updates % 500 == 1:
                self.assertTrue(np.array_equal(out.misalignment_m, seen[updates - 1]), t)
        self.assertEqual(updates, replay.estimates)
        self.assertTrue(np.array_equal(out.misalignment_m, replay.final_output.misalignment_m))
        self.assertEqual(out.onset, replay.final_output.onset)
        # reset: the stream starts over.
        pipeline.reset(ws)
        t = 0
        first = pipeline.compute_sample(ws, rec.time[0], rec.position[0], rec.velocity[0], rec.effort[0])
        while first.updates == 0:
            t += 1
            first = pipeline.compute_sample(ws, rec.time[t], rec.position[t], rec.velocity[t], rec.effort[t])
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
