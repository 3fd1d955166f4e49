// The online estimator, the pipeline a live robot runs per sample, the replay
// of a recording through it, and the correction (hold, compensate, reposition)
// from its running estimate.

#include "common.hpp"
#include "options.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"

namespace rcm::python {

namespace {

using dynamics::TorqueModel;

// The pipeline workspace keeps its pipeline alive and is checked against it:
// its free-space part is sized and typed for that pipeline's model.
struct PipelineWorkspace {
  std::shared_ptr<const OnlinePipeline> owner;
  OnlinePipeline::Workspace workspace;
};

Eigen::VectorXd joint_values(py::handle object, const std::string& fn, const char* name, int at_least) {
  const Eigen::VectorXd v = to_vector(object, argument_location(fn, name));
  if (v.size() < at_least)
    throw InputError(argument_location(fn, name), "expected at least " + std::to_string(at_least) + " values, got " +
                                                      std::to_string(v.size()));
  return v;
}

py::object optional_double(const std::optional<double>& v) { return v ? py::object(py::float_(*v)) : py::none(); }

}  // namespace

void bind_online(py::module_& m) {
  // ---- online ----
  def_options<OnlineEstimatorOptions>(m, "OnlineEstimatorOptions", "The bank of EKFs, onset and alarm")
      .def("check", &OnlineEstimatorOptions::check);
  m.def("make_online_options", &make_online_options, py::arg("joint"),
        "Online options agreeing with a batch estimate's bounds and scales");
  py::class_<OnlineOutput>(m, "OnlineOutput", "What the online estimator says after a sample")
      .def_readonly("updates", &OnlineOutput::updates,
                    "samples estimated since the reset; 0: none yet (a model whose torque trails fills its delay "
                    "first); a call brings none (it is unchanged) or more (after a gap: the output is the last's)")
      .def_readonly("time", &OnlineOutput::time, "of the sample the estimate is for")
      .def_readonly("used", &OnlineOutput::used, "False: the pivot was beyond max_theta_rad")
      .def_readonly("at_rest", &OnlineOutput::at_rest)
      .def_readonly("hypothesis", &OnlineOutput::hypothesis)
      .def_readonly("misalignment_m", &OnlineOutput::misalignment_m, "[dr_x, dr_y, D], incision frame, m")
      .def_readonly("sd_m", &OnlineOutput::sd_m, "sqrt of the covariance's diagonal, m")
      .def_readonly("covariance_m2", &OnlineOutput::covariance_m2,
                    "3 x 3 covariance of misalignment_m, m^2 (the axes' errors are correlated)")
      .def_readonly("f_inc_base", &OnlineOutput::f_inc_base, "the model's force now, base frame, N")
      .def_readonly("force_norm_n", &OnlineOutput::force_norm_n)
      .def_readonly("cusum", &OnlineOutput::cusum)
      .def_readonly("fit_cost", &OnlineOutput::fit_cost,
                    "the reported filter's mean robust loss per sample since it started, each innovation against the "
                    "spread the filter predicts for it: about 1.5 when the model explains the residual")
      .def_readonly("onset", &OnlineOutput::onset)
      .def_readonly("onset_time", &OnlineOutput::onset_time)
      .def_readonly("alarm", &OnlineOutput::alarm)
      .def_readonly("alarm_raised", &OnlineOutput::alarm_raised)
      .def_readonly("alarm_cleared", &OnlineOutput::alarm_cleared)
      .def_readonly("out_of_regime", &OnlineOutput::out_of_regime,
                    "the sample lies beyond the free-space model's training data (rcm.dynamics.describe_regime_flags)")
      .def_readonly("regime_flags", &OnlineOutput::regime_flags, "bit 3 j + k: joint j position (k 0), velocity (1), acceleration (2); "
                    "rcm.dynamics.get_residual_regime_flag(): a torque residual no incision force explains")
      .def("__repr__", [](const OnlineOutput& o) {
        return "<rcm.OnlineOutput t=" + std::to_string(o.time) + " [" + std::to_string(o.misalignment_m[0]) + ", " +
               std::to_string(o.misalignment_m[1]) + ", " + std::to_string(o.misalignment_m[2]) + "] m" +
               (o.onset ? ", onset" : "") + (o.alarm ? ", ALARM" : "") + (o.out_of_regime ? ", out of regime" : "") + ">";
      });
  py::class_<OnlineEstimator::Workspace>(m, "OnlineEstimatorWorkspace", "State of the filter bank (fixed size)")
      .def_property_readonly("output", [](const OnlineEstimator::Workspace& w) { return w.output; }, "the last OnlineOutput");
  py::class_<OnlineEstimator>(m, "OnlineEstimator",
                              "The joint model as a bank of EKFs on [dr_x, dr_y, D], updated sample by sample (immutable)")
      .def(py::init<const IncisionFrame&, const JointTissueModel&, const OnlineEstimatorOptions&>(), py::arg("incision"),
           py::arg("tissue"), py::arg("options") = OnlineEstimatorOptions{})
      .def("create_workspace", &OnlineEstimator::create_workspace)
      .def("reset", &OnlineEstimator::reset, py::arg("workspace"))
      .def("compute_update", [](const OnlineEstimator& e, OnlineEstimator::Workspace& ws, double time, py::handle q,
                                py::handle qd, py::handle dtau) {
        const std::string fn = "OnlineEstimator.compute_update";
        to_finite(time, argument_location(fn, "time"));
        return e.compute_update(ws, time, to_vector3(q, argument_location(fn, "q")), to_vector3(qd, argument_location(fn, "qd")),
                                to_vector3(dtau, argument_location(fn, "dtau")));  // copied out of the workspace
      }, py::arg("workspace"), py::arg("time"), py::arg("q"), py::arg("qd"), py::arg("dtau"),
           "One sample: joints 1-3 position and velocity and the residual tau - tau_fs (N m, N m, N)")
      // Copies: the estimator is immutable (its constructor derived state from these).
      .def_property_readonly("incision", [](const OnlineEstimator& e) { return e.incision(); })
      .def_property_readonly("tissue", [](const OnlineEstimator& e) { return e.tissue(); })
      .def_property_readonly("options", [](const OnlineEstimator& e) { return e.options(); })
      .def("apply_rcm_shift", [](const OnlineEstimator& e, OnlineEstimator::Workspace& ws, py::handle shift) {
        e.apply_rcm_shift(ws, to_vector3(shift, argument_location("OnlineEstimator.apply_rcm_shift", "shift_base")));
      }, py::arg("workspace"), py::arg("shift_base"),
           "The RCM moved by shift_base (base frame, m): the offsets, relative to the RCM, move with it");

  py::class_<PipelineWorkspace>(m, "OnlinePipelineWorkspace", "Free-space model state + estimator state of one stream");
  py::class_<OnlinePipeline, std::shared_ptr<OnlinePipeline>>(
      m, "OnlinePipeline",
      "The whole per-sample path of a live robot (what `rcm monitor` and the ROS node run): measured joint\n"
      "state and effort in, the free-space model stepped with its state, the residual into the estimator.")
      .def(py::init([](std::shared_ptr<TorqueModel> model, const OnlineEstimator& estimator) {
             return std::make_shared<OnlinePipeline>(model, estimator);
           }),
           py::arg("model"), py::arg("estimator"))
      .def("create_workspace", [](std::shared_ptr<OnlinePipeline> self) {
        return PipelineWorkspace{self, self->create_workspace()};
      })
      .def("reset", [](const OnlinePipeline& self, PipelineWorkspace& ws) {
        if (ws.owner.get() != &self)
          throw InputError(argument_location("OnlinePipeline.reset", "workspace"), "was created by another pipeline");
        self.reset(ws.workspace);
      }, py::arg("workspace"))
      .def("compute_sample", [](const OnlinePipeline& self, PipelineWorkspace& ws, double time, py::handle q, py::handle qd,
                                py::handle effort) {
        const std::string fn = "OnlinePipeline.compute_sample";
        if (ws.owner.get() != &self)
          throw InputError(argument_location(fn, "workspace"), "was created by another pipeline; use pipeline.create_workspace()");
        to_finite(time, argument_location(fn, "time"));
        const int n = std::max(3, self.model().num_joints());
        const Eigen::VectorXd qv = joint_values(q, fn, "q", n), qdv = joint_values(qd, fn, "qd", n),
                              ev = joint_values(effort, fn, "effort", n);
        return self.compute_sample(ws.workspace, time, qv.data(), qdv.data(), ev.data());  // copied
      }, py::arg("workspace"), py::arg("time"), py::arg("q"), py::arg("qd"), py::arg("effort"),
           "One measured sample (time s; q, qd, effort of at least max(3, model.num_joints) joints) -> OnlineOutput")
      .def_property_readonly("model", [](std::shared_ptr<OnlinePipeline> self) {
        // Aliasing pointer: it keeps the pipeline, and with it the model, alive.
        return std::shared_ptr<TorqueModel>(self, const_cast<TorqueModel*>(&self->model()));
      }, "the free-space model")
      .def_property_readonly("estimator", &OnlinePipeline::estimator)
      .def("apply_rcm_shift", [](const OnlinePipeline& self, PipelineWorkspace& ws, py::handle shift) {
        const std::string fn = "OnlinePipeline.apply_rcm_shift";
        if (ws.owner.get() != &self) throw InputError(argument_location(fn, "workspace"), "was created by another pipeline");
        self.apply_rcm_shift(ws.workspace, to_vector3(shift, argument_location(fn, "shift_base")));
      }, py::arg("workspace"), py::arg("shift_base"),
           "The RCM moved by shift_base (base frame) before the next sample. With a model whose torque trails\n"
           "(output_delay_s > 0) the filters take the shift when they reach the first sample taken after it;\n"
           "meanwhile each output's misalignment_m is relative to the RCM as it is now.");

  // ---- from estimate to action ----
  py::enum_<CorrectionAction>(m, "CorrectionAction")
      .value("hold", CorrectionAction::hold)
      .value("compensate", CorrectionAction::compensate)
      .value("reposition", CorrectionAction::reposition);
  py::enum_<HoldReason>(m, "HoldReason")
      .value("none", HoldReason::none)
      .value("no_onset", HoldReason::no_onset)
      .value("model_mismatch", HoldReason::model_mismatch)
      .value("not_confident", HoldReason::not_confident)
      .value("within_tolerance", HoldReason::within_tolerance);
  def_options<CorrectionOptions>(m, "CorrectionOptions", "Gates and limits of the RCM correction (m, m/s)");
  py::class_<CorrectionOutput>(m, "CorrectionOutput", "The action after a sample (estimation/correction.hpp)")
      .def_readonly("time", &CorrectionOutput::time)
      .def_readonly("action", &CorrectionOutput::action)
      .def_readonly("reason", &CorrectionOutput::reason, "why it holds (none when it acts)")
      .def_readonly("changed", &CorrectionOutput::changed)
      .def_readonly("move_inc", &CorrectionOutput::move_inc, "RCM move onto the incision, incision frame, m")
      .def_readonly("move_base", &CorrectionOutput::move_base, "the same, base frame, m")
      .def_readonly("move_low_inc", &CorrectionOutput::move_low_inc)
      .def_readonly("move_high_inc", &CorrectionOutput::move_high_inc)
      .def_readonly("distance_m", &CorrectionOutput::distance_m)
      .def_readonly("distance_low_m", &CorrectionOutput::distance_low_m)
      .def_readonly("distance_high_m", &CorrectionOutput::distance_high_m)
      .def_readonly("fit_cost", &CorrectionOutput::fit_cost)
      .def_readonly("step_base", &CorrectionOutput::step_base, "software RCM shift commanded now, base frame, m")
      .def_readonly("applied_base", &CorrectionOutput::applied_base, "the shift in effect once the step is made")
      .def("__repr__", [](const CorrectionOutput& c) {
        return std::string("<rcm.CorrectionOutput t=") + std::to_string(c.time) + " " + to_string(c.action) +
               (c.action == CorrectionAction::hold ? std::string(" (") + to_string(c.reason) + ")" : std::string()) +
               " " + std::to_string(c.distance_m * 1e3) + " mm>";
      });
  py::class_<RcmCorrector::Workspace>(m, "RcmCorrectorWorkspace")
      .def_property_readonly("output", [](const RcmCorrector::Workspace& w) { return w.output; });
  py::class_<RcmCorrector>(m, "RcmCorrector", "hold / compensate / reposition from the running estimate (immutable)")
      .def(py::init<const IncisionFrame&, const CorrectionOptions&>(), py::arg("incision"),
           py::arg("options") = CorrectionOptions{})
      .def("create_workspace", &RcmCorrector::create_workspace)
      .def("reset", &RcmCorrector::reset, py::arg("workspace"))
      .def("compute_correction", [](const RcmCorrector& c, RcmCorrector::Workspace& ws, const OnlineOutput& estimate,
                                    py::handle applied) {
        const Eigen::Vector3d a = applied.is_none() ? Eigen::Vector3d::Zero()
                                                    : to_vector3(applied, argument_location("RcmCorrector.compute_correction", "applied_base"));
        return c.compute_correction(ws, estimate, a);  // copied
      }, py::arg("workspace"), py::arg("estimate"), py::arg("applied_base") = py::none(),
           "The action after one OnlineOutput, given the software shift in effect (base frame, m; None: none)")
      .def("describe", [](const RcmCorrector& c, const CorrectionOutput& out) { return describe_correction(out, c); },
           py::arg("correction"), "the advice in words")
      .def_property_readonly("incision", [](const RcmCorrector& c) { return c.incision(); })
      .def_property_readonly("options", [](const RcmCorrector& c) { return c.options(); });
  m.def("describe_rcm_move", [](py::handle move, const IncisionFrame& incision) {
    return describe_rcm_move(to_vector3(move, argument_location("rcm.describe_rcm_move", "move_inc")), incision);
  }, py::arg("move_inc"), py::arg("incision"), "'23 mm deeper along the instrument, 8.0 mm toward +x_base'");
  py::class_<AlignmentCheck>(m, "AlignmentCheck")
      .def_readonly("aligned", &AlignmentCheck::aligned)
      .def_readonly("confident", &AlignmentCheck::confident)
      .def_readonly("within_m", &AlignmentCheck::within_m, "95 % upper bound of the distance, m")
      .def_readonly("message", &AlignmentCheck::message);
  m.def("check_alignment", &check_alignment, py::arg("estimate"), py::arg("incision"),
        py::arg("options") = CorrectionOptions{}, "After re-docking: is the RCM on the incision?");

  // One call per sample for anyone's simulator or robot script: the estimate and the correction.
  struct PyCorrectionLoop {
    std::shared_ptr<const CorrectionLoop> loop;
    CorrectionLoop::Workspace ws;
  };
  py::class_<PyCorrectionLoop>(
      m, "CorrectionLoop",
      "Pipeline + corrector, one call per sample: step(time, q, qd, effort, applied_base) -> (OnlineOutput,\n"
      "CorrectionOutput). applied_base is the software shift of the RCM in effect (base frame, m); a change\n"
      "is passed to the estimator before the sample. Carry out correction.step_base and pass the new shift next time.")
      .def(py::init([](const OnlinePipeline& pipeline, const RcmCorrector& corrector) {
             auto loop = std::make_shared<const CorrectionLoop>(pipeline, corrector);
             return PyCorrectionLoop{loop, loop->create_workspace()};
           }),
           py::arg("pipeline"), py::arg("corrector"))
      .def("reset", [](PyCorrectionLoop& self) { self.loop->reset(self.ws); })
      .def("step", [](PyCorrectionLoop& self, double time, py::handle q, py::handle qd, py::handle effort,
                      py::handle applied) {
        const std::string fn = "CorrectionLoop.step";
        to_finite(time, argument_location(fn, "time"));
        const int n = std::max(3, self.loop->pipeline().model().num_joints());
        const Eigen::VectorXd qv = joint_values(q, fn, "q", n), qdv = joint_values(qd, fn, "qd", n),
                              ev = joint_values(effort, fn, "effort", n);
        const Eigen::Vector3d a = applied.is_none() ? Eigen::Vector3d::Zero()
                                                    : to_vector3(applied, argument_location(fn, "applied_base"));
        const CorrectionOutput c = self.loop->compute_sample(self.ws, time, qv.data(), qdv.data(), ev.data(), a);
        return py::make_tuple(get_online_output(self.ws.pipeline.estimator), c);
      }, py::arg("time"), py::arg("q"), py::arg("qd"), py::arg("effort"), py::arg("applied_base") = py::none())
      .def_property_readonly("corrector", [](const PyCorrectionLoop& self) { return self.loop->corrector(); });

  py::class_<OnlineAlarm>(m, "OnlineAlarm")
      .def_readonly("raised_s", &OnlineAlarm::raised_s)
      .def_property_readonly("cleared_s", [](const OnlineAlarm& a) { return optional_double(a.cleared_s); })
      .def_readonly("peak_force_n", &OnlineAlarm::peak_force_n);
  def_options<OnlineReplayOptions>(m, "OnlineReplayOptions", "What replay_online measures");
  py::class_<OnlineReplay>(m, "OnlineReplay", "A recording streamed through a pipeline (rcm monitor)")
      .def_readonly("samples", &OnlineReplay::samples)
      .def_readonly("estimates", &OnlineReplay::estimates,
                    "samples estimated, each once: all but the last output_delay_s of the model's")
      .def_readonly("final_output", &OnlineReplay::final_output)
      .def_property_readonly("motion_start_s", [](const OnlineReplay& r) { return optional_double(r.motion_start_s); })
      .def_property_readonly("onset_s", [](const OnlineReplay& r) { return optional_double(r.onset_s); })
      .def_property_readonly("settled_after_s", [](const OnlineReplay& r) { return optional_double(r.settled_after_s); })
      .def_readonly("alarms", &OnlineReplay::alarms)
      .def_readonly("peak_force_n", &OnlineReplay::peak_force_n)
      .def_readonly("mean_update_s", &OnlineReplay::mean_update_s, "wall clock per sample (with a callback: includes it)")
      .def_readonly("max_update_s", &OnlineReplay::max_update_s)
      .def_readonly("regime", &OnlineReplay::regime, "samples outside the free-space model's training regime");
  // One home for both: a whole Recording is one chunk.
  auto replay = [](const OnlinePipeline& pipeline, py::object recording, const OnlineReplayOptions& o,
                   py::object on_sample) {
    std::function<void(const OnlineOutput&)> callback;
    // With a callback the GIL stays held around it: it is called from this thread for every sample.
    if (!on_sample.is_none())
      callback = [&on_sample](const OnlineOutput& out) {
        const py::gil_scoped_acquire acquire;
        on_sample(out);
      };
    OnlineReplayer replayer(pipeline, o, callback);
    auto add = [&](const Recording& chunk) {
      py::gil_scoped_release release;
      replayer.add(chunk);
    };
    if (py::isinstance<Recording>(recording)) {
      add(recording.cast<const Recording&>());
    } else {
      for (py::handle chunk : recording) add(chunk.cast<const Recording&>());
    }
    py::gil_scoped_release release;
    return replayer.finish();
  };
  m.def("replay_online", replay, py::arg("pipeline"), py::arg("recording"), py::arg("options") = OnlineReplayOptions{},
        py::arg("on_sample") = py::none(),
        "Stream a recording through the pipeline from its reset state; on_sample(OnlineOutput) is called\n"
        "after every sample when given. `recording`: an rcm.Recording, or an iterable of them in order (the\n"
        "chunks of rcm.iter_recording): the same OnlineReplay, in memory that does not grow with the length.");
}

}  // namespace rcm::python
