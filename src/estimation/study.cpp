#include "rcm/estimation/study.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>

#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/json_file.hpp"

namespace rcm {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void progress(bool verbose, const std::string& text) {
  if (verbose) std::cerr << "[rcm] " << text << std::endl;
}

nlohmann::json vec_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

nlohmann::json solver_json(const SolverReport& s) {
  return {{"converged", s.converged}, {"termination", s.termination}, {"message", s.message},
          {"iterations", s.iterations}, {"initial_cost", s.initial_cost}, {"final_cost", s.final_cost}};
}

nlohmann::json estimate_json(const ThreeStepResult& r, const std::optional<Eigen::Vector3d>& truth) {
  nlohmann::json j = {{"misalignment_m", vec_json(r.misalignment_m)},
                      {"coaxial_solver", solver_json(r.solver)},
                      {"samples_used", r.samples_used},
                      {"radial", {{"force_inc_n", vec_json(r.f_radial_inc)},
                                  {"force_in_plane_n", r.f_radial_in_plane},
                                  {"inverse", to_string(r.radial_inverse)},
                                  {"extrapolated", r.radial_extrapolated},
                                  {"message", r.radial_message}}}};
  if (truth) j["error_m"] = (r.misalignment_m - *truth).norm();
  return j;
}

}  // namespace

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
  FreeSpaceModelStep out;
  out.kind = options.model_kind;
  std::vector<Recording> free_space;
  for (const auto& p : session.free_space) free_space.push_back(load_recording(p, get_read_options(session, options.read)));
  if (options.model_file) {
    progress(options.verbose, "loading free-space model " + options.model_file->string());
    out.model = dynamics::load_torque_model(*options.model_file);
    out.kind = out.model->kind();
    const dynamics::TimeSplit split = dynamics::split_in_time(free_space, 0.7, 0.2);
    out.errors = dynamics::evaluate_on_segments(*out.model, free_space, split.test);
  } else {
    progress(options.verbose, "fitting the " + dynamics::to_string(options.model_kind) + " free-space model on " +
                                  std::to_string(free_space.size()) + " recording(s)");
    dynamics::FitResult fit = fitter(options.model_kind, free_space, options.fit);
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

MonitorSetup prepare_monitor(const Session& session, const StudyOptions& options, const TorqueModelFitter& fitter) {
  if (!session.calibration) {
    InputLocation where;
    where.file = session.manifest.string();
    where.kind = InputLocation::Kind::json_field;
    where.field = "calibration";
    throw InputError(where, "missing: the monitor identifies the tissue on a calibration at a known coaxial offset");
  }
  MonitorSetup setup{fit_free_space_step(session, options, fitter), make_incision_frame(session.q0), {}, {}};
  setup.joint_options = make_joint_options_for_model(options.joint, setup.free_space);
  const Recording calibration = load_recording(session.calibration->recording, get_read_options(session, options.read));
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
  options.three_step.check();
  if (options.method != "three-step" && options.method != "joint") {
    InputLocation where;
    where.file = "method";
    throw InputError(where, "expected three-step or joint, got '" + options.method + "'");
  }
}

StudyResult run_study(const Session& session, const StudyOptions& options, const TorqueModelFitter& fitter) {
  check_study_inputs(session, options);
  return run_study(session, options, fit_free_space_step(session, options, fitter));
}

StudyResult run_study(const Session& session, const StudyOptions& options, FreeSpaceModelStep free_space_step) {
  const auto start = std::chrono::steady_clock::now();
  check_study_inputs(session, options);
  StudyResult result;
  result.method = options.method;
  result.session_manifest = session.manifest;
  result.model_kind = options.model_kind;
  const IncisionFrame incision = make_incision_frame(session.q0);

  // Step 0: the free-space model.
  result.model = free_space_step.model;
  result.model_kind = free_space_step.kind;
  result.fit = free_space_step.fit;
  result.free_space_errors = free_space_step.errors;
  const dynamics::TorqueModel& model = *result.model;

  // Step 2: the tissue law from the calibration at D*.
  const Recording calibration = load_recording(session.calibration->recording, get_read_options(session, options.read));
  result.calibration_offset_m = session.calibration->coaxial_offset_m;
  progress(options.verbose, "identifying the tissue law on " + calibration.source);
  throw_if_interrupted("identifying the tissue law");
  const Eigen::MatrixXd tau_fs_cal = dynamics::predict_torque(model, calibration);
  {
    TissuePairsResult pairs = compute_tissue_pairs(calibration, tau_fs_cal, session.q0, result.calibration_offset_m,
                                                   options.tissue_pairs);
    result.tissue_pairs = pairs.pairs;
    result.tissue_pairs_report = pairs.report;
  }
  result.tissue = fit_tissue_law(result.tissue_pairs, options.tissue);
  if (!result.tissue.law) {
    InputLocation where;
    where.file = calibration.source;
    throw InputError(where, "the identified tissue law is unusable: " + result.tissue.summary.brief_report());
  }
  const TissueLaw& g = *result.tissue.law;
  progress(options.verbose, "tissue law g(x) = " + g.to_string(ExpressionFormat::plain, 6));
  if (options.tissue_sensitivity_delta_m > 0) {
    auto make_pairs = [&](double D) {
      return compute_tissue_pairs(calibration, tau_fs_cal, session.q0, D, options.tissue_pairs).pairs;
    };
    result.tissue_sensitivity = fit_tissue_sensitivity(make_pairs, result.calibration_offset_m,
                                                       options.tissue_sensitivity_delta_m, 3, options.tissue);
  }

  // Joint method, step 2 in torque space: the tissue parameters at D*.
  throw_if_interrupted("identifying the tissue law");
  JointEstimatorOptions joint_options = options.joint;
  if (options.method == "joint") {
    joint_options = make_joint_options_for_model(options.joint, free_space_step);
    if (session.baseline) {
      const Recording baseline = load_recording(*session.baseline, get_read_options(session, options.read));
      try {
        result.baseline_hold = compute_model_hold(model, baseline, session.q0, options);
        joint_options.torque_bias = result.baseline_hold->get_dtau();
        result.baseline_message = "free-space model error at rest on the aligned baseline";
      } catch (const InputError& e) {
        result.baseline_message = std::string("not used: ") + e.what();
      }
    } else {
      result.baseline_message = "no baseline in the session";
    }
    progress(options.verbose, "baseline: " + result.baseline_message +
                                  (result.baseline_hold ? " [" + std::to_string(joint_options.torque_bias[0]) + ", " +
                                                              std::to_string(joint_options.torque_bias[1]) + ", " +
                                                              std::to_string(joint_options.torque_bias[2]) + "]"
                                                        : std::string()));
    progress(options.verbose, "joint method: identifying the tissue model in torque space");
    result.joint_tissue = fit_joint_tissue_model(
        incision, make_joint_samples(incision, calibration, tau_fs_cal, options.three_step.coaxial.max_theta_rad),
        result.calibration_offset_m, joint_options);
  }

  // Step 3: every trial.
  const Eigen::Vector3d tau_fs_paper = compute_settled_free_space_torque(model, session.q0, options.paper_settle_s);
  const dynamics::RegimeMonitor regime(model.info().regime);
  result.trials_planned = session.trials.size();
  // An interrupt ends the study between trials, or inside one (a Ceres solve
  // aborted), whose partial outcome is dropped: the finished trials are kept.
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
    const Recording trial = load_recording(spec.recording, get_read_options(session, options.read));
    const Eigen::MatrixXd tau_fs = dynamics::predict_torque(model, trial);
    out.regime = dynamics::compute_regime_summary(regime, trial);
    if (out.regime.flagged > 0) progress(options.verbose, "  warning: " + out.regime.to_text());
    Eigen::Vector3d dtau_radial = Eigen::Vector3d::Zero();
    std::vector<JointSample> joint_samples;
    if (result.joint_tissue)
      joint_samples = make_joint_samples(incision, trial, tau_fs, options.three_step.coaxial.max_theta_rad);
    if (spec.static_recording) {
      const Recording hold_rec = load_recording(*spec.static_recording, get_read_options(session, options.read));
      Eigen::MatrixXd tau_fs_hold;
      out.hold = compute_model_hold(model, hold_rec, session.q0, options, &tau_fs_hold);
      dtau_radial = out.hold->get_dtau();
      if (result.joint_tissue) {
        const auto hold_samples = make_joint_samples(incision, hold_rec, tau_fs_hold, options.three_step.coaxial.max_theta_rad);
        joint_samples.insert(joint_samples.end(), hold_samples.begin(), hold_samples.end());
      }
    }
    if (result.joint_tissue) {
      out.joint = estimate_joint(incision, *result.joint_tissue, joint_samples, joint_options);
      // The same trial streamed sample by sample, as `rcm monitor` would see it.
      const OnlinePipeline pipeline(result.model, OnlineEstimator(incision, *result.joint_tissue,
                                                                  make_online_options(joint_options)));
      out.online = replay_online(pipeline, trial);
    }
    out.estimate = estimate_three_step(incision, g, trial, tau_fs, dtau_radial, options.three_step);
    if (out.hold)
      out.paper_variant = estimate_three_step(incision, g, trial, tau_fs, out.hold->tau_measured - tau_fs_paper,
                                              options.three_step);

    if (options.export_problems_dir) {
      std::filesystem::create_directories(*options.export_problems_dir);
      const CoaxialProblem problem = make_coaxial_problem(incision, trial, tau_fs, dtau_radial, options.three_step.coaxial);
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

    // Forces for Table III and Fig. 4: at the true D when known (the paper's
    // force estimation experiment), else at D~.
    out.force_offset_used_m = out.truth_m ? (*out.truth_m)[2] : out.estimate.misalignment_m[2];
    const IncisionForceSeries series =
        compute_incision_force_series(incision, trial, tau_fs, out.force_offset_used_m);
    out.time = trial.time;
    out.f_estimated = series.f_inc_base;
    out.ill_conditioned_samples = series.num_ill_conditioned + series.num_singular;
    const InverseDecomposition radial = compute_inverse_decomposition(incision, session.q0, dtau_radial);
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
    out.seconds = seconds_since(trial_start);
    if (options.verbose) {
      const Eigen::Vector3d m = 1e3 * out.get_misalignment_m();
      std::string line = "  estimate [" + std::to_string(m[0]).substr(0, 6) + ", " + std::to_string(m[1]).substr(0, 6) +
                         ", " + std::to_string(m[2]).substr(0, 6) + "] mm";
      if (auto e = out.get_error_m()) line += ", e = " + std::to_string(1e3 * *e).substr(0, 5) + " mm";
      progress(true, line);
    }
    result.trials.push_back(std::move(out));
  }
  } catch (const Interrupted&) {
    if (result.trials.empty()) throw Interrupted("interrupted before the first trial was estimated");
    result.interrupted = true;
    progress(options.verbose, "interrupted after " + std::to_string(result.trials.size()) + " of " +
                                  std::to_string(result.trials_planned) + " trials");
  }
  result.seconds = seconds_since(start) + free_space_step.seconds;
  return result;
}

