#pragma once
// The whole study on one session (paper IV-V): fit or load the free-space model,
// identify the tissue law on the calibration, estimate every trial, and gather
// what the paper's tables and figures show. The free-space fitter is passed in so
// that rcm::core stays free of LibTorch (the CLI passes the LibTorch-backed one).

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "rcm/dynamics/fit.hpp"
#include "rcm/estimation/joint.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/estimation/three_step.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"
#include "rcm/tissue/tissue_fit.hpp"

namespace rcm {

// Fits a free-space model of a kind; it knows whether it trains the networks.
class TorqueModelFitter {
 public:
  using Function = std::function<dynamics::FitResult(dynamics::TorqueModelKind, const std::vector<Recording>&,
                                                     const dynamics::FitOptions&)>;
  TorqueModelFitter() = default;
  // Any callable fit(kind, recordings, options) -> FitResult; `trains_networks`:
  // it fits lstm, mlp and hybrid too (rcm::torch's fit_torque_model).
  template <class F, class = std::enable_if_t<std::is_invocable_r_v<dynamics::FitResult, F&, dynamics::TorqueModelKind,
                                                                    const std::vector<Recording>&,
                                                                    const dynamics::FitOptions&>>>
  TorqueModelFitter(F fit, bool trains_networks = false)  // NOLINT: implicit, as the std::function it wraps
      : fit_(std::move(fit)), trains_networks_(trains_networks) {}

  dynamics::FitResult operator()(dynamics::TorqueModelKind kind, const std::vector<Recording>& recordings,
                                 const dynamics::FitOptions& options) const {
    return fit_(kind, recordings, options);
  }
  bool trains_networks() const { return trains_networks_; }
  // `kind` when set, else dynamics::get_default_model_kind().
  static dynamics::TorqueModelKind resolve_kind(const std::optional<dynamics::TorqueModelKind>& kind) {
    return kind ? *kind : dynamics::get_default_model_kind();
  }

 private:
  Function fit_;
  bool trains_networks_ = false;
};

// The fitter of rcm::core alone: fit_linear_torque_model for the linear kind;
// any other kind throws InputError at `where` (networks are fitted with
// rcm::torch's fit_torque_model or `rcm dynamics fit` and reach the study as
// StudyOptions::model_file, which needs no fitter at all). The Python module,
// the examples and a CLI without LibTorch use it.
TorqueModelFitter get_linear_torque_model_fitter(
    const InputLocation& where = InputLocation::plain("StudyOptions", "model_kind"));

struct StudyOptions {
  // "joint" (all offsets in torque space, with 95 % intervals; the three-step
  // estimate is computed beside it) or "three-step" (paper Algorithm 1 alone).
  // Joint is the default: it uses the whole motion, so the hysteretic friction a
  // real joint holds at rest barely moves it, where the three-step radial force
  // rests on one hold.
  std::string method = "joint";
  JointEstimatorOptions joint;
  // The free-space model to fit; unset: dynamics::get_default_model_kind(), linear.
  std::optional<dynamics::TorqueModelKind> model_kind;
  std::optional<std::filesystem::path> model_file;  // use a saved model, skip fitting
  // The monitor (prepare_monitor): with model_file, the tissue model `rcm setup`
  // saved with it (tissue_model.json), instead of identifying it again.
  std::optional<std::filesystem::path> tissue_model_file;
  dynamics::FitOptions fit;
  TissueFitOptions tissue;
  TissuePairOptions tissue_pairs;
  double tissue_sensitivity_delta_m = 0.003;  // paper V-D: D* +- 3 mm
  int tissue_sensitivity_steps = 3;           // offsets refitted in [D* - delta, D* + delta]
  ThreeStepOptions three_step;
  RestDetectionOptions rest;
  StaticStep static_step = StaticStep::balanced;  // how step 3b combines the static file's holds
  RecordingReadOptions read;
  // The paper's f(q0, 0): the model stepped on (q0, 0) from its reset state for
  // this long, then read.
  double paper_settle_s = 2.0;
  // The free-space model reads the static file's positions through a play
  // operator this many encoder counts wide (the count measured from the file;
  // see remove_position_chatter). A joint resting on a count edge toggles by one
  // count, which a model with a friction state reads as reversals: the holding
  // friction it predicts then decays although the real one stays. 0 disables.
  double hold_chatter_width_counts = 1.5;
  bool verbose = true;  // progress to stderr
  // When set, every trial's coaxial problem is written there as JSON with the
  // optimum at the paper's tolerance and at 1e-15, and the median solve time
  // (bench/scipy_crosscheck.py solves the same problems with scipy).
  std::optional<std::filesystem::path> export_problems_dir;
};
const OptionTable<StudyOptions>& get_option_table(OptionTag<StudyOptions>);

struct TrialOutcome {
  std::string name;
  std::optional<Eigen::Vector3d> truth_m;
  ThreeStepResult estimate;                     // tau_fs of the hold with state carried
  std::optional<ThreeStepResult> paper_variant;  // tau_fs of the hold = f(q0, 0)
  std::optional<JointEstimate> joint;            // with --method joint
  std::optional<OnlineReplay> online;            // with --method joint: the trial streamed through the online estimator
  std::optional<StaticHold> hold;
  // Force at the incision through J_D at the true D (or D~ without truth), vs the
  // sensor columns when present: time, estimate and sensor, T x 3 each.
  Eigen::VectorXd time;
  Eigen::MatrixXd f_estimated, f_sensor;
  Eigen::MatrixXd f_coaxial_decoupled;  // f_e - f_r at the same D
  double force_offset_used_m = 0.0;
  std::optional<Eigen::Vector3d> force_rmse;  // per axis, N
  std::size_t ill_conditioned_samples = 0;
  // The trial's samples outside the free-space model's training regime.
  dynamics::RegimeSummary regime;
  double seconds = 0.0;

