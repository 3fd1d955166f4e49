// Estimation: the static hold, the three-step method (paper Algorithm 1), the
// joint torque-space estimate, the online estimator / pipeline, and the whole
// study on a session. Solver outcomes come back as objects with their status
// (SolverReport.converged, .termination), never as exceptions.

#include <cmath>

#include "common.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/joint.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/estimation/three_step.hpp"

namespace rcm::python {

namespace {

using dynamics::TorqueModel;

// The study's free-space fitter in a build without LibTorch, as the CLI's
// (apps/rcm/study_cli.cpp): linear only, a clear error for the others.
TorqueModelFitter get_python_fitter() {
  return [](dynamics::TorqueModelKind kind, const std::vector<Recording>& recordings, const dynamics::FitOptions& options) {
    if (kind != dynamics::TorqueModelKind::linear)
      throw InputError(argument_location("StudyOptions", "model_kind"),
                       "the Python module has no LibTorch: only the linear model can be fitted; fit " +
                           dynamics::to_string(kind) + " with `rcm dynamics fit` and pass it as model_file");
    return dynamics::fit_linear_torque_model(recordings, options);
  };
}

std::shared_ptr<TorqueModel> unconst(const std::shared_ptr<const TorqueModel>& model) {
  // Python has no const objects; every TorqueModel method bound is const, so
  // handing the same model out through a non-const holder changes nothing.
  return std::const_pointer_cast<TorqueModel>(model);
}

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

void bind_estimation(py::module_& m) {
  // ---- static hold (steps 1 and 3b) ----
  py::class_<RestDetectionOptions>(m, "RestDetectionOptions", "When a sample counts as at rest at q0")
      .def(py::init<>())
      .def_readwrite("max_angular_speed", &RestDetectionOptions::max_angular_speed, "rad/s, joints 1-2")
      .def_readwrite("max_linear_speed", &RestDetectionOptions::max_linear_speed, "m/s, joint 3")
      .def_readwrite("max_angle_from_q0", &RestDetectionOptions::max_angle_from_q0, "rad")
      .def_readwrite("max_insertion_from_q0", &RestDetectionOptions::max_insertion_from_q0, "m")
      .def_readwrite("min_duration_s", &RestDetectionOptions::min_duration_s);
  py::class_<RestSegment>(m, "RestSegment", "Samples [begin, end) at rest at q0")
      .def_readonly("begin", &RestSegment::begin)
      .def_readonly("end", &RestSegment::end)
      .def_readonly("duration_s", &RestSegment::duration_s);
  m.def("find_rest_segment", [](const Recording& rec, py::handle q0, const RestDetectionOptions& o) {
    return find_rest_segment(rec, to_vector3(q0, argument_location("rcm.find_rest_segment", "q0")), o);
  }, py::arg("recording"), py::arg("q0"), py::arg("options") = RestDetectionOptions{},
        "The last run of samples at rest at q0; rcm.InputError when the recording never rests there");
  m.def("find_rest_segments", [](const Recording& rec, py::handle q0, const RestDetectionOptions& o) {
    return find_rest_segments(rec, to_vector3(q0, argument_location("rcm.find_rest_segments", "q0")), o);
  }, py::arg("recording"), py::arg("q0"), py::arg("options") = RestDetectionOptions{},
        "Every run of samples at rest at q0, in time order; rcm.InputError when there is none");
  py::enum_<StaticStep>(m, "StaticStep", "How step 3b combines the static file's holds")
      .value("balanced", StaticStep::balanced)
      .value("last_hold", StaticStep::last_hold);
  py::class_<HoldApproach>(m, "HoldApproach", "One hold at q0 and, per joint, the direction of the motion that ended there")
      .def_readonly("segment", &HoldApproach::segment)
      .def_property_readonly("direction", [](const HoldApproach& h) { return Eigen::Vector3d(h.direction.cast<double>()); },
                             "+1 up, -1 down, 0 unknown, per joint")
      .def_readonly("tau_measured", &HoldApproach::tau_measured)
      .def_readonly("tau_free_space", &HoldApproach::tau_free_space);
  py::class_<StaticHold>(m, "StaticHold", "Step 3b: measured and predicted torque at q0, combined over the holds")
      .def_readonly("segment", &StaticHold::segment, "the last hold")
      .def_readonly("holds", &StaticHold::holds)
      .def_readonly("step", &StaticHold::step)
      .def_readonly("tau_measured", &StaticHold::tau_measured)
      .def_readonly("tau_free_space", &StaticHold::tau_free_space)
      .def_property_readonly("direction_balanced", [](const StaticHold& h) {
        return std::vector<bool>{h.direction_balanced[0], h.direction_balanced[1], h.direction_balanced[2]};
      }, "per joint: holds from both directions were averaged")
      .def("get_dtau", &StaticHold::get_dtau, "tau_measured - tau_free_space");
  m.def("compute_static_hold", [](const Recording& rec, py::handle tau_fs, py::handle q0, const RestDetectionOptions& o,
                                  StaticStep step) {
    const std::string fn = "rcm.compute_static_hold";
    const Eigen::MatrixXd tau = to_matrix(tau_fs, argument_location(fn, "tau_fs"));
    return compute_static_hold(rec, tau, to_vector3(q0, argument_location(fn, "q0")), o, step);
  }, py::arg("recording"), py::arg("tau_fs"), py::arg("q0"), py::arg("options") = RestDetectionOptions{},
        py::arg("step") = StaticStep::balanced,
        "tau_fs: (T, >= 3) prediction for the whole static file with the model's state carried");
  m.def("estimate_position_quantum", &estimate_position_quantum, py::arg("recording"),
        "Smallest nonzero position step per joint (the encoder count of quantized recordings)");
  m.def("remove_position_chatter", [](const Recording& rec, py::handle width) {
    const Eigen::VectorXd w = to_vector(width, argument_location("rcm.remove_position_chatter", "width"));
    return std::make_shared<Recording>(remove_position_chatter(rec, w));
  }, py::arg("recording"), py::arg("width"),
        "A copy whose positions went through a play operator of the given width per joint (what the study\n"
        "does to a static file before predicting its tau_fs: width = 1.5 * estimate_position_quantum)");

  // ---- three-step ----
  py::class_<SolverReport>(m, "SolverReport", "How a solve ended (Ceres): the status object of every estimate")
      .def_readonly("converged", &SolverReport::converged)
      .def_readonly("termination", &SolverReport::termination, "Ceres termination type")
      .def_readonly("message", &SolverReport::message)
      .def_readonly("iterations", &SolverReport::iterations)
      .def_readonly("initial_cost", &SolverReport::initial_cost)
      .def_readonly("final_cost", &SolverReport::final_cost)
      .def_readonly("seconds", &SolverReport::seconds)
      .def("brief_report", &SolverReport::brief_report)
      .def("__repr__", [](const SolverReport& s) { return "<rcm.SolverReport " + s.brief_report() + ">"; });
  py::class_<CoaxialProblemOptions>(m, "CoaxialProblemOptions")
      .def(py::init<>())
      .def_readwrite("max_theta_rad", &CoaxialProblemOptions::max_theta_rad);
  py::class_<ThreeStepOptions>(m, "ThreeStepOptions")
      .def(py::init<>())
      .def_readwrite("D_min", &ThreeStepOptions::D_min, "m (paper Eq. 16)")
      .def_readwrite("D_max", &ThreeStepOptions::D_max, "m")
      .def_readwrite("D_initial", &ThreeStepOptions::D_initial, "m or None (middle of the bounds)")
      .def_readwrite("function_tolerance", &ThreeStepOptions::function_tolerance)
      .def_readwrite("max_iterations", &ThreeStepOptions::max_iterations)
      .def_readwrite("coaxial", &ThreeStepOptions::coaxial)
      .def("check", &ThreeStepOptions::check, "ValueError naming the first bad option");
  py::class_<ThreeStepResult>(m, "ThreeStepResult")
      .def_readonly("misalignment_m", &ThreeStepResult::misalignment_m, "[dr_x, dr_y, D], incision frame, m")
      .def_readonly("solver", &ThreeStepResult::solver, "SolverReport of the coaxial solve")
      .def_readonly("samples_used", &ThreeStepResult::samples_used)
      .def_readonly("f_radial_inc", &ThreeStepResult::f_radial_inc)
      .def_readonly("f_radial_in_plane", &ThreeStepResult::f_radial_in_plane)
      .def_readonly("radial_inverse", &ThreeStepResult::radial_inverse, "TissueInverseStatus of g^-1")
      .def_readonly("radial_extrapolated", &ThreeStepResult::radial_extrapolated)
      .def_readonly("radial_message", &ThreeStepResult::radial_message)
      .def("__repr__", [](const ThreeStepResult& r) {
        return "<rcm.ThreeStepResult [" + std::to_string(r.misalignment_m[0]) + ", " + std::to_string(r.misalignment_m[1]) +
               ", " + std::to_string(r.misalignment_m[2]) + "] m, " + (r.solver.converged ? "converged" : "NOT converged") + ">";
      });
  m.def("estimate_three_step", [](const IncisionFrame& inc, const TissueLaw& g, const Recording& trial, py::handle tau_fs,
                                  py::handle dtau_radial, const ThreeStepOptions& o) {
    const std::string fn = "rcm.estimate_three_step";
    const Eigen::MatrixXd tau = to_matrix(tau_fs, argument_location(fn, "tau_fs_trial"));
    const Eigen::Vector3d dtau = to_vector3(dtau_radial, argument_location(fn, "dtau_radial"));
    py::gil_scoped_release release;
    return estimate_three_step(inc, g, trial, tau, dtau, o);
  }, py::arg("incision"), py::arg("g"), py::arg("trial"), py::arg("tau_fs_trial"), py::arg("dtau_radial"),
        py::arg("options") = ThreeStepOptions{},
        "Steps 3c-3d for one trial: tau_fs_trial = predict_torque(model, trial); dtau_radial = the static\n"
        "hold's get_dtau() (zeros without a static file: the radial offset then stays 0).");

  // ---- joint torque-space estimate ----
  py::class_<JointSample>(m, "JointSample", "One precomputed sample of the joint model")
      .def_readonly("z3", &JointSample::z3)
      .def_readonly("dtau", &JointSample::dtau)
      .def_readonly("cos_theta", &JointSample::cos_theta)
      .def_readonly("qd3", &JointSample::qd3);
  py::bind_vector<std::vector<JointSample>>(m, "JointSampleList",
                                            "A list of JointSample kept in C++ (len, indexing, extend, +)");
  m.def("make_joint_samples", [](const IncisionFrame& inc, const Recording& rec, py::handle tau_fs, double max_theta_rad) {
    const Eigen::MatrixXd tau = to_matrix(tau_fs, argument_location("rcm.make_joint_samples", "tau_fs"));
    py::gil_scoped_release release;
    return make_joint_samples(inc, rec, tau, max_theta_rad);
  }, py::arg("incision"), py::arg("recording"), py::arg("tau_fs"), py::arg("max_theta_rad") = 80.0 * M_PI / 180.0,
        "Samples of a recording with their residual tau - tau_fs whose pivot stays below max_theta_rad");
  py::class_<JointEstimatorOptions>(m, "JointEstimatorOptions")
      .def(py::init<>())
      .def_readwrite("D_min", &JointEstimatorOptions::D_min)
      .def_readwrite("D_max", &JointEstimatorOptions::D_max)
      .def_readwrite("radial_max", &JointEstimatorOptions::radial_max)
      .def_readwrite("D_starts", &JointEstimatorOptions::D_starts)
      .def_readwrite("torque_sigma", &JointEstimatorOptions::torque_sigma, "residual scale per joint (N m, N m, N)")
      .def_readwrite("huber_scale", &JointEstimatorOptions::huber_scale)
      .def_readwrite("bootstrap_replicates", &JointEstimatorOptions::bootstrap_replicates)
      .def_readwrite("calibration_bootstrap_replicates", &JointEstimatorOptions::calibration_bootstrap_replicates)
      .def_readwrite("bootstrap_block_s", &JointEstimatorOptions::bootstrap_block_s)
      .def_readwrite("calibration_offset_sd_m", &JointEstimatorOptions::calibration_offset_sd_m)
      .def_readwrite("torque_bias", &JointEstimatorOptions::torque_bias, "free-space model error off the trials (N m, N m, N)")
      .def_readwrite("sample_period_s", &JointEstimatorOptions::sample_period_s)
      .def_readwrite("seed", &JointEstimatorOptions::seed)
      .def_readwrite("max_iterations", &JointEstimatorOptions::max_iterations)
      .def("check", &JointEstimatorOptions::check);
  py::class_<JointTissueModel>(m, "JointTissueModel", "Tissue parameters [k1 N/m, k3 N/m^3, c N s/m, F N] identified in torque space")
      .def_readonly("parameters", &JointTissueModel::parameters)
      .def_readonly("family", &JointTissueModel::family, "'linear' or 'stiffening'")
      .def_readonly("axial_velocity_scale", &JointTissueModel::axial_velocity_scale)
      .def_readonly("cost", &JointTissueModel::cost)
      .def_readonly("bic", &JointTissueModel::bic)
      .def_readonly("covariance", &JointTissueModel::covariance)
      .def_readonly("bootstrap_replicates", &JointTissueModel::bootstrap_replicates)
      .def_readonly("calibration_bias_m", &JointTissueModel::calibration_bias_m)
      .def_readonly("calibration_offset_m", &JointTissueModel::calibration_offset_m)
      .def("__repr__", [](const JointTissueModel& t) {
        return "<rcm.JointTissueModel " + t.family + ": k1 " + std::to_string(t.parameters[0]) + " N/m, c " +
               std::to_string(t.parameters[2]) + " N s/m>";
      });
  m.def("fit_joint_tissue_model", [](const IncisionFrame& inc, const std::vector<JointSample>& calibration, double D_star,
                                     const JointEstimatorOptions& o) {
    py::gil_scoped_release release;
    return fit_joint_tissue_model(inc, calibration, D_star, o);
  }, py::arg("incision"), py::arg("calibration"), py::arg("D_star"), py::arg("options") = JointEstimatorOptions{},
        "Step 2 in torque space on the calibration samples at the known D* (m)");
  py::class_<JointEstimate>(m, "JointEstimate")
      .def_readonly("misalignment_m", &JointEstimate::misalignment_m, "[dr_x, dr_y, D], incision frame, m")
      .def_readonly("covariance", &JointEstimate::covariance)
      .def_readonly("ci_low", &JointEstimate::ci_low, "95 % interval")
      .def_readonly("ci_high", &JointEstimate::ci_high)
      .def_readonly("sd_bootstrap", &JointEstimate::sd_bootstrap)
      .def_readonly("sd_tissue", &JointEstimate::sd_tissue)
      .def_readonly("sd_systematic", &JointEstimate::sd_systematic)
      .def_readonly("sd_systematic_scale", &JointEstimate::sd_systematic_scale)
      .def_readonly("sd_calibration_offset", &JointEstimate::sd_calibration_offset)
      .def_readonly("sd_free_space_model", &JointEstimate::sd_free_space_model)
      .def_readonly("bootstrap_replicates", &JointEstimate::bootstrap_replicates)
      .def_readonly("solver", &JointEstimate::solver, "SolverReport")
      .def_readonly("samples", &JointEstimate::samples);
  m.def("estimate_joint", [](const IncisionFrame& inc, const JointTissueModel& tissue, const std::vector<JointSample>& samples,
                             const JointEstimatorOptions& o) {
    py::gil_scoped_release release;
    return estimate_joint(inc, tissue, samples, o);
  }, py::arg("incision"), py::arg("tissue"), py::arg("samples"), py::arg("options") = JointEstimatorOptions{},
        "All three offsets in torque space (bounded robust least squares) with 95 % intervals");

  // ---- online ----
  py::class_<OnlineEstimatorOptions>(m, "OnlineEstimatorOptions")
      .def(py::init<>())
      .def_readwrite("D_min", &OnlineEstimatorOptions::D_min)
      .def_readwrite("D_max", &OnlineEstimatorOptions::D_max)
      .def_readwrite("radial_max", &OnlineEstimatorOptions::radial_max)
      .def_readwrite("D_starts", &OnlineEstimatorOptions::D_starts, "one filter each (at most 4)")
      .def_readwrite("torque_sigma", &OnlineEstimatorOptions::torque_sigma)
      .def_readwrite("correlation_time_s", &OnlineEstimatorOptions::correlation_time_s)
      .def_readwrite("huber_scale", &OnlineEstimatorOptions::huber_scale)
      .def_readwrite("initial_radial_sd_m", &OnlineEstimatorOptions::initial_radial_sd_m)
      .def_readwrite("initial_D_sd_m", &OnlineEstimatorOptions::initial_D_sd_m)
      .def_readwrite("drift_sd_m_per_sqrt_s", &OnlineEstimatorOptions::drift_sd_m_per_sqrt_s)
      .def_readwrite("max_drift_gap_s", &OnlineEstimatorOptions::max_drift_gap_s)
      .def_readwrite("hypothesis_memory_s", &OnlineEstimatorOptions::hypothesis_memory_s)
      .def_readwrite("onset_threshold", &OnlineEstimatorOptions::onset_threshold)
      .def_readwrite("alarm_force_n", &OnlineEstimatorOptions::alarm_force_n)
      .def_readwrite("alarm_clear_fraction", &OnlineEstimatorOptions::alarm_clear_fraction)
      .def_readwrite("max_theta_rad", &OnlineEstimatorOptions::max_theta_rad)
      .def_readwrite("rest_angular_speed", &OnlineEstimatorOptions::rest_angular_speed)
      .def_readwrite("rest_linear_speed", &OnlineEstimatorOptions::rest_linear_speed)
      .def_readwrite("rest_sigma_factor", &OnlineEstimatorOptions::rest_sigma_factor)
      .def_readwrite("min_dt_s", &OnlineEstimatorOptions::min_dt_s)
      .def("check", &OnlineEstimatorOptions::check);
  m.def("make_online_options", &make_online_options, py::arg("joint"),
        "Online options agreeing with a batch estimate's bounds and scales");
  py::class_<OnlineOutput>(m, "OnlineOutput", "What the online estimator says after a sample")
      .def_readonly("time", &OnlineOutput::time)
      .def_readonly("used", &OnlineOutput::used, "False: the pivot was beyond max_theta_rad")
      .def_readonly("at_rest", &OnlineOutput::at_rest)
      .def_readonly("hypothesis", &OnlineOutput::hypothesis)
      .def_readonly("misalignment_m", &OnlineOutput::misalignment_m, "[dr_x, dr_y, D], incision frame, m")
      .def_readonly("sd_m", &OnlineOutput::sd_m)
      .def_readonly("f_inc_base", &OnlineOutput::f_inc_base, "the model's force now, base frame, N")
      .def_readonly("force_norm_n", &OnlineOutput::force_norm_n)
      .def_readonly("cusum", &OnlineOutput::cusum)
      .def_readonly("fit_cost", &OnlineOutput::fit_cost,
                    "the reported filter's mean robust loss per sample: about 1.5 when the model explains the residual")
      .def_readonly("onset", &OnlineOutput::onset)
      .def_readonly("onset_time", &OnlineOutput::onset_time)
      .def_readonly("alarm", &OnlineOutput::alarm)
      .def_readonly("alarm_raised", &OnlineOutput::alarm_raised)
      .def_readonly("alarm_cleared", &OnlineOutput::alarm_cleared)
      .def_readonly("out_of_regime", &OnlineOutput::out_of_regime,
                    "the sample lies beyond the free-space model's training data (rcm.dynamics.describe_regime_flags)")
      .def_readonly("regime_flags", &OnlineOutput::regime_flags, "bit 3 j + k: joint j position (k 0), velocity (1), acceleration (2)")
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
      }, py::arg("workspace"), py::arg("shift_base"), "See OnlineEstimator.apply_rcm_shift");

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
  py::class_<CorrectionOptions>(m, "CorrectionOptions", "Gates and limits of the RCM correction (m, m/s)")
      .def(py::init<>())
      .def_readwrite("tolerance_m", &CorrectionOptions::tolerance_m, "within this, hold (default 0.002)")
      .def_readwrite("compensate_limit_m", &CorrectionOptions::compensate_limit_m,
                     "software shifts up to this in all, beyond: re-docking (default 0.010)")
      .def_readwrite("max_rate_m_per_s", &CorrectionOptions::max_rate_m_per_s, "speed of the software shift (default 0.005)")
      .def_readwrite("confidence_z", &CorrectionOptions::confidence_z, "1.96: the 95 % interval")
      .def_readwrite("max_fit_cost", &CorrectionOptions::max_fit_cost,
                     "hold above this OnlineOutput.fit_cost: the model does not explain the torques (default 10)")
      .def_readwrite("release_fraction", &CorrectionOptions::release_fraction, "back to hold below this x tolerance")
      .def_readwrite("max_step_dt_s", &CorrectionOptions::max_step_dt_s, "a step after a gap covers at most this long");
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
  py::class_<OnlineReplayOptions>(m, "OnlineReplayOptions")
      .def(py::init<>())
      .def_readwrite("settle_band_m", &OnlineReplayOptions::settle_band_m)
      .def_readwrite("motion_speed", &OnlineReplayOptions::motion_speed, "rad/s");
  py::class_<OnlineReplay>(m, "OnlineReplay", "A recording streamed through a pipeline (rcm monitor)")
      .def_readonly("samples", &OnlineReplay::samples)
      .def_readonly("final_output", &OnlineReplay::final_output)
      .def_property_readonly("motion_start_s", [](const OnlineReplay& r) { return optional_double(r.motion_start_s); })
      .def_property_readonly("onset_s", [](const OnlineReplay& r) { return optional_double(r.onset_s); })
      .def_property_readonly("settled_after_s", [](const OnlineReplay& r) { return optional_double(r.settled_after_s); })
      .def_readonly("alarms", &OnlineReplay::alarms)
      .def_readonly("peak_force_n", &OnlineReplay::peak_force_n)
      .def_readonly("mean_update_s", &OnlineReplay::mean_update_s, "wall clock per sample (with a callback: includes it)")
      .def_readonly("max_update_s", &OnlineReplay::max_update_s)
      .def_readonly("regime", &OnlineReplay::regime, "samples outside the free-space model's training regime");
  m.def("replay_online", [](const OnlinePipeline& pipeline, const Recording& rec, const OnlineReplayOptions& o,
                            py::object on_sample) {
    // With a callback the GIL stays held: it is called from this thread for every sample.
    if (!on_sample.is_none())
      return replay_online(pipeline, rec, o, [&on_sample](const OnlineOutput& out) { on_sample(out); });
    py::gil_scoped_release release;
    return replay_online(pipeline, rec, o);
  }, py::arg("pipeline"), py::arg("recording"), py::arg("options") = OnlineReplayOptions{}, py::arg("on_sample") = py::none(),
        "Stream a recording through the pipeline from its reset state; on_sample(OnlineOutput) is called\n"
        "after every sample when given.");

