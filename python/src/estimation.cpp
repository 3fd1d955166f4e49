// Estimation: the static hold, the three-step method (paper Algorithm 1) and
// the joint torque-space estimate. Solver outcomes come back as objects with
// their status (SolverReport.converged, .termination), never as exceptions.
// The online estimator and the correction are bound in online.cpp, the study
// in study.cpp.

#include <cmath>

#include "common.hpp"
#include "options.hpp"
#include "rcm/estimation/joint.hpp"
#include "rcm/estimation/joint_tissue_file.hpp"
#include "rcm/estimation/three_step.hpp"

namespace rcm::python {

void bind_estimation(py::module_& m) {
  // ---- static hold (steps 1 and 3b) ----
  def_options<RestDetectionOptions>(m, "RestDetectionOptions", "When a sample counts as at rest at q0");
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
  def_options<CoaxialProblemOptions>(m, "CoaxialProblemOptions", "Which samples the coaxial problem (step 3c) uses");
  py::enum_<CoaxialForce>(m, "CoaxialForce", "How step 3c compares the tissue law with the forces")
      .value("total", CoaxialForce::total)
      .value("difference", CoaxialForce::difference);
  def_options<ThreeStepOptions, CoaxialProblemOptions, CoaxialForce>(m, "ThreeStepOptions",
                                                                     "The three-step method (paper Algorithm 1)")
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
  def_options<JointEstimatorOptions>(m, "JointEstimatorOptions", "The joint torque-space estimator")
      .def("check", &JointEstimatorOptions::check);
  py::class_<JointTissueModel>(m, "JointTissueModel", "Tissue parameters [k1 N/m, k3 N/m^3, c N s/m, F N] identified in torque space")
      .def_readonly("parameters", &JointTissueModel::parameters)
      .def_readonly("family", &JointTissueModel::family, "'linear' or 'stiffening'")
      .def_readonly("axial_velocity_scale", &JointTissueModel::axial_velocity_scale)
      .def_readonly("cost", &JointTissueModel::cost)
      .def_readonly("bic", &JointTissueModel::bic)
      .def_readonly("covariance", &JointTissueModel::covariance)
      .def_readonly("bootstrap_replicates", &JointTissueModel::bootstrap_replicates)
      .def_readonly("torque_offset", &JointTissueModel::torque_offset,
                    "the free-space model's torque error identified on the calibration (N m, N m, N)")
      .def_readonly("torque_offset_covariance", &JointTissueModel::torque_offset_covariance)
      .def_readonly("calibration_bias_m", &JointTissueModel::calibration_bias_m,
                    "the held-out self-check: RMS per component of what one half's models find on the other half")
      .def_readonly("calibration_check", &JointTissueModel::calibration_check)
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
  py::class_<TissueModelOrigin>(m, "TissueModelOrigin",
                                "What a saved tissue model was made from: the calibration recording's and the "
                                "free-space model file's digests, D* (m) and q0")
      .def_readonly("calibration_digest", &TissueModelOrigin::calibration_digest)
      .def_readonly("free_space_model_digest", &TissueModelOrigin::free_space_model_digest)
      .def_readonly("calibration_offset_m", &TissueModelOrigin::calibration_offset_m)
      .def_readonly("q0", &TissueModelOrigin::q0);
  m.def("get_tissue_model_origin", &get_tissue_model_origin, py::arg("session"), py::arg("free_space_model_file"),
        "The origin of a tissue model identified on the session's calibration with that saved free-space model");
  m.def("save_joint_tissue_model", &save_joint_tissue_model, py::arg("path"), py::arg("model"), py::arg("origin"),
        "Writes tissue_model.json (rcm-tissue-model/1), as rcm setup does");
  m.def("load_joint_tissue_model", &load_joint_tissue_model, py::arg("path"), py::arg("expected_origin"),
        "Reads a saved tissue model; InputError when a field is bad or it was made from another origin");
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

}

}  // namespace rcm::python
