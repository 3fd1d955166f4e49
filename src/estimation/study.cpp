#include "rcm/estimation/study.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>

#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/common/options.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/estimation/joint_tissue_file.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording_reader.hpp"

namespace rcm {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void progress(bool verbose, const std::string& text) {
  if (verbose) std::cerr << "[rcm] " << text << std::endl;
}

}  // namespace

TorqueModelFitter get_linear_torque_model_fitter(const InputLocation& where) {
  return TorqueModelFitter(
      [where](dynamics::TorqueModelKind kind, const std::vector<Recording>& recordings,
              const dynamics::FitOptions& options) {
        return dynamics::fit_torque_model_without_networks(kind, recordings, options, where);
      },
      false);
}

const OptionTable<StudyOptions>& get_option_table(OptionTag<StudyOptions>) {
  static const auto table =
      OptionTable<StudyOptions>("StudyOptions")
          .add("method", &StudyOptions::method,
               "joint: all offsets in torque space with 95 % intervals, three-step beside it; three-step: paper "
               "Algorithm 1 alone",
               "", {}, {"joint", "three-step"})
          .add_section("joint", &StudyOptions::joint, "the joint torque-space estimator")
          .add("model_kind", &StudyOptions::model_kind,
               "free-space model to fit (null: the default kind, linear)")
          .add("model_file", &StudyOptions::model_file, "use this saved free-space model instead of fitting one")
          .add("tissue_model_file", &StudyOptions::tissue_model_file,
               "the monitor: tissue_model.json of rcm setup, made with model_file")
          .add_section("fit", &StudyOptions::fit, "the free-space model's fit")
          .add_section("tissue", &StudyOptions::tissue, "the tissue law's symbolic regression")
          .add_section("tissue_pairs", &StudyOptions::tissue_pairs, "the calibration's pairs x, |f_inc|")
          .add("tissue_sensitivity_delta_m", &StudyOptions::tissue_sensitivity_delta_m,
               "the tissue law refitted at D* +- this (paper V-D; 0: not refitted)", "m", OptionLimits::at_least(0))
          .add("tissue_sensitivity_steps", &StudyOptions::tissue_sensitivity_steps,
               "offsets refitted in [D* - delta, D* + delta]", "", OptionLimits::at_least(2))
          .add_section("three_step", &StudyOptions::three_step, "the three-step method")
          .add_section("rest", &StudyOptions::rest, "when a sample is at rest at q0 (steps 1 and 3b)")
          .add("static_step", &StudyOptions::static_step,
               "how step 3b reads the static file: balanced (holds approached from both sides averaged apart) or "
               "last-hold (the paper's)")
          .add_section("read", &StudyOptions::read, "how the session's recordings are read")
          .add("paper_settle_s", &StudyOptions::paper_settle_s,
               "the paper's f(q0, 0): the model stepped at rest from its reset state this long", "s",
               OptionLimits::at_least(0))
          .add("hold_chatter_width_counts", &StudyOptions::hold_chatter_width_counts,
               "encoder chatter removed from a static file's positions, in encoder counts (0: none)", "counts",
               OptionLimits::at_least(0))
          .add("verbose", &StudyOptions::verbose, "progress to stderr")
          .add("export_problems_dir", &StudyOptions::export_problems_dir,
               "write every trial's coaxial problem as JSON into this folder (solver cross-checks)");
  return table;
}

std::optional<double> TrialOutcome::get_error_m() const {
  if (!truth_m) return std::nullopt;
  return (get_misalignment_m() - *truth_m).norm();
}

std::optional<double> TrialOutcome::get_three_step_error_m() const {
  if (!truth_m) return std::nullopt;
  return (estimate.misalignment_m - *truth_m).norm();
}

StaticHold compute_model_hold(const dynamics::TorqueModel& model, const Recording& recording, const Eigen::Vector3d& q0,
                              const StudyOptions& options, Eigen::MatrixXd* tau_fs) {
  // At a hold the encoders chatter by a count; the model runs on positions with
  // that chatter removed so that its friction memory survives.
  Eigen::MatrixXd predicted =
      options.hold_chatter_width_counts > 0
          ? dynamics::predict_torque(model, remove_position_chatter(recording, options.hold_chatter_width_counts *
                                                                                   estimate_position_quantum(recording)))
          : dynamics::predict_torque(model, recording);
  StaticHold hold = compute_static_hold(recording, predicted, q0, options.rest, options.static_step);
  if (tau_fs) *tau_fs = std::move(predicted);
  return hold;
}

