// rcm.dynamics: free-space torque models (load any kind, run, stream, fit the
// linear one). Nothing here needs LibTorch: the networks run on the library's
// own kernels, and only the linear model is fitted without it.

#include <cmath>

#include "common.hpp"
#include "options.hpp"
#include "rcm/dynamics/excitation.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/networks.hpp"
#include "rcm/dynamics/payload.hpp"
#include "rcm/dynamics/torque_model.hpp"

namespace rcm::python {

namespace {

using dynamics::TorqueModel;

// A workspace remembers the model that made it: compute_step() on another
// model's workspace would read a buffer of the wrong type or size (undefined
// behaviour in C++), so here it is an rcm.InputError instead.
struct TorqueWorkspace {
  std::shared_ptr<const TorqueModel> model;
  std::unique_ptr<dynamics::TorqueModelWorkspace> workspace;
};

void check_owner(const TorqueModel& model, const TorqueWorkspace& ws, const std::string& fn) {
  if (ws.model.get() != &model)
    throw InputError(argument_location(fn, "workspace"), "was created by another model; use model.create_workspace()");
}

struct PyFitResult {
  std::shared_ptr<TorqueModel> model;
  dynamics::FitSummary summary;
};

PyFitResult to_py(dynamics::FitResult&& fit) { return {std::shared_ptr<TorqueModel>(std::move(fit.model)), std::move(fit.summary)}; }

// time (T,), position and velocity (T, N >= model's joints), all finite.
struct Trajectory {
  Eigen::VectorXd time;
  Eigen::MatrixXd position, velocity;
};
Trajectory to_trajectory(const TorqueModel& model, py::handle time, py::handle position, py::handle velocity,
                         const std::string& fn) {
  Trajectory t;
  t.time = to_vector(time, argument_location(fn, "time"));
  t.position = to_matrix(position, argument_location(fn, "position"), t.time.size(), -1);
  t.velocity = to_matrix(velocity, argument_location(fn, "velocity"), t.time.size(), t.position.cols());
  if (t.position.cols() < model.num_joints())
    throw InputError(argument_location(fn, "position"), "the model reads " + std::to_string(model.num_joints()) +
                                                            " joints, the arrays have " + std::to_string(t.position.cols()));
  return t;
}

}  // namespace

void bind_dynamics(py::module_& m, py::module_& d) {
  (void)m;
  using namespace rcm::dynamics;
  py::enum_<TorqueModelKind>(d, "TorqueModelKind")
      .value("lstm", TorqueModelKind::lstm)
      .value("mlp", TorqueModelKind::mlp)
      .value("linear", TorqueModelKind::linear)
      .value("hybrid", TorqueModelKind::hybrid);
  d.def("parse_torque_model_kind", &parse_torque_model_kind, py::arg("text"), py::arg("what") = "kind",
        "'lstm' | 'mlp' | 'linear' | 'hybrid'; rcm.InputError otherwise");

  py::class_<TorqueModelInfo>(d, "TorqueModelInfo")
      .def_readonly("num_joints", &TorqueModelInfo::num_joints, "joints read: q, qdot of joints 1..num_joints")
      .def_readonly("num_outputs", &TorqueModelInfo::num_outputs, "joints predicted: 1..num_outputs")
      .def_readonly("sample_period_s", &TorqueModelInfo::sample_period_s, "the period it was trained at")
      .def_property_readonly("training", [](const TorqueModelInfo& i) { return to_python(i.training); },
                             "fit summary (dict, informative only)")
      .def_readonly("regime", &TorqueModelInfo::regime, "what the fit saw (TrainingRegime; known False if the file says nothing)");

  py::class_<TrainingRegime>(d, "TrainingRegime",
                             "Per-joint position, velocity and acceleration ranges of the data a free-space model was fitted on")
      .def_property_readonly("known", [](const TrainingRegime& r) { return !r.empty(); })
      .def_readonly("position_min", &TrainingRegime::position_min)
      .def_readonly("position_max", &TrainingRegime::position_max)
      .def_readonly("velocity_min", &TrainingRegime::velocity_min)
      .def_readonly("velocity_max", &TrainingRegime::velocity_max)
      .def_readonly("acceleration_abs_max", &TrainingRegime::acceleration_abs_max,
                    "of the causal estimate: low-pass (acceleration_filter_s) of the velocity's backward difference")
      .def_readonly("acceleration_filter_s", &TrainingRegime::acceleration_filter_s)
      .def_readonly("samples", &TrainingRegime::samples);
  d.def("get_residual_regime_flag", &get_residual_regime_flag,
        "the bit of OnlineOutput.regime_flags set while a torque residual no incision force explains persists");
  d.def("describe_regime_flags", &describe_regime_flags, py::arg("flags"),
        "'joint 1 velocity, joint 3 position' for OnlineOutput.regime_flags");
  py::class_<RegimeSummary>(d, "RegimeSummary", "Samples outside a free-space model's training regime")
      .def_readonly("known", &RegimeSummary::known, "False: the model carries no regime, nothing was checked")
      .def_readonly("samples", &RegimeSummary::samples)
      .def_readonly("flagged", &RegimeSummary::flagged)
      .def_property_readonly("fraction", &RegimeSummary::get_fraction)
      .def_property_readonly("first_time_s", [](const RegimeSummary& s) -> py::object {
        return s.first_time_s ? py::object(py::float_(*s.first_time_s)) : py::object(py::none());
      })
      .def_readonly("all_flags", &RegimeSummary::all_flags)
      .def("to_dict", [](const RegimeSummary& s) { return to_python(s.to_json()); })
      .def("__str__", &RegimeSummary::to_text);
  d.def("compute_gravity_regressor", [](py::handle q) {
    const Eigen::Vector3d qv = to_vector3(q, argument_location("compute_gravity_regressor", "q"));
    Eigen::Matrix<double, 3, LinearTorqueModel::kGravityTerms> Y;
    LinearTorqueModel::compute_gravity_regressor(qv.data(), Y);
    return Eigen::MatrixXd(Y);
  }, py::arg("q"), "3 x 17: the torque of joints 1-3 per coefficient of the free potential (docs/methods.md)");
  d.def("compute_inertia_regressor", [](py::handle q, py::handle qd, py::handle qdd) {
    const std::string fn = "compute_inertia_regressor";
    const Eigen::Vector3d qv = to_vector3(q, argument_location(fn, "q")), qdv = to_vector3(qd, argument_location(fn, "qd")),
                          qddv = to_vector3(qdd, argument_location(fn, "qdd"));
    Eigen::Matrix<double, 3, kInertiaTerms> Y;
    compute_inertia_regressor(qv.data(), qdv.data(), qddv.data(), Y);
    return Eigen::MatrixXd(Y);
  }, py::arg("q"), py::arg("qd"), py::arg("qdd"),
        "3 x 19: the torque of joints 1-3 per rigid-body inertia coefficient (Lagrange, docs/methods.md)");
  d.def("compute_gravity_moment_map", [](py::handle g) {
    Eigen::Matrix<double, 17, kGravityMoments> P;
    compute_gravity_moment_map(to_vector3(g, argument_location("compute_gravity_moment_map", "g")), P);
    return Eigen::MatrixXd(P);
  }, py::arg("g"), "17 x 7: free-potential coefficients of the 7 mass moments under gravity direction g");
  d.def("compute_dahl_state", &compute_dahl_state, py::arg("z"), py::arg("dq"), py::arg("x_c"),
        "the friction state after a displacement dq over characteristic displacement x_c");
  d.def("compute_regime_summary", [](const TorqueModel& model, const rcm::Recording& recording) {
    return compute_regime_summary(RegimeMonitor(model.info().regime), recording);
  }, py::arg("model"), py::arg("recording"),
        "The recording's samples beyond the model's training regime (what `rcm dynamics eval` prints)");

  py::class_<TorqueWorkspace>(d, "TorqueModelWorkspace",
                              "State (friction memory, LSTM h/c) and buffers of one running model; from model.create_workspace()");

  py::class_<TorqueModel, std::shared_ptr<TorqueModel>>(
      d, "TorqueModel",
      "A trained free-space model (lstm, mlp, linear or hybrid), immutable. Run it over a whole recording with\n"
      "predict_torque(), or sample by sample: ws = model.create_workspace(); tau = model.compute_step(ws, t, q, qd).")
      .def_property_readonly("kind", &TorqueModel::kind)
      .def_property_readonly("info", &TorqueModel::info)
      .def_property_readonly("num_joints", &TorqueModel::num_joints)
      .def_property_readonly("num_outputs", &TorqueModel::num_outputs)
      .def_property_readonly("output_delay", &TorqueModel::output_delay,
                             "samples by which compute_step's torque trails its input (0: the torque of the sample "
                             "passed); predict_torque and predict_torque_streaming align it")
      .def_property_readonly("output_delay_s", &TorqueModel::get_output_delay_s,
                             "the same in seconds (output_delay periods of the training rate): a caller streaming "
                             "at another rate pairs the torque with its sample that long before")
      .def("create_workspace", [](std::shared_ptr<TorqueModel> self) {
        return TorqueWorkspace{self, self->create_workspace()};
      }, "A workspace for this model, in the reset state")
      .def("reset_state", [](const TorqueModel& self, TorqueWorkspace& ws) {
        check_owner(self, ws, "TorqueModel.reset_state");
        self.reset_state(*ws.workspace);
      }, py::arg("workspace"), "Forget the history (the state at the start of a recording)")
      .def("compute_step", [](const TorqueModel& self, TorqueWorkspace& ws, double t, py::handle q, py::handle qd) {
        const std::string fn = "TorqueModel.compute_step";
        check_owner(self, ws, fn);
        to_finite(t, argument_location(fn, "t"));
        const Eigen::VectorXd qv = to_vector(q, argument_location(fn, "q"));
        const Eigen::VectorXd qdv = to_vector(qd, argument_location(fn, "qd"));
        if (qv.size() < self.num_joints() || qdv.size() < self.num_joints())
          throw InputError(argument_location(fn, qv.size() < self.num_joints() ? "q" : "qd"),
                           "expected at least " + std::to_string(self.num_joints()) + " values (the joints the model reads)");
        Eigen::VectorXd tau(self.num_outputs());
        self.compute_step(*ws.workspace, t, qv.data(), qdv.data(), tau.data());
        return tau;
      }, py::arg("workspace"), py::arg("t"), py::arg("q"), py::arg("qd"),
           "Advance by one sample at time t (s) and return tau_fs of joints 1..num_outputs (N m, N for joint 3).\n"
           "q, qd: at least num_joints values. The same as predict_torque_streaming, sample by sample;\n"
           "with output_delay d > 0, the torque of the sample output_delay_s earlier (d calls at the model's rate).")
      .def("compute_steps", [](const TorqueModel& self, TorqueWorkspace& ws, py::handle time, py::handle q,
                               py::handle qd) {
        const std::string fn = "TorqueModel.compute_steps";
        check_owner(self, ws, fn);
        const Eigen::VectorXd t = to_vector(time, argument_location(fn, "time"));
        const Eigen::MatrixXd qm = to_matrix(q, argument_location(fn, "q"), t.size());
        const Eigen::MatrixXd qdm = to_matrix(qd, argument_location(fn, "qd"), t.size(), qm.cols());
        if (qm.cols() < self.num_joints())
          throw InputError(argument_location(fn, "q"),
                           "expected at least " + std::to_string(self.num_joints()) + " columns (the joints the model reads)");
        for (Eigen::Index k = 0; k < t.size(); ++k) to_finite(t[k], argument_location(fn, "time"));
        Eigen::MatrixXd out(t.size(), self.num_outputs());
        {
          py::gil_scoped_release release;
          using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
          const RowMajor qr = qm, qdr = qdm;
          Eigen::VectorXd tau(self.num_outputs());
          for (Eigen::Index k = 0; k < t.size(); ++k) {
            self.compute_step(*ws.workspace, t[k], qr.row(k).data(), qdr.row(k).data(), tau.data());
            out.row(k) = tau.transpose();
          }
        }
        return out;
      }, py::arg("workspace"), py::arg("time"), py::arg("q"), py::arg("qd"),
           "compute_step over a block of samples (time (T,), q and qd (T, >= num_joints), e.g. a chunk of\n"
           "rcm.iter_recording), the state carried in the workspace from block to block: (T, num_outputs), row k\n"
           "what compute_step returns for sample k.")
      .def("get_step_runs", [](const TorqueModel& self, const TorqueWorkspace& ws) -> py::object {
        check_owner(self, ws, "TorqueModel.get_step_runs");
        const TorqueModel::StepRuns runs = self.get_step_runs(*ws.workspace);
        if (runs.count < 0) return py::none();
        const int M = self.num_outputs();
        Eigen::VectorXd time(runs.count);
        Eigen::MatrixXd torque(runs.count, M);
        for (int i = 0; i < runs.count; ++i) {
          time[i] = runs.time[i];
          for (int j = 0; j < M; ++j) torque(i, j) = runs.torque[static_cast<std::ptrdiff_t>(i) * M + j];
        }
        return py::make_tuple(time, torque);
      }, py::arg("workspace"),
           "The samples the last compute_step ran, oldest first: (times, torques num_runs x num_outputs), for the\n"
           "linear model with its zero-phase qddot live (after a gap in the stream, or on jittered stamps, a call\n"
           "may run several, or none); None for a model that gives one torque per call (compute_step's).")
      .def("to_json", [](const TorqueModel& self) { return to_python(torque_model_to_json(self)); },
           "The model file's content (rcm-torque-model/1) as a dict")
      .def("__repr__", [](const TorqueModel& self) {
        return "<rcm.dynamics.TorqueModel " + to_string(self.kind()) + ": " + std::to_string(self.num_joints()) +
               " joints in, " + std::to_string(self.num_outputs()) + " out>";
      });

  py::class_<LinearTorqueParameters>(d, "LinearTorqueParameters", "Coefficients of the linear model (docs/methods.md)")
      .def_readonly("gravity", &LinearTorqueParameters::gravity, "17 shared potential coefficients")
      .def_readonly("armature", &LinearTorqueParameters::armature)
      .def_readonly("viscous", &LinearTorqueParameters::viscous)
      .def_readonly("coulomb", &LinearTorqueParameters::coulomb)
      .def_readonly("offset", &LinearTorqueParameters::offset)
      .def_readonly("dahl_displacement", &LinearTorqueParameters::dahl_displacement)
      .def_readonly("acceleration_window_s", &LinearTorqueParameters::acceleration_window_s)
      .def_readonly("acceleration_filter_s", &LinearTorqueParameters::acceleration_filter_s)
      .def_readonly("batch_acceleration_window_s", &LinearTorqueParameters::batch_acceleration_window_s)
      .def_readonly("batch_acceleration_degree", &LinearTorqueParameters::batch_acceleration_degree)
      .def_readonly("inertia", &LinearTorqueParameters::inertia, "19 rigid-body inertia coefficients (empty: none)")
      .def_readonly("gravity_direction", &LinearTorqueParameters::gravity_direction,
                    "the gravity direction the fit found (unit, base frame; empty: free potential)")
      .def_readonly("coulomb_slow", &LinearTorqueParameters::coulomb_slow, "of the slow Dahl state (empty: none)")
      .def_readonly("sqrt_viscous", &LinearTorqueParameters::sqrt_viscous, "of sqrt(|qd|) sign(qd) (empty: none)")
      .def_readonly("dahl_displacement_slow", &LinearTorqueParameters::dahl_displacement_slow,
                    "the slow Dahl state's characteristic displacement (joint units; empty: none)")
      .def_readonly("friction_speed_limit", &LinearTorqueParameters::friction_speed_limit,
                    "per joint, the |qd| beyond which the rate-dependent friction holds (0 or empty: none)")
      .def_readonly("coulomb_profile", &LinearTorqueParameters::coulomb_profile,
                    "the Coulomb level's change along each joint's travel at equally spaced knots (rows: joints; "
                    "empty: constant)")
      .def_readonly("coulomb_profile_range", &LinearTorqueParameters::coulomb_profile_range,
                    "the range [lo, hi] the knots span, per joint")
      .def_readonly("stiffness", &LinearTorqueParameters::stiffness,
                    "torque per unit of each joint's position (the insertion's elastic element; empty: none)")
      .def_readonly("live_zero_phase", &LinearTorqueParameters::live_zero_phase,
                    "compute_step takes the zero-phase qddot, its torque trailing by output_delay samples");
  py::class_<LinearTorqueModel, TorqueModel, std::shared_ptr<LinearTorqueModel>>(
      d, "LinearTorqueModel", "Rigid-body terms linear in parameters plus friction with a Dahl state")
      .def_property_readonly("parameters", &LinearTorqueModel::parameters);
  py::class_<LstmTorqueModel, TorqueModel, std::shared_ptr<LstmTorqueModel>>(d, "LstmTorqueModel", "The paper's LSTM")
      .def_property_readonly("hidden_size", [](const LstmTorqueModel& s) { return s.network().hidden_size(); })
      .def_property_readonly("num_layers", [](const LstmTorqueModel& s) { return s.network().layers.size(); });
  py::class_<MlpTorqueModel, TorqueModel, std::shared_ptr<MlpTorqueModel>>(d, "MlpTorqueModel",
                                                                           "One tanh network per joint (memoryless)");
  py::class_<HybridTorqueModel, TorqueModel, std::shared_ptr<HybridTorqueModel>>(
      d, "HybridTorqueModel", "The linear model plus an LSTM on its residual")
      .def_property_readonly("hidden_size", [](const HybridTorqueModel& s) { return s.residual_network().hidden_size(); });

  d.def("load_torque_model", [](const std::filesystem::path& path) {
    py::gil_scoped_release release;
    return std::shared_ptr<TorqueModel>(load_torque_model(path));
  }, py::arg("path"), "Read a model file (rcm-torque-model/1) of any kind; rcm.InputError names the file and field");
  d.def("save_torque_model", [](const std::filesystem::path& path, const TorqueModel& model) {
    py::gil_scoped_release release;
    save_torque_model(path, model);
  }, py::arg("path"), py::arg("model"), "Write a model file atomically; save -> load is bit-exact");
  d.def("torque_model_from_json", [](py::handle document, const std::string& source) {
    return std::shared_ptr<TorqueModel>(torque_model_from_json(to_json(document), source));
  }, py::arg("document"), py::arg("source") = "<dict>", "A model from the dict of TorqueModel.to_json()");

  d.def("predict_torque", [](const TorqueModel& model, const Recording& rec) {
    py::gil_scoped_release release;
    return predict_torque(model, rec);
  }, py::arg("model"), py::arg("recording"),
        "tau_fs over a whole recording from the reset state, (T, num_outputs). Offline: the linear and hybrid\n"
        "models may use later samples for qddot (zero-phase); predict_torque_streaming is what a live robot gets.");
  d.def("predict_torque", [](const TorqueModel& model, py::handle time, py::handle position, py::handle velocity) {
    const Trajectory t = to_trajectory(model, time, position, velocity, "rcm.dynamics.predict_torque");
    py::gil_scoped_release release;
    return predict_torque(model, t.time, t.position, t.velocity);
  }, py::arg("model"), py::arg("time"), py::arg("position"), py::arg("velocity"),
        "Same from arrays: time (T,), position and velocity (T, N >= model.num_joints)");
  d.def("predict_torque_streaming", [](const TorqueModel& model, const Recording& rec) {
    py::gil_scoped_release release;
    return predict_torque_streaming(model, rec);
  }, py::arg("model"), py::arg("recording"),
        "compute_step() on every sample from the reset state, as live (row t: the torque of sample t, a delayed "
        "model's output paired with it), (T, num_outputs)");
  d.def("predict_torque_streaming", [](const TorqueModel& model, py::handle time, py::handle position, py::handle velocity) {
    const Trajectory t = to_trajectory(model, time, position, velocity, "rcm.dynamics.predict_torque_streaming");
    py::gil_scoped_release release;
    return predict_torque_streaming(model, t.time, t.position, t.velocity);
  }, py::arg("model"), py::arg("time"), py::arg("position"), py::arg("velocity"));
  d.def("check_sample_period", &check_sample_period, py::arg("model"), py::arg("recording"),
        "A warning sentence when the recording's samples are over 4 training periods apart (recurrent kinds, whose network steps at its training rate on interpolated inputs); '' otherwise");

  def_options<FitOptions>(d, "FitOptions", "Options of every fit_* (the CLI's defaults: one table, FitOptions)")
      .def("check", &FitOptions::check, "rcm.InputError when a value is out of range");
  d.def("get_default_model_kind", &get_default_model_kind,
        "The kind fitted when none is named, in every program: linear (StudyOptions.model_kind None)");
  py::class_<JointTorqueError>(d, "JointTorqueError", "Table II: per-joint RMSE and NRMSE")
      .def_readonly("index", &JointTorqueError::index, "1-based joint number")
      .def_readonly("rmse", &JointTorqueError::rmse, "N m (N for joint 3)")
      .def_readonly("nrmse_percent", &JointTorqueError::nrmse_percent, "RMSE / (max - min) x 100")
      .def_readonly("range", &JointTorqueError::range)
      .def_readonly("robust_sd", &JointTorqueError::robust_sd,
                    "the spread of the error's bulk (Huber scale), which rare spikes leave alone; NaN when streamed")
      .def("__repr__", [](const JointTorqueError& e) {
        return "<JointTorqueError joint " + std::to_string(e.index) + ": RMSE " + std::to_string(e.rmse) + ", NRMSE " +
               std::to_string(e.nrmse_percent) + " %>";
      });
  py::class_<FitSummary>(d, "FitSummary")
      .def_readonly("kind", &FitSummary::kind)
      .def_readonly("train_samples", &FitSummary::train_samples)
      .def_readonly("validation_samples", &FitSummary::validation_samples)
      .def_readonly("test_samples", &FitSummary::test_samples)
      .def_readonly("seconds", &FitSummary::seconds)
      .def_readonly("test_errors", &FitSummary::test_errors, "on the held-out last 10 %")
      .def_readonly("warnings", &FitSummary::warnings)
      .def_readonly("structure", &FitSummary::structure, "linear: 'remote-center', 'rigid-body' or 'generic'")
      .def("brief_report", &FitSummary::brief_report)
      .def("to_dict", [](const FitSummary& s) { return to_python(s.to_json()); });
  py::class_<PyFitResult>(d, "FitResult")
      .def_readonly("model", &PyFitResult::model)
      .def_readonly("summary", &PyFitResult::summary);
  d.def("fit_linear_torque_model", [](const std::vector<Recording>& recordings, const FitOptions& options) {
    py::gil_scoped_release release;
    return to_py(fit_linear_torque_model(recordings, options));
  }, py::arg("recordings"), py::arg("options") = FitOptions{},
        "Fit the linear model on free-space recordings (least squares; deterministic). The same fit as\n"
        "`rcm dynamics fit --model linear`. Returns FitResult(model, summary).");
  d.def("fit_torque_model", [](TorqueModelKind kind, const std::vector<Recording>& recordings, const FitOptions& options) {
    py::gil_scoped_release release;
    return to_py(fit_torque_model_without_networks(kind, recordings, options,
                                                   argument_location("rcm.dynamics.fit_torque_model", "kind")));
  }, py::arg("kind"), py::arg("recordings"), py::arg("options") = FitOptions{},
        "fit_linear_torque_model for kind linear; other kinds need LibTorch (rcm.InputError)");

  def_options<ExcitationOptions>(d, "ExcitationOptions",
                                 "Options of design_excitation (`rcm excite`'s flags: one table, ExcitationOptions)");
  py::class_<ExcitationSummary>(d, "ExcitationSummary", "The solver's outcome (docs/methods.md)")
      .def_readonly("converged", &ExcitationSummary::converged)
      .def_readonly("termination", &ExcitationSummary::termination)
      .def_readonly("message", &ExcitationSummary::message)
      .def_readonly("iterations", &ExcitationSummary::iterations)
      .def_readonly("initial_condition_number", &ExcitationSummary::initial_condition_number)
      .def_readonly("condition_number", &ExcitationSummary::condition_number, "of the written samples")
      .def_readonly("limits_satisfied", &ExcitationSummary::limits_satisfied)
      .def_readonly("limit_scale", &ExcitationSummary::limit_scale)
      .def_readonly("periods", &ExcitationSummary::periods)
      .def_readonly("period_s", &ExcitationSummary::period_s)
      .def_readonly("seconds", &ExcitationSummary::seconds)
      .def("brief_report", &ExcitationSummary::brief_report);
  py::class_<ExcitationTrajectory>(d, "ExcitationTrajectory",
                                   "A designed free-space trajectory of joints 1-3, sampled at the options' rate")
      .def_property_readonly("time", [](py::object self) {
        return readonly_view(self.cast<const ExcitationTrajectory&>().time, self);
      }, "(T,) s, from 0 to the duration")
      .def_property_readonly("position", [](py::object self) {
        return readonly_view(self.cast<const ExcitationTrajectory&>().position, self);
      }, "(T, 3) rad, rad, m")
      .def_property_readonly("velocity", [](py::object self) {
        return readonly_view(self.cast<const ExcitationTrajectory&>().velocity, self);
      }, "(T, 3) rad/s, rad/s, m/s")
      .def_property_readonly("acceleration", [](py::object self) {
        return readonly_view(self.cast<const ExcitationTrajectory&>().acceleration, self);
      }, "(T, 3) rad/s^2, rad/s^2, m/s^2")
      .def_readonly("reversals", &ExcitationTrajectory::reversals, "velocity sign changes per joint")
      .def_readonly("summary", &ExcitationTrajectory::summary);
  d.def("design_excitation", [](const ExcitationOptions& options, py::handle robot) {
    const PsmModel model = resolve_robot(robot);
    py::gil_scoped_release release;
    return design_excitation(model, options);
  }, py::arg("options") = ExcitationOptions{}, py::arg("robot") = "dvrk-psm-classic",
        "Design a free-space excitation trajectory (`rcm excite`; docs/howto-record-free-space.md):\n"
        "the same samples as the CLI's CSV for the same options. Bad options: ValueError naming the field;\n"
        "q0 outside the limits: rcm.InputError.");

  d.def("compute_torque_errors", [](py::handle measured, py::handle predicted) {
    const std::string fn = "rcm.dynamics.compute_torque_errors";
    const Eigen::MatrixXd a = to_matrix(measured, argument_location(fn, "measured"));
    const Eigen::MatrixXd b = to_matrix(predicted, argument_location(fn, "predicted"), a.rows(), a.cols());
    return compute_torque_errors(a, b);
  }, py::arg("measured"), py::arg("predicted"), "Per-joint RMSE / NRMSE of two (T, M) arrays");
  py::class_<RecordingTorqueStream>(
      d, "RecordingTorqueStream",
      "predict_torque over a recording given in chunks (rcm.iter_recording): add(chunk) returns the samples\n"
      "whose torque is final and their torque, (rcm.Recording, (n, num_outputs) array); finish() the rest.\n"
      "The rows are exactly predict_torque's (streaming=True: predict_torque_streaming's); memory holds only\n"
      "what the model looks ahead (the linear model's zero-phase window, a network's output delay).")
      .def(py::init([](std::shared_ptr<TorqueModel> model, bool streaming) {
             // The stream refers to the model: keep it alive with the stream (keep_alive below).
             return std::make_unique<RecordingTorqueStream>(*model, streaming ? PredictionMode::streaming
                                                                              : PredictionMode::batch);
           }),
           py::arg("model"), py::arg("streaming") = false, py::keep_alive<1, 2>())
      .def("add", [](RecordingTorqueStream& self, const Recording& chunk) {
        {
          py::gil_scoped_release release;
          self.add(chunk);
        }
        return py::make_tuple(std::make_shared<Recording>(self.get_samples()), Eigen::MatrixXd(self.get_torque()));
      }, py::arg("chunk"))
      .def("finish", [](RecordingTorqueStream& self) {
        {
          py::gil_scoped_release release;
          self.finish();
        }
        return py::make_tuple(std::make_shared<Recording>(self.get_samples()), Eigen::MatrixXd(self.get_torque()));
      });
  d.def("evaluate_torque_model", [](const TorqueModel& model, const std::vector<Recording>& recordings, double first_fraction,
                                    bool streaming) {
    py::gil_scoped_release release;
    return evaluate_torque_model(model, recordings, first_fraction,
                                 streaming ? PredictionMode::streaming : PredictionMode::batch);
  }, py::arg("model"), py::arg("recordings"), py::arg("first_fraction") = 0.0, py::arg("streaming") = false,
        "Run over every recording (reset at each start) and score samples from first_fraction of each on\n"
        "(what `rcm dynamics eval` reports; streaming=True: predict_torque_streaming, as `--streaming`)");
  d.def("refit_payload", [](const LinearTorqueModel& model, const std::vector<Recording>& recordings) {
    PayloadRefit refit;
    {
      py::gil_scoped_release release;
      refit = refit_payload(model, recordings);
    }
    py::object out = to_python(refit.to_json());
    out["model"] = py::cast(std::shared_ptr<LinearTorqueModel>(std::move(refit.model)));
    return out;
  }, py::arg("model"), py::arg("recordings"),
        "Re-identify a payload change on the insertion stage from free-space recordings with it, on a linear\n"
        "model fitted without it (what `rcm dynamics payload` does). Returns a dict: 'model' (the model with\n"
        "its potential refitted and the payload's inertia), 'payload' {'first_moment_n_m', 'weight_n',\n"
        "'inertia_kg_m2'}, 'gravity_direction', 'rms_before', 'rms_after',\n"
        "'instrument_axis', 'reciprocal_condition', 'samples'; rcm.InputError when the model or the motion\n"
        "cannot identify it.");
}

}  // namespace rcm::python
