// The whole study on a session (run_study, as `rcm run`), its steps for the
// online monitor (fit_free_space_step, prepare_monitor), its results, and the
// checks between docking and the first estimate (run_setup, as `rcm setup`).

#include "common.hpp"
#include "options.hpp"
#include "rcm/estimation/setup.hpp"
#include "rcm/estimation/study.hpp"

namespace rcm::python {

namespace {

using dynamics::TorqueModel;

// The study's free-space fitter: rcm::core's, as the module has no LibTorch
// (linear only; its default kind is linear).
TorqueModelFitter get_python_fitter() {
  return get_linear_torque_model_fitter(argument_location("rcm.StudyOptions", "model_kind"));
}

std::shared_ptr<TorqueModel> unconst(const std::shared_ptr<const TorqueModel>& model) {
  // Python has no const objects; every TorqueModel method bound is const, so
  // handing the same model out through a non-const holder changes nothing.
  return std::const_pointer_cast<TorqueModel>(model);
}

}  // namespace

void bind_study(py::module_& m) {
  // ---- the study on a session ----
  def_options<RecordingReadOptions>(m, "RecordingReadOptions", "How recordings are read");
  def_options<StudyOptions, JointEstimatorOptions, std::optional<dynamics::TorqueModelKind>, dynamics::FitOptions,
              TissueFitOptions, TissuePairOptions, ThreeStepOptions, RestDetectionOptions, StaticStep, CoaxialForce,
              RecordingReadOptions>(
      m, "StudyOptions",
      "Options of run_study / prepare_monitor. model_kind None: the default kind, linear\n"
      "(rcm.dynamics.get_default_model_kind(); the only kind this module fits, without LibTorch); set\n"
      "model_file to use a saved model of any kind.");
  py::class_<TrialOutcome>(m, "TrialOutcome", "Everything the study found on one trial")
      .def_readonly("name", &TrialOutcome::name)
      .def_readonly("truth_m", &TrialOutcome::truth_m)
      .def_readonly("estimate", &TrialOutcome::estimate, "ThreeStepResult (hold tau_fs with the model's state carried)")
      .def_readonly("paper_variant", &TrialOutcome::paper_variant, "ThreeStepResult with the paper's f(q0, 0), or None")
      .def_readonly("joint", &TrialOutcome::joint, "JointEstimate (method 'joint') or None")
      .def_readonly("online", &TrialOutcome::online, "OnlineReplay of the trial (method 'joint') or None")
      .def_readonly("hold", &TrialOutcome::hold, "StaticHold or None")
      .def_readonly("time", &TrialOutcome::time)
      .def_readonly("f_estimated", &TrialOutcome::f_estimated, "(T, 3) Eq. 6 force at the true D (or D~), N")
      .def_readonly("f_sensor", &TrialOutcome::f_sensor, "(T, 3) force columns of the recording (empty without)")
      .def_readonly("force_offset_used_m", &TrialOutcome::force_offset_used_m)
      .def_readonly("force_rmse", &TrialOutcome::force_rmse, "per axis, N, or None")
      .def_readonly("ill_conditioned_samples", &TrialOutcome::ill_conditioned_samples)
      .def_readonly("regime", &TrialOutcome::regime, "the trial's samples outside the free-space model's training regime")
      .def_readonly("seconds", &TrialOutcome::seconds)
      .def("get_misalignment_m", &TrialOutcome::get_misalignment_m, "the method's estimate: joint when computed, else three-step")
      .def("get_error_m", &TrialOutcome::get_error_m, "|estimate - truth| or None")
      .def("get_three_step_error_m", &TrialOutcome::get_three_step_error_m);
  py::class_<StudyResult>(m, "StudyResult")
      .def_readonly("session_manifest", &StudyResult::session_manifest)
      .def_readonly("method", &StudyResult::method)
      .def_readonly("model_kind", &StudyResult::model_kind)
      .def_property_readonly("model", [](const StudyResult& r) { return unconst(r.model); }, "the free-space TorqueModel")
      .def_readonly("fit", &StudyResult::fit, "FitSummary when fitted here, else None")
      .def_readonly("free_space_errors", &StudyResult::free_space_errors, "Table II (held-out test split)")
      .def_readonly("tissue", &StudyResult::tissue, "TissueFitResult")
      .def_readonly("tissue_pairs_report", &StudyResult::tissue_pairs_report)
      .def_readonly("tissue_pairs", &StudyResult::tissue_pairs)
      .def_readonly("joint_tissue", &StudyResult::joint_tissue, "JointTissueModel (method 'joint') or None")
      .def_readonly("baseline_hold", &StudyResult::baseline_hold, "StaticHold of the aligned baseline (joint method) or None")
      .def_readonly("baseline_message", &StudyResult::baseline_message)
      .def_readonly("calibration_offset_m", &StudyResult::calibration_offset_m)
      .def_readonly("trials", &StudyResult::trials, "list of TrialOutcome")
      .def_readonly("seconds", &StudyResult::seconds)
      .def("to_json", [](const StudyResult& r) { return to_python(r.to_json()); },
           "The rcm-results/1 object (what `rcm run --json` prints) as a dict");
  m.def("run_study", [](const Session& session, const StudyOptions& o, std::optional<FreeSpaceModelStep> free_space) {
    py::gil_scoped_release release;
    if (free_space) return run_study(session, o, std::move(*free_space));
    return run_study(session, o, get_python_fitter());
  }, py::arg("session"), py::arg("options") = StudyOptions{}, py::arg("free_space") = py::none(),
        "The whole study (`rcm run`): free-space model (fitted, linear, or options.model_file), tissue law on\n"
        "the calibration, every trial of session.trials (assign a shorter list to estimate fewer).\n"
        "free_space: a FreeSpaceModelStep from fit_free_space_step, used instead of fitting again (as `rcm run`,\n"
        "which saves the model before the rest of the study).");
  m.def("check_study_inputs", &check_study_inputs, py::arg("session"), py::arg("options") = StudyOptions{},
        "What run_study checks before any work (a calibration, a trial, the options' limits); raises InputError");
  m.def("check_study_recordings", [](const Session& session, const StudyOptions& o) {
    py::gil_scoped_release release;
    check_study_recordings(session, o);
  }, py::arg("session"), py::arg("options") = StudyOptions{},
        "Reads every recording the study reads after the free-space fit (calibration, baseline, trials) and\n"
        "discards it, so that a bad file raises InputError (file, line, field) before the fit, as `rcm run` does");
  m.def("format_table_iv", &format_table_iv, py::arg("result"), "Table IV as `rcm run` prints it");
  m.def("write_study_report", [](const StudyResult& r, const Session& s, const std::filesystem::path& out_dir) {
    py::gil_scoped_release release;
    return write_study_report(r, s, out_dir);
  }, py::arg("result"), py::arg("session"), py::arg("out_dir"),
        "results.json, report.md and figures/ (figures need gnuplot); returns the report path");

  py::class_<FreeSpaceModelStep>(m, "FreeSpaceModelStep")
      .def_property_readonly("model", [](const FreeSpaceModelStep& s) { return unconst(s.model); })
      .def_readonly("kind", &FreeSpaceModelStep::kind)
      .def_readonly("fit", &FreeSpaceModelStep::fit)
      .def_readonly("errors", &FreeSpaceModelStep::errors, "per-joint errors on the held-out last 10 %");
  m.def("fit_free_space_step", [](const Session& session, const StudyOptions& o) {
    py::gil_scoped_release release;
    return fit_free_space_step(session, o, get_python_fitter());
  }, py::arg("session"), py::arg("options") = StudyOptions{}, "Step 0: fit (linear) or load options.model_file");
  m.def("make_joint_options_for_model", &make_joint_options_for_model, py::arg("base"), py::arg("step"),
        "Joint options whose residual scales are the model's held-out RMSE and sample period its own");
  py::class_<MonitorSetup>(m, "MonitorSetup", "What the online monitor needs of a session")
      .def_readonly("free_space", &MonitorSetup::free_space)
      .def_readonly("incision", &MonitorSetup::incision)
      .def_readonly("tissue", &MonitorSetup::tissue)
      .def_property_readonly("joint_options", [](const MonitorSetup& s) { return s.joint_options; },
                             "a copy: edit it freely before make_online_options / estimate_joint");
  m.def("prepare_monitor", [](const Session& session, const StudyOptions& o) {
    py::gil_scoped_release release;
    return prepare_monitor(session, o, get_python_fitter());
  }, py::arg("session"), py::arg("options") = StudyOptions{},
        "Free-space model, incision frame at q0 and the tissue model identified on the calibration, as\n"
        "`rcm monitor` prepares them. Then: OnlinePipeline(setup.free_space.model, OnlineEstimator(\n"
        "setup.incision, setup.tissue, make_online_options(setup.joint_options))).");
  def_options<SetupOptions>(m, "SetupOptions", "Thresholds of run_setup (`rcm setup`; docs/howto-setup.md)");
  m.def("run_setup", [](const Session& session, const StudyOptions& o, const SetupOptions& setup_options) {
    SetupReport report;
    {
      py::gil_scoped_release release;
      report = run_setup(session, o, setup_options, get_python_fitter());
    }
    py::object out = to_python(report.to_json());
    out["text"] = report.to_text();
    out["free_space_model"] = report.free_space.model ? py::cast(unconst(report.free_space.model)) : py::none();
    return out;
  }, py::arg("session"), py::arg("options") = StudyOptions{}, py::arg("setup_options") = SetupOptions{},
        "Is the arm ready to estimate? What `rcm setup` checks and fits, as the dict of its setup.json\n"
        "('ready', 'findings' [{'check', 'severity', 'message'}], 'robot_time_s', 'compute_s', 'joints',\n"
        "'model', 'learning_curve', 'calibration'), plus 'text' (what the command prints) and\n"
        "'free_space_model' (the fitted TorqueModel, or None when the data could not be fitted).");
  m.def("compute_settled_free_space_torque", [](const TorqueModel& model, py::handle q0, double settle_s) {
    return compute_settled_free_space_torque(
        model, to_vector3(q0, argument_location("rcm.compute_settled_free_space_torque", "q0")), settle_s);
  }, py::arg("model"), py::arg("q0"), py::arg("settle_s") = 2.0, "The paper's f(q0, 0): the model stepped at rest from reset");
}

}  // namespace rcm::python