  // ---- the study on a session ----
  py::class_<StudyOptions>(m, "StudyOptions",
                           "Options of run_study / prepare_monitor. model_kind defaults to linear (the only kind the\n"
                           "module fits: it has no LibTorch); set model_file to use a saved model of any kind.")
      .def(py::init([] {
        StudyOptions o;
        o.model_kind = dynamics::TorqueModelKind::linear;  // as the CLI without LibTorch
        return o;
      }))
      .def_readwrite("method", &StudyOptions::method, "'joint' (default; three-step beside it) or 'three-step'")
      .def_readwrite("static_step", &StudyOptions::static_step, "StaticStep of the three-step method")
      .def_readwrite("joint", &StudyOptions::joint, "JointEstimatorOptions")
      .def_readwrite("model_kind", &StudyOptions::model_kind)
      .def_readwrite("model_file", &StudyOptions::model_file, "path of a saved free-space model, or None (fit)")
      .def_readwrite("fit", &StudyOptions::fit, "rcm.dynamics.FitOptions")
      .def_readwrite("tissue", &StudyOptions::tissue, "TissueFitOptions")
      .def_readwrite("tissue_pairs", &StudyOptions::tissue_pairs)
      .def_readwrite("tissue_sensitivity_delta_m", &StudyOptions::tissue_sensitivity_delta_m, "0: skip the D* +- delta refits")
      .def_readwrite("three_step", &StudyOptions::three_step)
      .def_readwrite("rest", &StudyOptions::rest)
      .def_readwrite("read", &StudyOptions::read, "RecordingReadOptions")
      .def_readwrite("paper_settle_s", &StudyOptions::paper_settle_s)
      .def_readwrite("hold_chatter_width_counts", &StudyOptions::hold_chatter_width_counts)
      .def_readwrite("verbose", &StudyOptions::verbose, "progress to stderr");
  py::class_<RecordingReadOptions>(m, "RecordingReadOptions")
      .def(py::init<>())
      .def_readwrite("dedupe", &RecordingReadOptions::dedupe)
      .def_readwrite("assumed_rate_hz", &RecordingReadOptions::assumed_rate_hz)
      .def_readwrite("min_joints", &RecordingReadOptions::min_joints);

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
  m.def("run_study", [](const Session& session, const StudyOptions& o) {
    py::gil_scoped_release release;
    return run_study(session, o, get_python_fitter());
  }, py::arg("session"), py::arg("options") = StudyOptions{},
        "The whole study (`rcm run`): free-space model (fitted, linear, or options.model_file), tissue law on\n"
        "the calibration, every trial of session.trials (assign a shorter list to estimate fewer).");
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
  m.def("compute_settled_free_space_torque", [](const TorqueModel& model, py::handle q0, double settle_s) {
    return compute_settled_free_space_torque(
        model, to_vector3(q0, argument_location("rcm.compute_settled_free_space_torque", "q0")), settle_s);
  }, py::arg("model"), py::arg("q0"), py::arg("settle_s") = 2.0, "The paper's f(q0, 0): the model stepped at rest from reset");
}

}  // namespace rcm::python