Eigen::Vector3d compute_settled_free_space_torque(const dynamics::TorqueModel& model, const Eigen::Vector3d& q0,
                                                  double settle_s) {
  const double dt = model.info().sample_period_s > 0 ? model.info().sample_period_s : 0.005;
  const int steps = std::max(1, static_cast<int>(std::ceil(settle_s / dt)));
  auto ws = model.create_workspace();
  model.reset_state(*ws);
  std::vector<double> q(static_cast<std::size_t>(model.num_joints()), 0.0), qd(q.size(), 0.0),
      tau(static_cast<std::size_t>(model.num_outputs()), 0.0);
  for (int i = 0; i < 3 && i < model.num_joints(); ++i) q[static_cast<std::size_t>(i)] = q0[i];
  for (int k = 0; k < steps; ++k) model.compute_step(*ws, k * dt, q.data(), qd.data(), tau.data());
  return {tau[0], tau[1], tau[2]};
}

FreeSpaceModelStep fit_free_space_step(const Session& session, const StudyOptions& options,
                                       const TorqueModelFitter& fitter) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<Recording> free_space;
  for (const auto& p : session.free_space) free_space.push_back(load_recording(p, get_read_options(session, options.read)));
  FreeSpaceModelStep out = fit_free_space_step(free_space, options, fitter);
  out.seconds = seconds_since(start);
  return out;
}

FreeSpaceModelStep fit_free_space_step(const std::vector<Recording>& free_space, const StudyOptions& options,
                                       const TorqueModelFitter& fitter) {
  const auto start = std::chrono::steady_clock::now();
  FreeSpaceModelStep out;
  out.kind = fitter.resolve_kind(options.model_kind);
  if (options.model_file) {
    progress(options.verbose, "loading free-space model " + options.model_file->string());
    out.model = dynamics::load_torque_model(*options.model_file);
    out.kind = out.model->kind();
    const dynamics::TimeSplit split = dynamics::split_in_time(free_space, 0.7, 0.2);
    out.errors = dynamics::evaluate_on_segments(*out.model, free_space, split.test);
  } else {
    progress(options.verbose, "fitting the " + dynamics::to_string(out.kind) + " free-space model on " +
                                  std::to_string(free_space.size()) + " recording(s)");
    dynamics::FitResult fit = fitter(out.kind, free_space, options.fit);
    // A network whose training was cut short is not the model the study asked for.
    if (fit.summary.interrupted) throw Interrupted("interrupted while fitting the free-space model");
    out.fit = fit.summary;
    out.errors = fit.summary.test_errors;
    out.model = std::move(fit.model);
    // A verbose fit has printed its report already.
    if (!options.fit.verbose) progress(options.verbose, "free-space model: " + out.fit->brief_report());
  }
  if (out.model->num_outputs() < 3) {
    InputLocation where;
    where.file = options.model_file ? options.model_file->string() : "free-space model";
    throw InputError(where, "the model predicts " + std::to_string(out.model->num_outputs()) +
                                " joints; the estimator needs joints 1-3");
  }
  out.seconds = seconds_since(start);
  return out;
}

JointEstimatorOptions make_joint_options_for_model(const JointEstimatorOptions& base, const FreeSpaceModelStep& step) {
  JointEstimatorOptions o = base;
  // Residual scales: the free-space model's own held-out error, with a floor for
  // models that fit their data too well.
  for (const auto& e : step.errors)
    if (e.index >= 1 && e.index <= 3) o.torque_sigma[e.index - 1] = std::max(e.rmse, e.index == 3 ? 0.05 : 0.01);
  o.sample_period_s = step.model->info().sample_period_s > 0 ? step.model->info().sample_period_s : 0.005;
  return o;
}

namespace {

// Checked before a fit, so that a session without one fails at once.
void require_monitor_calibration(const Session& session) {
  if (session.calibration) return;
  InputLocation where;
  where.file = session.manifest.string();
  where.kind = InputLocation::Kind::json_field;
  where.field = "calibration";
  throw InputError(where, "missing: the monitor identifies the tissue on a calibration at a known coaxial offset");
}

// The tissue model was identified with one free-space model: only a saved one
// can be checked to be the same.
void require_model_file_with_tissue_model_file(const StudyOptions& options) {
  if (options.tissue_model_file && !options.model_file)
    throw InputError(InputLocation::plain("options", "tissue_model_file"),
                     "goes with model_file (--model-file): the free-space model the tissue model was identified with");
}

}  // namespace

MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, const TorqueModelFitter& fitter) {
  require_monitor_calibration(session);
  require_model_file_with_tissue_model_file(options);
  return prepare_monitor(session, options, fit_free_space_step(session, options, fitter));
}

MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space) {
  require_monitor_calibration(session);
  require_model_file_with_tissue_model_file(options);
  if (options.tissue_model_file) {
    MonitorSetup setup{std::move(free_space), make_incision_frame(session.q0), {}, {}};
    setup.joint_options = make_joint_options_for_model(options.joint, setup.free_space);
    progress(options.verbose, "loading tissue model " + options.tissue_model_file->string());
    setup.tissue = load_joint_tissue_model(*options.tissue_model_file,
                                           get_tissue_model_origin(session, *options.model_file));
    return setup;
  }
  return prepare_monitor(session, options, std::move(free_space),
                         load_recording(session.calibration->recording, get_read_options(session, options.read)));
}

MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space,
                             const Recording& calibration) {
  require_monitor_calibration(session);
  MonitorSetup setup{std::move(free_space), make_incision_frame(session.q0), {}, {}};
  setup.joint_options = make_joint_options_for_model(options.joint, setup.free_space);
  progress(options.verbose, "identifying the tissue model in torque space on " + calibration.source);
  const Eigen::MatrixXd tau_fs_cal = dynamics::predict_torque(*setup.free_space.model, calibration);
  setup.tissue = fit_joint_tissue_model(
      setup.incision,
      make_joint_samples(setup.incision, calibration, tau_fs_cal, options.three_step.coaxial.max_theta_rad),
      session.calibration->coaxial_offset_m, setup.joint_options);
  return setup;
}

void check_study_inputs(const Session& session, const StudyOptions& options) {
  InputLocation manifest_where;
  manifest_where.file = session.manifest.string();
  manifest_where.kind = InputLocation::Kind::json_field;
  if (!session.calibration) {
    manifest_where.field = "calibration";
    throw InputError(manifest_where, "missing: the three-step method needs a calibration at a known coaxial offset");
  }
  if (session.trials.empty()) {
    manifest_where.field = "trials";
    throw InputError(manifest_where, "no trials to estimate");
  }
  check_options(options, "StudyOptions");
}

void check_study_recordings(const Session& session, const StudyOptions& options) {
  const RecordingReadOptions read = get_read_options(session, options.read);
  std::vector<std::filesystem::path> paths;
  if (session.calibration) paths.push_back(session.calibration->recording);
  if (options.method == "joint" && session.baseline) paths.push_back(*session.baseline);
  for (const TrialSpec& spec : session.trials) {
    paths.push_back(spec.recording);
    if (spec.static_recording) paths.push_back(*spec.static_recording);
  }
  // Read through in chunks, every check made and nothing kept: memory does not grow with the files' length.
  Recording chunk;
  for (const auto& path : paths) {
    throw_if_interrupted("checking the session's recordings");
    const auto reader = open_recording(path, read);
    while (reader->read_chunk(chunk)) throw_if_interrupted("checking the session's recordings");
  }
}

StudyResult run_study(const Session& session, const StudyOptions& options, const TorqueModelFitter& fitter) {
  check_study_inputs(session, options);
  check_study_recordings(session, options);
  return run_study(session, options, fit_free_space_step(session, options, fitter));
}

