"""Tests of the Python module's options classes: made from the C++ field tables
(rcm/common/options.hpp), so their attributes and keyword arguments are the
table's fields, to_dict / from_dict its JSON, and their errors its located
ones."""

import unittest

import rcm

OPTIONS_CLASSES = [rcm.StudyOptions, rcm.JointEstimatorOptions, rcm.dynamics.FitOptions, rcm.TissueFitOptions,
                   rcm.TissuePairOptions, rcm.JacobianCheckOptions, rcm.ThreeStepOptions, rcm.CoaxialProblemOptions,
                   rcm.RestDetectionOptions, rcm.RecordingReadOptions, rcm.OnlineEstimatorOptions,
                   rcm.OnlineReplayOptions, rcm.CorrectionOptions]


def attributes(cls):
    return {name for name in dir(cls) if isinstance(getattr(cls, name), property)}


class TestOptionsTables(unittest.TestCase):
    def test_attributes_and_keywords_are_the_table_fields(self):
        for cls in OPTIONS_CLASSES:
            with self.subTest(cls=cls.__name__):
                defaults = cls()
                fields = set(defaults.to_dict())
                self.assertEqual(attributes(cls), fields)
                # Every field is a keyword argument of the constructor, and reads back as given.
                again = cls(**{name: getattr(defaults, name) for name in fields})
                self.assertEqual(again.to_dict(), defaults.to_dict())
                for name in fields:
                    self.assertTrue(getattr(cls, name).__doc__, name)

    def test_keyword_arguments_set_and_check_the_fields(self):
        o = rcm.StudyOptions(method="three-step", tissue_sensitivity_delta_m=0.0,
                             joint=rcm.JointEstimatorOptions(seed=4, bootstrap_replicates=10))
        self.assertEqual(o.method, "three-step")
        self.assertEqual(o.tissue_sensitivity_delta_m, 0.0)
        self.assertEqual((o.joint.seed, o.joint.bootstrap_replicates), (4, 10))
        self.assertEqual(rcm.CorrectionOptions(tolerance_m=0.003).tolerance_m, 0.003)
        with self.assertRaises(TypeError) as cm:
            rcm.CorrectionOptions(tolerance=0.003)
        self.assertIn("tolerance_m", str(cm.exception))  # the fields are listed
        with self.assertRaises(rcm.InputError) as cm:
            rcm.CorrectionOptions(tolerance_m=-0.003)
        self.assertEqual(cm.exception.field, "tolerance_m")
        with self.assertRaises(rcm.InputError) as cm:
            rcm.StudyOptions(method="both")
        self.assertEqual(cm.exception.field, "method")
        # Nested fields stay writable in place, as before.
        o.fit.max_minutes = 3.0
        self.assertEqual(o.to_dict()["fit"]["max_minutes"], 3.0)

    def test_dict_round_trip_and_located_errors(self):
        d = rcm.StudyOptions().to_dict()
        d["joint"]["D_starts"] = [0.02, 0.04]
        d["model_kind"] = "linear"
        d["static_step"] = "last-hold"
        self.assertEqual(d["three_step"]["coaxial_force"], "total")
        d["three_step"]["coaxial_force"] = "difference"
        o = rcm.StudyOptions.from_dict(d)
        self.assertEqual(o.model_kind, rcm.dynamics.TorqueModelKind.linear)
        self.assertEqual(o.static_step, rcm.StaticStep.last_hold)
        self.assertEqual(o.three_step.coaxial_force, rcm.CoaxialForce.difference)
        self.assertEqual(o.to_dict(), d)
        with self.assertRaises(rcm.InputError) as cm:
            rcm.StudyOptions.from_dict({"joint": {"huber": 2.0}})
        self.assertEqual(cm.exception.field, "joint.huber")
        with self.assertRaises(rcm.InputError) as cm:
            rcm.StudyOptions.from_dict({"fit": {"seed": "one"}})
        self.assertEqual(cm.exception.field, "fit.seed")
        o = rcm.JointEstimatorOptions()
        o.huber_scale = -1.0
        with self.assertRaises(rcm.InputError) as cm:
            o.validate()
        self.assertEqual(cm.exception.field, "huber_scale")

    def test_model_kind_default_is_the_one_rule(self):
        self.assertIsNone(rcm.StudyOptions().model_kind)
        self.assertEqual(rcm.dynamics.get_default_model_kind(), rcm.dynamics.TorqueModelKind.linear)


if __name__ == "__main__":
    unittest.main()