  // The estimate of the study's method: joint when computed, else three-step.
  Eigen::Vector3d get_misalignment_m() const { return joint ? joint->misalignment_m : estimate.misalignment_m; }
  std::optional<double> get_error_m() const;
  std::optional<double> get_three_step_error_m() const;
};

struct StudyResult {
  std::filesystem::path session_manifest;
  std::string method = "joint";
  dynamics::TorqueModelKind model_kind = dynamics::TorqueModelKind::linear;  // the kind used
  std::shared_ptr<const dynamics::TorqueModel> model;
  std::optional<dynamics::FitSummary> fit;        // when fitted here
  std::vector<dynamics::JointTorqueError> free_space_errors;  // Table II (held-out test split)
  TissueFitResult tissue;
  TissuePairsReport tissue_pairs_report;
  TissuePairs tissue_pairs;
  std::optional<TissueSensitivity> tissue_sensitivity;
  std::optional<JointTissueModel> joint_tissue;  // with --method joint
  // The free-space model's torque residual at rest on the aligned baseline (no
  // tissue force there): its error on the arm as docked. Joint intervals include
  // it (JointEstimatorOptions::torque_bias). Unset without a baseline hold at q0,
  // with the reason in baseline_message.
  std::optional<StaticHold> baseline_hold;
  std::string baseline_message;
  double calibration_offset_m = 0.0;
  std::vector<TrialOutcome> trials;
  // An interrupt (rcm/common/interrupt.hpp) ended the study after trials.size()
  // of the session's trials_planned trials.
  bool interrupted = false;
  std::size_t trials_planned = 0;
  double seconds = 0.0;