nlohmann::json StudyResult::to_json() const {
  nlohmann::json j;
  j["format"] = "rcm-results/1";
  j["method"] = method;
  j["session"] = session_manifest.string();
  if (interrupted)
    j["interrupted"] = {{"trials_estimated", trials.size()}, {"trials_planned", trials_planned}};
  const TissueFrontEntry& best = tissue.best();
  j["tissue_model"] = {{"expression", format_expression(best.expression, ExpressionFormat::sympy)},
                       {"complexity", best.complexity},
                       {"loss", best.loss},
                       {"score", best.score},
                       {"bic", best.bic},
                       {"latex", format_expression(best.expression, ExpressionFormat::latex, 6)},
                       {"calibration_offset_m", calibration_offset_m},
                       {"pairs", {{"samples", tissue_pairs_report.samples},
                                  {"kept", tissue_pairs_report.kept},
                                  {"dropped_small_theta", tissue_pairs_report.dropped_small_theta},
                                  {"dropped_singular", tissue_pairs_report.dropped_singular},
                                  {"dropped_ill_conditioned", tissue_pairs_report.dropped_ill_conditioned},
                                  {"dropped_non_finite", tissue_pairs_report.dropped_non_finite}}}};
  if (tissue.law) j["tissue_model"]["fitted_range_m"] = {tissue.law->x_min(), tissue.law->x_max()};
  nlohmann::json front = nlohmann::json::array();
  for (const auto& e : tissue.front)
    front.push_back({{"complexity", e.complexity}, {"loss", e.loss}, {"score", e.score}, {"bic", e.bic},
                     {"expression", format_expression(e.expression, ExpressionFormat::sympy)}});
  j["tissue_model"]["front"] = front;
  if (tissue_sensitivity) {
    nlohmann::json s = {{"leading_coefficient_min", tissue_sensitivity->leading_min},
                        {"leading_coefficient_max", tissue_sensitivity->leading_max},
                        {"same_family", tissue_sensitivity->same_family}};
    for (const auto& e : tissue_sensitivity->entries)
      s["refits"].push_back({{"offset_m", e.offset_m}, {"leading_coefficient", e.leading_coefficient},
                             {"expression", format_expression(e.best.expression, ExpressionFormat::sympy)}});
    j["tissue_model"]["sensitivity"] = s;
  }
  j["free_space_model"] = {{"kind", dynamics::to_string(model_kind)}, {"test_errors", dynamics::to_json(free_space_errors)}};
  if (fit) j["free_space_model"]["fit"] = fit->to_json();

  if (method == "joint") {
    j["baseline"] = {{"used", baseline_hold.has_value()}, {"message", baseline_message}};
    if (baseline_hold) {
      j["baseline"]["torque_residual"] = vec_json(baseline_hold->get_dtau());
      j["baseline"]["holds"] = baseline_hold->holds.size();
    }
  }
  if (joint_tissue)
    j["joint_tissue_model"] = {{"family", joint_tissue->family},
                               {"k1_n_per_m", joint_tissue->parameters[0]},
                               {"k3_n_per_m3", joint_tissue->parameters[1]},
                               {"damping_n_s_per_m", joint_tissue->parameters[2]},
                               {"axial_friction_n", joint_tissue->parameters[3]},
                               {"bic", joint_tissue->bic},
                               {"parameter_sd", {std::sqrt(joint_tissue->covariance(0, 0)), std::sqrt(joint_tissue->covariance(1, 1)),
                                                 std::sqrt(joint_tissue->covariance(2, 2)), std::sqrt(joint_tissue->covariance(3, 3))}},
                               {"bootstrap_replicates", joint_tissue->bootstrap_replicates},
                               {"calibration_bias_m", vec_json(joint_tissue->calibration_bias_m)},
                               {"bootstrap_block_s", joint_tissue->bootstrap_block_s},
                               {"calibration_offset_sd_m", joint_tissue->calibration_offset_sd_m}};
  nlohmann::json trials_json = nlohmann::json::array();
  std::vector<double> e_far, e_near, e3_far, e3_near, eo_far, eo_near;
  double settle_max = 0.0;
  std::size_t covered = 0, with_interval = 0;
  for (const auto& t : trials) {
    nlohmann::json jt = estimate_json(t.estimate, t.truth_m);
    jt["three_step"] = estimate_json(t.estimate, t.truth_m);
    if (t.joint) {
      const JointEstimate& je = *t.joint;
      nlohmann::json jj = {{"misalignment_m", vec_json(je.misalignment_m)},
                           {"ci95_low_m", vec_json(je.ci_low)},
                           {"ci95_high_m", vec_json(je.ci_high)},
                           {"sd_m", vec_json(je.covariance.diagonal().cwiseSqrt())},
                           {"sd_bootstrap_m", vec_json(je.sd_bootstrap)},
                           {"sd_tissue_m", vec_json(je.sd_tissue)},
                           {"sd_systematic_m", vec_json(je.sd_systematic)},
                           {"sd_systematic_scale_m", vec_json(je.sd_systematic_scale)},
                           {"sd_calibration_offset_m", vec_json(je.sd_calibration_offset)},
                           {"sd_free_space_model_m", vec_json(je.sd_free_space_model)},
                           {"bootstrap_replicates", je.bootstrap_replicates},
                           {"bootstrap_block_s", je.bootstrap_block_s},
                           {"samples", je.samples},
                           {"solver", solver_json(je.solver)}};
      if (t.truth_m) {
        jj["error_m"] = (je.misalignment_m - *t.truth_m).norm();
        const bool inside = ((t.truth_m->array() >= je.ci_low.array()) && (t.truth_m->array() <= je.ci_high.array())).all();
        jj["truth_inside_ci95"] = inside;
        if (je.bootstrap_replicates > 0) {
          ++with_interval;
          covered += inside ? 1 : 0;
        }
      }
      jt["joint"] = jj;
      if (t.online) {
        const OnlineReplay& o = *t.online;
        auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };
        nlohmann::json jo = {{"misalignment_m", vec_json(o.final_output.misalignment_m)},
                             {"sd_m", vec_json(o.final_output.sd_m)},
                             {"onset_s", opt(o.onset_s)},
                             {"motion_start_s", opt(o.motion_start_s)},
                             {"settled_after_s", opt(o.settled_after_s)},
                             {"alarms", o.alarms.size()},
                             {"peak_force_n", o.peak_force_n},
                             {"mean_update_us", 1e6 * o.mean_update_s}};
        if (t.truth_m) {
          const double e = (o.final_output.misalignment_m - *t.truth_m).norm();
          jo["error_m"] = e;
          ((*t.truth_m)[2] > 0.020 + 1e-9 ? eo_far : eo_near).push_back(e);
        }
        if (o.settled_after_s) settle_max = std::max(settle_max, *o.settled_after_s);
        jt["online"] = jo;
      }
      jt["misalignment_m"] = jj["misalignment_m"];
      if (t.truth_m) jt["error_m"] = jj["error_m"];
      else jt.erase("error_m");
    }
    jt["name"] = t.name;
    if (t.truth_m) jt["truth_m"] = vec_json(*t.truth_m);
    if (t.hold) {
      nlohmann::json holds = nlohmann::json::array();
      for (const HoldApproach& h : t.hold->holds)
        holds.push_back({{"duration_s", h.segment.duration_s},
                         {"samples", h.segment.end - h.segment.begin},
                         {"approach_direction", {h.direction[0], h.direction[1], h.direction[2]}},
                         {"tau_measured", vec_json(h.tau_measured)},
                         {"tau_free_space", vec_json(h.tau_free_space)}});
      const auto& b = t.hold->direction_balanced;
      jt["static_hold"] = {{"static_step", to_string(t.hold->step)},
                           {"duration_s", t.hold->segment.duration_s},
                           {"samples", t.hold->segment.end - t.hold->segment.begin},
                           {"tau_measured", vec_json(t.hold->tau_measured)},
                           {"tau_free_space", vec_json(t.hold->tau_free_space)},
                           {"direction_balanced", {b[0], b[1], b[2]}},
                           {"holds", holds}};
    }
    if (t.paper_variant) jt["paper_f_q0_0_variant"] = estimate_json(*t.paper_variant, t.truth_m);
    if (t.force_rmse) jt["force_rmse_n"] = vec_json(*t.force_rmse);
    jt["force_offset_used_m"] = t.force_offset_used_m;
    jt["ill_conditioned_samples"] = t.ill_conditioned_samples;
    jt["regime"] = t.regime.to_json();
    jt["seconds"] = t.seconds;
    if (auto e = t.get_error_m()) ((*t.truth_m)[2] > 0.020 + 1e-9 ? e_far : e_near).push_back(*e);
    if (auto e = t.get_three_step_error_m()) ((*t.truth_m)[2] > 0.020 + 1e-9 ? e3_far : e3_near).push_back(*e);
    trials_json.push_back(jt);
  }
  j["trials"] = trials_json;
  auto stats = [](const std::vector<double>& v) -> nlohmann::json {
    if (v.empty()) return nullptr;
    double mean = 0, var = 0;
    for (double x : v) mean += x;
    mean /= static_cast<double>(v.size());
    for (double x : v) var += (x - mean) * (x - mean);
    const double sd = v.size() > 1 ? std::sqrt(var / static_cast<double>(v.size() - 1)) : 0.0;
    return {{"mean_m", mean}, {"sd_m", sd}, {"trials", v.size()}};
  };
  j["summary"] = {{"error_D_above_20mm", stats(e_far)}, {"error_D_up_to_20mm", stats(e_near)}, {"seconds", seconds}};
  if (method == "joint") {
    j["summary"]["three_step_error_D_above_20mm"] = stats(e3_far);
    j["summary"]["three_step_error_D_up_to_20mm"] = stats(e3_near);
    if (with_interval > 0) j["summary"]["ci95_coverage"] = static_cast<double>(covered) / static_cast<double>(with_interval);
    j["summary"]["online_error_D_above_20mm"] = stats(eo_far);
    j["summary"]["online_error_D_up_to_20mm"] = stats(eo_near);
    j["summary"]["online_settled_after_s_max"] = settle_max;
  }
  return j;
}

}  // namespace rcm