namespace {

// The study's steps below share what the free-space model and the calibration
// give every trial.
struct StudyContext {
  const Session& session;
  const StudyOptions& options;
  const dynamics::TorqueModel& model;
  IncisionFrame incision;
  // The joint method's options for this model (make_joint_options_for_model),
  // its torque bias from the aligned baseline when there is one.
  JointEstimatorOptions joint_options;
  // The paper's f(q0, 0) for the paper-variant three-step estimate.
  Eigen::Vector3d tau_fs_paper = Eigen::Vector3d::Zero();
};

// A recording of the session, read with the session's and the options' read options.
Recording load_session_recording(const StudyContext& c, const std::filesystem::path& path) {
  return load_recording(path, get_read_options(c.session, c.options.read));
}

// The calibration at the known coaxial offset D* and the model's torque over it.
struct CalibrationData {
  Recording recording;
  Eigen::MatrixXd tau_fs;
};

// Step 0: the free-space model in the result (fitted or loaded by fit_free_space_step).
StudyResult start_study_result(const Session& session, const StudyOptions& options,
                               const FreeSpaceModelStep& free_space) {
  StudyResult result;
  result.method = options.method;
  result.session_manifest = session.manifest;
  result.model = free_space.model;
  result.model_kind = free_space.kind;
  result.fit = free_space.fit;
  result.free_space_errors = free_space.errors;
  result.calibration_offset_m = session.calibration->coaxial_offset_m;
  return result;
}

// Step 2 (paper III-C, V-D): the pairs x = D* tan(theta), y = |f_inc| on the
// calibration, the tissue law g by symbolic regression, and its sensitivity to
// D* when options.tissue_sensitivity_delta_m > 0.
void identify_tissue_law(const StudyContext& c, const CalibrationData& calibration, StudyResult& result) {
  const StudyOptions& options = c.options;
  TissuePairsResult pairs = compute_tissue_pairs(calibration.recording, calibration.tau_fs, c.session.q0,
                                                 result.calibration_offset_m, options.tissue_pairs);
  result.tissue_pairs = pairs.pairs;
  result.tissue_pairs_report = pairs.report;
  result.tissue = fit_tissue_law(result.tissue_pairs, options.tissue);
  if (!result.tissue.law) {
    InputLocation where;
    where.file = calibration.recording.source;
    throw InputError(where, "the identified tissue law is unusable: " + result.tissue.summary.brief_report());
  }
  progress(options.verbose, "tissue law g(x) = " + result.tissue.law->to_string(ExpressionFormat::plain, 6));
  if (options.tissue_sensitivity_delta_m > 0) {
    auto make_pairs = [&](double D) {
      return compute_tissue_pairs(calibration.recording, calibration.tau_fs, c.session.q0, D, options.tissue_pairs)
          .pairs;
    };
    result.tissue_sensitivity =
        fit_tissue_sensitivity(make_pairs, result.calibration_offset_m, options.tissue_sensitivity_delta_m,
                               options.tissue_sensitivity_steps, options.tissue);
  }
}

// The joint method's step 2 in torque space: the model's error at rest on the
// aligned baseline (the intervals' torque bias) and the tissue parameters at D*.
void identify_joint_tissue(StudyContext& c, const FreeSpaceModelStep& free_space, const CalibrationData& calibration,
                           StudyResult& result) {
  const StudyOptions& options = c.options;
  c.joint_options = make_joint_options_for_model(options.joint, free_space);
  if (c.session.baseline) {
    const Recording baseline = load_session_recording(c, *c.session.baseline);
    try {
      result.baseline_hold = compute_model_hold(c.model, baseline, c.session.q0, options);
      c.joint_options.torque_bias = result.baseline_hold->get_dtau();
      result.baseline_message = "free-space model error at rest on the aligned baseline";
    } catch (const InputError& e) {
      result.baseline_message = std::string("not used: ") + e.what();
    }
  } else {
    result.baseline_message = "no baseline in the session";
  }
  const Eigen::Vector3d& bias = c.joint_options.torque_bias;
  progress(options.verbose, "baseline: " + result.baseline_message +
                                (result.baseline_hold ? " [" + std::to_string(bias[0]) + ", " + std::to_string(bias[1]) +
                                                            ", " + std::to_string(bias[2]) + "]"
                                                      : std::string()));
  progress(options.verbose, "joint method: identifying the tissue model in torque space");
  result.joint_tissue = fit_joint_tissue_model(
      c.incision,
      make_joint_samples(c.incision, calibration.recording, calibration.tau_fs, options.three_step.coaxial.max_theta_rad),
      result.calibration_offset_m, c.joint_options);
  // The intervals widen by what the correction leaves of the baseline's error.
  if (result.baseline_hold) c.joint_options.torque_bias -= result.joint_tissue->torque_offset;
  const Eigen::Vector3d& b = result.joint_tissue->torque_offset;
  progress(options.verbose, "free-space model's torque offset from the calibration [" + std::to_string(b[0]) + ", " +
                                std::to_string(b[1]) + ", " + std::to_string(b[2]) + "], self-check " +
                                std::to_string(1e3 * result.joint_tissue->calibration_bias_m.norm()) + " mm (" +
                                result.joint_tissue->calibration_check + ")");
}

// Step 3 on one trial: its static hold (step 3b), the joint estimate and the
// trial streamed through the online estimator (joint method), and the
// three-step estimate (steps 3c-3d, paper Algorithm 1) with the hold's torque
// carried and with the paper's f(q0, 0).
void estimate_trial(const StudyContext& c, const StudyResult& result, const Recording& trial,
                    const Eigen::MatrixXd& tau_fs, const TrialSpec& spec, TrialOutcome& out,
                    Eigen::Vector3d& dtau_radial) {
  const StudyOptions& options = c.options;
  const double max_theta = options.three_step.coaxial.max_theta_rad;
  dtau_radial = Eigen::Vector3d::Zero();
  std::vector<JointSample> joint_samples;
  if (result.joint_tissue) joint_samples = make_joint_samples(c.incision, trial, tau_fs, max_theta);
  if (spec.static_recording) {
    const Recording hold_rec = load_session_recording(c, *spec.static_recording);
    Eigen::MatrixXd tau_fs_hold;
    out.hold = compute_model_hold(c.model, hold_rec, c.session.q0, options, &tau_fs_hold);
    dtau_radial = out.hold->get_dtau();
    if (result.joint_tissue) {
      const auto hold_samples = make_joint_samples(c.incision, hold_rec, tau_fs_hold, max_theta);
      joint_samples.insert(joint_samples.end(), hold_samples.begin(), hold_samples.end());
    }
  }
  if (result.joint_tissue) {
    out.joint = estimate_joint(c.incision, *result.joint_tissue, joint_samples, c.joint_options);
    // The same trial streamed sample by sample, as `rcm monitor` would see it.
    const OnlinePipeline pipeline(result.model, OnlineEstimator(c.incision, *result.joint_tissue,
                                                                make_online_options(c.joint_options)));
    out.online = replay_online(pipeline, trial);
    // The stream's summary adds what the samples alone cannot show: a torque
    // residual that no incision force explains (a payload change).
    if (out.online->regime.flagged > out.regime.flagged && out.regime.flagged == 0)
      progress(options.verbose, "  warning: " + out.online->regime.to_text());
    out.regime = out.online->regime;
  }
  const TissueLaw& g = *result.tissue.law;
  out.estimate = estimate_three_step(c.incision, g, trial, tau_fs, dtau_radial, options.three_step);
  if (out.hold)
    out.paper_variant = estimate_three_step(c.incision, g, trial, tau_fs, out.hold->tau_measured - c.tau_fs_paper,
                                            options.three_step);
}

// With StudyOptions::export_problems_dir: the trial's coaxial problem as JSON,
// with its optimum at the paper's tolerance and at 1e-15 and the median solve time.
void export_trial_problem(const StudyContext& c, const TissueLaw& g, const Recording& trial,
                          const Eigen::MatrixXd& tau_fs, const Eigen::Vector3d& dtau_radial, const TrialSpec& spec,
                          const TrialOutcome& out) {
  const StudyOptions& options = c.options;
  std::filesystem::create_directories(*options.export_problems_dir);
  const CoaxialProblem problem = make_coaxial_problem(c.incision, trial, tau_fs, dtau_radial, options.three_step.coaxial);
  nlohmann::json j = coaxial_problem_to_json(problem, g, options.three_step);
  ThreeStepOptions tight = options.three_step;
  tight.function_tolerance = 1e-15;
  j["D_paper_tolerance"] = out.estimate.misalignment_m[2];
  j["D_tight"] = solve_coaxial_offset(problem, g, tight, nullptr);
  std::vector<double> times;
  for (int k = 0; k < 21; ++k) {
    SolverReport report;
    solve_coaxial_offset(problem, g, options.three_step, &report);
    times.push_back(report.seconds);
  }
  std::nth_element(times.begin(), times.begin() + 10, times.end());
  j["ceres_seconds_median"] = times[10];
  j["trial"] = spec.name;
  save_json_file(*options.export_problems_dir / (spec.name + ".json"), j);
}

// The forces of Table III and Fig. 4: Eq. 6 at the true D when known (the
// paper's force estimation experiment), else at D~; the coaxial part with the
// hold's radial force taken out; the RMSE per axis against the sensor columns.
void score_trial_forces(const StudyContext& c, const Recording& trial, const Eigen::MatrixXd& tau_fs,
                        const Eigen::Vector3d& dtau_radial, TrialOutcome& out) {
  out.force_offset_used_m = out.truth_m ? (*out.truth_m)[2] : out.estimate.misalignment_m[2];
  const IncisionForceSeries series = compute_incision_force_series(c.incision, trial, tau_fs, out.force_offset_used_m);
  out.time = trial.time;
  out.f_estimated = series.f_inc_base;
  out.ill_conditioned_samples = series.num_ill_conditioned + series.num_singular;
  const InverseDecomposition radial = compute_inverse_decomposition(c.incision, c.session.q0, dtau_radial);
  out.f_coaxial_decoupled = out.f_estimated.rowwise() - radial.evaluate(out.force_offset_used_m).transpose();
  if (trial.force) {
    out.f_sensor = *trial.force;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Index n = 0;
    for (Eigen::Index t = 0; t < out.f_estimated.rows(); ++t) {
      if (!out.f_estimated.row(t).allFinite()) continue;
      sum += (out.f_estimated.row(t) - out.f_sensor.row(t)).array().square().matrix().transpose();
      ++n;
    }
    if (n > 0) out.force_rmse = (sum / static_cast<double>(n)).cwiseSqrt();
  }
}

void report_trial(bool verbose, const TrialOutcome& out) {
  if (!verbose) return;
  const Eigen::Vector3d m = 1e3 * out.get_misalignment_m();
  std::string line = "  estimate [" + std::to_string(m[0]).substr(0, 6) + ", " + std::to_string(m[1]).substr(0, 6) +
                     ", " + std::to_string(m[2]).substr(0, 6) + "] mm";
  if (auto e = out.get_error_m()) line += ", e = " + std::to_string(1e3 * *e).substr(0, 5) + " mm";
  progress(true, line);
}

// Step 3 on every trial: load, estimate, score, report. An interrupt ends the
// study between trials, or inside one (a Ceres solve aborted), whose partial
// outcome is dropped: the finished trials are kept.
void estimate_trials(const StudyContext& c, StudyResult& result) {
  const StudyOptions& options = c.options;
  const Session& session = c.session;
  const dynamics::RegimeMonitor regime(c.model.info().regime);
  result.trials_planned = session.trials.size();
  try {
    for (std::size_t i = 0; i < session.trials.size(); ++i) {
      throw_if_interrupted("estimating the trials");
      const TrialSpec& spec = session.trials[i];
      const auto trial_start = std::chrono::steady_clock::now();
      progress(options.verbose, "trial " + std::to_string(i + 1) + "/" + std::to_string(session.trials.size()) + ": " +
                                    spec.name);
      TrialOutcome out;
      out.name = spec.name;
      out.truth_m = spec.truth_misalignment_m;
      const Recording trial = load_session_recording(c, spec.recording);
      const Eigen::MatrixXd tau_fs = dynamics::predict_torque(c.model, trial);
      out.regime = dynamics::compute_regime_summary(regime, trial);
      if (out.regime.flagged > 0) progress(options.verbose, "  warning: " + out.regime.to_text());
      Eigen::Vector3d dtau_radial;
      estimate_trial(c, result, trial, tau_fs, spec, out, dtau_radial);
      if (options.export_problems_dir)
        export_trial_problem(c, *result.tissue.law, trial, tau_fs, dtau_radial, spec, out);
      score_trial_forces(c, trial, tau_fs, dtau_radial, out);
      out.seconds = seconds_since(trial_start);
      report_trial(options.verbose, out);
      result.trials.push_back(std::move(out));
    }
  } catch (const Interrupted&) {
    if (result.trials.empty()) throw Interrupted("interrupted before the first trial was estimated");
    result.interrupted = true;
    progress(options.verbose, "interrupted after " + std::to_string(result.trials.size()) + " of " +
                                  std::to_string(result.trials_planned) + " trials");
  }
}

}  // namespace

StudyResult run_study(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space_step) {
  const auto start = std::chrono::steady_clock::now();
  check_study_inputs(session, options);
  StudyResult result = start_study_result(session, options, free_space_step);
  StudyContext context{session, options, *result.model, make_incision_frame(session.q0), options.joint, {}};

  const CalibrationData calibration = [&] {
    CalibrationData d{load_session_recording(context, session.calibration->recording), {}};
    progress(options.verbose, "identifying the tissue law on " + d.recording.source);
    throw_if_interrupted("identifying the tissue law");
    d.tau_fs = dynamics::predict_torque(context.model, d.recording);
    return d;
  }();
  identify_tissue_law(context, calibration, result);
  throw_if_interrupted("identifying the tissue law");
  if (options.method == "joint") identify_joint_tissue(context, free_space_step, calibration, result);

  context.tau_fs_paper = compute_settled_free_space_torque(context.model, session.q0, options.paper_settle_s);
  estimate_trials(context, result);
  result.seconds = seconds_since(start) + free_space_step.seconds;
  return result;
}

}  // namespace rcm