  // The rcm-results/1 object (docs/formats.md, "Results"), with extra fields.
  nlohmann::json to_json() const;
};

// Step 0: the free-space model, fitted on the session's free-space recordings or
// loaded from options.model_file, with its errors on the held-out last 10 %.
struct FreeSpaceModelStep {
  std::shared_ptr<const dynamics::TorqueModel> model;
  dynamics::TorqueModelKind kind = dynamics::TorqueModelKind::linear;
  std::optional<dynamics::FitSummary> fit;  // when fitted here
  std::vector<dynamics::JointTorqueError> errors;
  double seconds = 0.0;  // loading the recordings and fitting
};
FreeSpaceModelStep fit_free_space_step(const Session& session, const StudyOptions& options,
                                       const TorqueModelFitter& fitter);
// The same on the session's free-space recordings already read (in the
// manifest's order), for a caller that has checked them (run_setup); seconds
// then counts the fit alone.
FreeSpaceModelStep fit_free_space_step(const std::vector<Recording>& free_space, const StudyOptions& options,
                                       const TorqueModelFitter& fitter);

// The torque-space estimators' options for a free-space model: the residual
// scales are its held-out RMSE per joint, the sample period its own.
JointEstimatorOptions make_joint_options_for_model(const JointEstimatorOptions& base, const FreeSpaceModelStep& step);

// What the online monitor needs of a session: the free-space model, the incision
// frame at q0 and the tissue model identified on the calibration.
struct MonitorSetup {
  FreeSpaceModelStep free_space;
  IncisionFrame incision;
  JointTissueModel tissue;
  JointEstimatorOptions joint_options;
};
MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, const TorqueModelFitter& fitter);
// The same with the free-space model already fitted (or loaded). With
// options.tissue_model_file the tissue model is loaded, checked against the
// session's calibration and options.model_file (estimation/joint_tissue_file.hpp).
MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space);
// The same with the session's calibration recording already read, too: the
// tissue model identified on it (what `rcm setup` saves).
MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space,
                             const Recording& calibration);

// What run_study checks of a session and options before any work: a
// calibration, at least one trial, every option within its table's limits
// (check_options); throws InputError.
void check_study_inputs(const Session& session, const StudyOptions& options);

// Reads every recording run_study will read after the free-space fit (the
// calibration, the aligned baseline for the joint method, each trial and its
// static hold) and discards it, so that a bad file stops the study before the
// fit rather than after it and the trials before it. Throws the reader's
// InputError (file, line, field).
void check_study_recordings(const Session& session, const StudyOptions& options);

// Throws InputError for any defect of the session's files; the study needs a
// calibration and at least one trial. Once an interrupt is requested
// (rcm/common/interrupt.hpp) the study stops: with the trials finished by then
// (StudyResult::interrupted), or by throwing Interrupted before the first.
StudyResult run_study(const Session& session, const StudyOptions& options, const TorqueModelFitter& fitter);
// The same with the free-space model in hand (fit_free_space_step), so that a
// caller can save it before the rest of the study runs.
StudyResult run_study(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space);

// The free-space model over a recording that ends at rest at q0 (a static file
// or the baseline), its positions' encoder chatter removed first as
// options.hold_chatter_width_counts says, and the holds combined as
// options.static_step says.
StaticHold compute_model_hold(const dynamics::TorqueModel& model, const Recording& recording, const Eigen::Vector3d& q0,
                              const StudyOptions& options, Eigen::MatrixXd* tau_fs = nullptr);

// The paper's f(q0, 0) for a stateful model: stepped on (q0, 0) from reset.
Eigen::Vector3d compute_settled_free_space_torque(const dynamics::TorqueModel& model, const Eigen::Vector3d& q0,
                                                  double settle_s);

// results.json, report.md (Tables II-IV, solver summaries) and figures/ (Fig. 3
// when the session has a force-angle sweep, Fig. 4). Figures need gnuplot; without
// it the report says so, as it does when the study was interrupted (figures are
// then not drawn). Returns the report path.
std::filesystem::path write_study_report(const StudyResult& result, const Session& session,
                                         const std::filesystem::path& out_dir);

// Table IV as text (truth, estimate, e in mm), as `rcm run` and `rcm demo` print it.
std::string format_table_iv(const StudyResult& result);

}  // namespace rcm
