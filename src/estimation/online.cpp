#include "rcm/estimation/online.hpp"

#include <ceres/jet.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "joint_model.hpp"
#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"

namespace rcm {

void OnlineEstimatorOptions::check() const {
  auto fail = [](const char* what) { throw std::invalid_argument(std::string("OnlineEstimatorOptions: ") + what); };
  if (!(D_min < D_max)) fail("D_min must be below D_max");
  if (!(radial_max > 0)) fail("radial_max must be > 0");
  if (D_starts.empty() || D_starts.size() > static_cast<std::size_t>(OnlineEstimator::kMaxHypotheses))
    fail("D_starts must hold 1 to kMaxHypotheses values");
  for (double d : D_starts)
    if (!(d >= D_min && d <= D_max)) fail("every D start must lie within the bounds");
  if (!(torque_sigma.minCoeff() > 0)) fail("torque_sigma must be > 0");
  if (!(correlation_time_s > 0)) fail("correlation_time_s must be > 0");
  if (!(huber_scale > 0)) fail("huber_scale must be > 0");
  if (!(initial_radial_sd_m > 0) || !(initial_D_sd_m > 0)) fail("initial standard deviations must be > 0");
  if (!(drift_sd_m_per_sqrt_s >= 0)) fail("drift_sd_m_per_sqrt_s must be >= 0");
  if (!(max_drift_gap_s > 0)) fail("max_drift_gap_s must be > 0");
  if (!(hypothesis_memory_s > 0)) fail("hypothesis_memory_s must be > 0");
  if (!(onset_threshold > 0)) fail("onset_threshold must be > 0");
  if (!(jump_threshold >= 0)) fail("jump_threshold must be >= 0 (0: off)");
  if (!(jump_allowance >= 0)) fail("jump_allowance must be >= 0");
  if (!(jump_holdoff_s >= 0)) fail("jump_holdoff_s must be >= 0");
  if (!(kept_holdoff_s >= 0)) fail("kept_holdoff_s must be >= 0");
  if (!(alarm_force_n > 0)) fail("alarm_force_n must be > 0");
  if (!(alarm_clear_fraction > 0 && alarm_clear_fraction <= 1)) fail("alarm_clear_fraction must be in (0, 1]");
  if (!(max_theta_rad > 0)) fail("max_theta_rad must be > 0");
  if (!(min_dt_s > 0)) fail("min_dt_s must be > 0");
  if (!(rest_angular_speed >= 0) || !(rest_linear_speed >= 0)) fail("rest speeds must be >= 0");
  if (!(rest_sigma_factor >= 1)) fail("rest_sigma_factor must be >= 1");
}

OnlineEstimatorOptions make_online_options(const JointEstimatorOptions& joint) {
  OnlineEstimatorOptions o;
  o.D_min = joint.D_min;
  o.D_max = joint.D_max;
  o.radial_max = joint.radial_max;
  o.D_starts = joint.D_starts;
  o.torque_sigma = joint.torque_sigma;
  o.correlation_time_s = joint.bootstrap_block_s;
  return o;
}

OnlineEstimator::OnlineEstimator(const IncisionFrame& incision, const JointTissueModel& tissue,
                                 const OnlineEstimatorOptions& options)
    : incision_(incision), tissue_(tissue), options_(options) {
  options_.check();
  measurement_variance_ = options_.torque_sigma.array().square() * options_.correlation_time_s;
}

OnlineEstimator::Workspace OnlineEstimator::create_workspace() const {
  Workspace ws;
  reset(ws);
  return ws;
}

// Every start back to its place and the prior covariance, each with the cost
// of the filter reported so far (incumbent, -1 at reset: none, cost 0): the fit
// cost then stays the forgotten mean of the whole stream, and the bank chooses
// by what the filters explain next. The incumbent itself stays, after them.
void OnlineEstimator::restart_hypotheses(Workspace& ws, int incumbent) const {
  const int starts = static_cast<int>(options_.D_starts.size());
  const Hypothesis kept = incumbent >= 0 ? ws.hypotheses[static_cast<std::size_t>(incumbent)] : Hypothesis{};
  const Eigen::Vector3d sd(options_.initial_radial_sd_m, options_.initial_radial_sd_m, options_.initial_D_sd_m);
  for (int h = 0; h < starts; ++h) {
    Hypothesis& hyp = ws.hypotheses[static_cast<std::size_t>(h)];
    hyp.p = Eigen::Vector3d(0.0, 0.0, options_.D_starts[static_cast<std::size_t>(h)]);
    hyp.P = sd.array().square().matrix().asDiagonal();
    hyp.cost = kept.cost;
    hyp.fit = hyp.fit_weight = 0.0;
  }
  ws.num_hypotheses = starts;
  if (incumbent >= 0) ws.hypotheses[static_cast<std::size_t>(ws.num_hypotheses++)] = kept;
}

void OnlineEstimator::reset(Workspace& ws) const {
  restart_hypotheses(ws, -1);
  ws.cost_weight = 0.0;
  ws.jump_armed_at = ws.kept_armed_at = 0.0;
  ws.started = false;
  ws.last_time = 0.0;
  ws.output = OnlineOutput{};
  ws.output.misalignment_m = ws.hypotheses[0].p;
  ws.output.sd_m = ws.hypotheses[0].P.diagonal().cwiseSqrt();
  ws.output.covariance_m2 = ws.hypotheses[0].P;
}

void OnlineEstimator::apply_rcm_shift(Workspace& ws, const Eigen::Vector3d& shift_base) const {
  const Eigen::Vector3d shift_inc = incision_.R_base_inc.transpose() * shift_base;
  for (int h = 0; h < ws.num_hypotheses; ++h) ws.hypotheses[static_cast<std::size_t>(h)].p -= shift_inc;
  ws.output.misalignment_m -= shift_inc;
}

namespace {
// The filter with the lowest forgotten innovation cost; on a tie the one kept
// from before a restart (after the `starts`), which restarted filters that
// predict alike at rest must beat, not equal.
int get_best_hypothesis(const OnlineEstimator::Workspace& ws, int starts) {
  int best = ws.num_hypotheses > starts ? starts : 0;
  for (int h = 0; h < ws.num_hypotheses; ++h)
    if (ws.hypotheses[static_cast<std::size_t>(h)].cost < ws.hypotheses[static_cast<std::size_t>(best)].cost) best = h;
  return best;
}
}  // namespace

const OnlineOutput& OnlineEstimator::compute_update(Workspace& ws, double time, const Eigen::Vector3d& q,
                                                    const Eigen::Vector3d& qd, const Eigen::Vector3d& dtau_measured) const {
  const OnlineEstimatorOptions& o = options_;
  // The index of the filter kept from before the last restart, when there is one.
  const int kept = static_cast<int>(o.D_starts.size());
  // The free-space model's torque offset the calibration found (0 when not fitted).
  const Eigen::Vector3d dtau = dtau_measured - tissue_.torque_offset;
  const double dt = ws.started ? std::max(time - ws.last_time, o.min_dt_s) : o.min_dt_s;
  // What one sample can tell: samples a correlation time apart are independent,
  // so a sample after a gap in the stream weighs as one such sample, not as the
  // whole gap's worth of data (its variance, its onset evidence and its share of
  // the hypothesis costs).
  const double dt_info = std::min(dt, o.correlation_time_s);
  if (!ws.started) ws.jump_armed_at = time + o.jump_holdoff_s;
  ws.started = true;
  ws.last_time = time;
  OnlineOutput& out = ws.output;
  ++out.updates;
  out.time = time;
  out.alarm_raised = out.alarm_cleared = false;

  // Time update of every filter: the incision drifts as a random walk.
  const double q_drift = o.drift_sd_m_per_sqrt_s * o.drift_sd_m_per_sqrt_s * std::min(dt, o.max_drift_gap_s);
  for (int h = 0; h < ws.num_hypotheses; ++h) ws.hypotheses[static_cast<std::size_t>(h)].P.diagonal().array() += q_drift;

  out.at_rest = std::abs(qd[0]) < o.rest_angular_speed && std::abs(qd[1]) < o.rest_angular_speed &&
                std::abs(qd[2]) < o.rest_linear_speed;
  JointSample sample;
  out.used = compute_joint_sample(incision_, q, qd, dtau, o.max_theta_rad, sample);
  if (out.used) {
    using Jet = ceres::Jet<double, 3>;
    const double rest_factor = out.at_rest ? o.rest_sigma_factor * o.rest_sigma_factor : 1.0;
    const Eigen::Vector3d R = measurement_variance_ * (rest_factor / dt_info);
    const Eigen::Vector3d inv_sigma = o.torque_sigma.cwiseInverse();
    const double forget = std::exp(-dt_info / o.hypothesis_memory_s);
    Jet tissue[4];
    for (int k = 0; k < 4; ++k) tissue[k] = Jet(tissue_.parameters[k]);
    // The filter reported before this sample: the onset test scores its
    // one-step prediction.
    const int prior_best = get_best_hypothesis(ws, kept);
    // Huber's rho of a normalized residual norm: the robust log-likelihood that
    // both the hypothesis costs and the onset test use, so that a transient the
    // free-space model misses cannot carry either.
    const double c = o.huber_scale * std::sqrt(3.0);
    auto rho = [c](double r) { return r <= c ? 0.5 * r * r : c * r - 0.5 * c * c; };
    double prior_cost_sample = 0.0;
    // The reported filter's level before this sample: what the change-point test compares with.
    const double prior_level =
        ws.cost_weight > 0 ? ws.hypotheses[static_cast<std::size_t>(prior_best)].cost / ws.cost_weight : 0.0;
    ws.cost_weight = forget * ws.cost_weight + (1.0 - forget);
    for (int h = 0; h < ws.num_hypotheses; ++h) {
      Hypothesis& hyp = ws.hypotheses[static_cast<std::size_t>(h)];
      Jet p[3], tau[3];
      for (int k = 0; k < 3; ++k) p[k] = Jet(hyp.p[k], k);
      detail::predict_joint_torque(sample, incision_.R_base_inc, tissue_.axial_velocity_scale, p, tissue, tau);
      Eigen::Vector3d nu;
      Eigen::Matrix3d H;
      for (int j = 0; j < 3; ++j) {
        nu[j] = dtau[j] - tau[j].a;
        H.row(j) = tau[j].v.transpose();
      }
      // Huber weight on the innovation in units of the free-space model error:
      // a friction spike the model misses must not throw the estimate.
      const double d = std::sqrt(nu.cwiseProduct(inv_sigma).squaredNorm() / 3.0);
      const double w = d <= o.huber_scale ? 1.0 : o.huber_scale / d;
      const double cost_sample = rho(nu.cwiseProduct(inv_sigma).norm());
      if (h == prior_best) prior_cost_sample = cost_sample;
      hyp.cost = forget * hyp.cost + (1.0 - forget) * cost_sample;

      const Eigen::Matrix3d PHt = hyp.P * H.transpose();
      const Eigen::Matrix3d HPHt = H * PHt;
      // The fit: the innovation against the spread the filter predicts for it.
      Eigen::Matrix3d S_fit = HPHt;
      S_fit.diagonal() += o.torque_sigma.cwiseAbs2();
      const Eigen::LLT<Eigen::Matrix3d> llt_fit(S_fit);
      if (llt_fit.info() == Eigen::Success) {
        const double fit_sample = rho(llt_fit.matrixL().solve(nu).norm());
        hyp.fit = forget * hyp.fit + (1.0 - forget) * fit_sample;
        hyp.fit_weight = forget * hyp.fit_weight + (1.0 - forget);
      }
      Eigen::Matrix3d S = HPHt;
      S.diagonal() += R / w;
      const Eigen::LLT<Eigen::Matrix3d> llt(S);
      if (llt.info() != Eigen::Success) continue;
      const Eigen::Matrix3d K = llt.solve(PHt.transpose()).transpose();
      hyp.p += K * nu;
      // Joseph form: stays symmetric positive definite in floating point.
      const Eigen::Matrix3d IKH = Eigen::Matrix3d::Identity() - K * H;
      hyp.P = IKH * hyp.P * IKH.transpose() + K * (R / w).asDiagonal() * K.transpose();
      hyp.P = 0.5 * (hyp.P + hyp.P.transpose()).eval();

      // The offsets' bounds hold by projection (a constrained filter's standard move).
      hyp.p[0] = std::clamp(hyp.p[0], -o.radial_max, o.radial_max);
      hyp.p[1] = std::clamp(hyp.p[1], -o.radial_max, o.radial_max);
      hyp.p[2] = std::clamp(hyp.p[2], o.D_min, o.D_max);
    }
    // Onset: log-likelihood ratio of that prediction against the aligned
    // incision, per correlation time, accumulated by a CUSUM. "Aligned" is p = 0,
    // not "no force": the shaft still slides through the tissue with friction.
    double tau_aligned[3];
    const double p_aligned[3] = {0.0, 0.0, 0.0};
    detail::predict_joint_torque(sample, incision_.R_base_inc, tissue_.axial_velocity_scale, p_aligned,
                                 tissue_.parameters.data(), tau_aligned);
    const Eigen::Vector3d nu_aligned = dtau - Eigen::Vector3d(tau_aligned[0], tau_aligned[1], tau_aligned[2]);
    const double llr =
        (rho(nu_aligned.cwiseProduct(inv_sigma).norm()) - prior_cost_sample) * (dt_info / o.correlation_time_s);
    if (!out.at_rest) out.cusum = std::max(0.0, out.cusum + llr);
    if (!out.onset && out.cusum > o.onset_threshold) {
      out.onset = true;
      out.onset_time = time;
    }
    // Change point: the reported filter's prediction costs more than its own
    // level (its forgotten mean before this sample) by more than the allowance, for
    // long enough. Scored as the onset test, per correlation time.
    const bool kept_reported = prior_best == kept;
    const bool armed = time >= ws.jump_armed_at || (kept_reported && time >= ws.kept_armed_at);
    if (o.jump_threshold > 0 && !out.at_rest && armed) {
      const double excess = (prior_cost_sample - prior_level - o.jump_allowance) * (dt_info / o.correlation_time_s);
      out.jump_cusum = std::max(0.0, out.jump_cusum + excess);
      if (out.jump_cusum > o.jump_threshold) {
        restart_hypotheses(ws, prior_best);
        ws.kept_armed_at = time + o.kept_holdoff_s;
        out.jump_cusum = 0.0;
        ++out.jumps;
        out.jump_time = time;
        ws.jump_armed_at = time + o.jump_holdoff_s;
      }
    }
  }

  const int best = get_best_hypothesis(ws, kept);
  const Hypothesis& chosen = ws.hypotheses[static_cast<std::size_t>(best)];
  out.hypothesis = best;
  out.misalignment_m = chosen.p;
  out.sd_m = chosen.P.diagonal().cwiseMax(0.0).cwiseSqrt();
  out.covariance_m2 = chosen.P;
  out.fit_cost = chosen.fit_weight > 0 ? chosen.fit / chosen.fit_weight : 0.0;

  if (out.used) {
    Eigen::Vector3d f;
    double tau[3];
    detail::predict_joint_torque(sample, incision_.R_base_inc, tissue_.axial_velocity_scale, chosen.p.data(),
                                 tissue_.parameters.data(), tau, &f);
    out.f_inc_base = f;
    out.force_norm_n = f.norm();
  }
  if (out.onset) {
    if (!out.alarm && out.force_norm_n > o.alarm_force_n) {
      out.alarm = out.alarm_raised = true;
    } else if (out.alarm && out.force_norm_n < o.alarm_clear_fraction * o.alarm_force_n) {
      out.alarm = false;
      out.alarm_cleared = true;
    }
  }
  return out;
}

namespace {
constexpr std::ptrdiff_t kDelayStride = 13;  // time, q 1-3, qd 1-3, effort 1-3, RCM shift 1-3
// The fastest stream the delay line is sized for (the dVRK streams up to 1.5 kHz).
constexpr double kFastestRateHz = 2000.0;
}  // namespace

OnlinePipeline::OnlinePipeline(std::shared_ptr<const dynamics::TorqueModel> model, OnlineEstimator estimator,
                               const dynamics::RegimeCheckOptions& regime_options)
    : model_(std::move(model)),
      estimator_(std::move(estimator)),
      regime_(model_ ? model_->info().regime : dynamics::TrainingRegime{}, regime_options),
      max_fit_cost_(regime_options.max_fit_cost),
      residual_persistence_s_(regime_options.residual_persistence_s) {
  if (!model_ || model_->num_outputs() < 3)
    throw std::invalid_argument("OnlinePipeline: the free-space model must predict joints 1-3");
}

OnlinePipeline::Workspace OnlinePipeline::create_workspace() const {
  Workspace ws;
  ws.model = model_->create_workspace();
  ws.estimator = estimator_.create_workspace();
  ws.regime = regime_.create_workspace();
  ws.tau_fs.assign(static_cast<std::size_t>(model_->num_outputs()), 0.0);
  const int d = model_->output_delay();
  if (d > 0) {
    const auto at_fastest = static_cast<int>(std::ceil(model_->get_output_delay_s() * kFastestRateHz)) + 2;
    ws.delay_line.assign(static_cast<std::size_t>(std::max(d + 1, at_fastest)) * kDelayStride, 0.0);
  }
  reset(ws);
  return ws;
}

void OnlinePipeline::reset(Workspace& ws) const {
  model_->reset_state(*ws.model);
  estimator_.reset(ws.estimator);
  regime_.reset(ws.regime);
  ws.delay_next = ws.delay_filled = 0;
  ws.delay_back = 1;
  ws.delay_last_time = std::numeric_limits<double>::quiet_NaN();
  ws.shift_declared_base.setZero();
  ws.shift_applied_base.setZero();
  ws.residual_since = std::numeric_limits<double>::quiet_NaN();
}

const OnlineOutput& OnlinePipeline::compute_sample(Workspace& ws, double time, const double* q, const double* qd,
                                                   const double* effort) const {
  model_->compute_step(*ws.model, time, q, qd, ws.tau_fs.data());
  if (ws.delay_line.empty()) {
    update_estimate(ws, time, q, qd, effort, ws.tau_fs.data());
    return finish_output(ws);
  }
  // The torque is that of a sample get_output_delay_s() before: pair it with
  // that sample's joint state and effort, kept in the delay line.
  const int capacity = static_cast<int>(ws.delay_line.size() / kDelayStride);
  // A time that goes back ends the stream (the model runs its last samples
  // now) and starts another: the line then keeps the new sample only.
  const bool restarted =
      ws.delay_filled > 0 &&
      time < ws.delay_line[static_cast<std::size_t>((ws.delay_next - 1 + capacity) % capacity) * kDelayStride];
  double* slot = ws.delay_line.data() + static_cast<std::ptrdiff_t>(ws.delay_next) * kDelayStride;
  slot[0] = time;
  std::copy(q, q + 3, slot + 1);
  std::copy(qd, qd + 3, slot + 4);
  std::copy(effort, effort + 3, slot + 7);
  std::copy(ws.shift_declared_base.data(), ws.shift_declared_base.data() + 3, slot + 10);
  ws.delay_next = (ws.delay_next + 1) % capacity;
  ws.delay_filled = std::min(ws.delay_filled + 1, capacity);
  auto entry = [&](int b) {
    return ws.delay_line.data() + static_cast<std::ptrdiff_t>((ws.delay_next - b + capacity) % capacity) * kDelayStride;
  };
  // Each sample estimated once, in order; the events of the call's updates
  // are kept together in the output.
  bool updated = false, raised = false, cleared = false;
  auto estimate = [&](const double* paired, const double* tau) {
    update_estimate(ws, paired[0], paired + 1, paired + 4, paired + 7, tau, paired + 10);
    ws.delay_last_time = paired[0];
    updated = true;
    raised |= ws.estimator.output.alarm_raised;
    cleared |= ws.estimator.output.alarm_cleared;
  };
  const dynamics::TorqueModel::StepRuns runs = model_->get_step_runs(*ws.model);
  if (runs.count < 0) {
    // One torque per call: that of the recent sample nearest the delay's
    // target (d calls ago at the model's rate). After a gap longer than the
    // delay it stays the last sample before the gap until the stream has
    // moved on that long: estimated already.
    const int back = dynamics::find_delayed_sample(
        ws.delay_filled, time - model_->get_output_delay_s(), [&](int b) { return entry(b)[0]; }, ws.delay_back + 1);
    if (back > 0) {
      ws.delay_back = back;
      if (!(entry(back)[0] <= ws.delay_last_time)) estimate(entry(back), ws.tau_fs.data());
    }
  } else {
    // Every sample the model ran this call, each with its own torque.
    const int M = model_->num_outputs();
    int back = std::min(ws.delay_back + 1, ws.delay_filled);
    for (int i = 0; i < runs.count; ++i) {
      const double t = runs.time[i];
      if (t <= ws.delay_last_time) continue;  // estimated already
      // Find the sample with that time from the last one paired (hint) on.
      while (back > 1 && entry(back)[0] < t) --back;
      while (back < ws.delay_filled && entry(back)[0] > t) ++back;
      if (back < 1 || entry(back)[0] != t) continue;  // no longer in the delay line
      ws.delay_back = back;
      estimate(entry(back), runs.torque + static_cast<std::ptrdiff_t>(i) * M);
    }
  }
  if (restarted) {
    ws.delay_filled = 1;
    ws.delay_back = 1;
    ws.delay_last_time = std::numeric_limits<double>::quiet_NaN();
  }
  if (!updated) return get_online_output(ws.estimator);  // not yet that much stream, or nothing new
  OnlineOutput& out = ws.estimator.output;
  out.alarm_raised = raised;
  out.alarm_cleared = cleared;
  return finish_output(ws);
}

void OnlinePipeline::update_estimate(Workspace& ws, double time, const double* q, const double* qd,
                                     const double* effort, const double* tau_fs, const double* shift_base) const {
  if (shift_base) {
    const Eigen::Map<const Eigen::Vector3d> paired_shift(shift_base);
    if (paired_shift != ws.shift_applied_base) {
      estimator_.apply_rcm_shift(ws.estimator, paired_shift - ws.shift_applied_base);
      ws.shift_applied_base = paired_shift;
    }
  }
  const Eigen::Vector3d dtau(effort[0] - tau_fs[0], effort[1] - tau_fs[1], effort[2] - tau_fs[2]);
  estimator_.compute_update(ws.estimator, time, Eigen::Vector3d(q[0], q[1], q[2]), Eigen::Vector3d(qd[0], qd[1], qd[2]),
                            dtau);
  // The regime of the sample the estimate is for (the delayed one, if any).
  OnlineOutput& out = ws.estimator.output;
  out.regime_flags = regime_.compute_flags(ws.regime, time, q, qd);
  if (out.fit_cost <= max_fit_cost_) {
    ws.residual_since = std::numeric_limits<double>::quiet_NaN();
  } else {
    if (!(time >= ws.residual_since)) ws.residual_since = time;  // NaN, or a time that went back
    if (time - ws.residual_since >= residual_persistence_s_) out.regime_flags |= dynamics::get_residual_regime_flag();
  }
  out.out_of_regime = out.regime_flags != 0;
}

const OnlineOutput& OnlinePipeline::finish_output(Workspace& ws) const {
  OnlineOutput& out = ws.estimator.output;
  // Relative to the RCM as it is now (rebuilt from the filters at the next update).
  if (ws.shift_declared_base != ws.shift_applied_base)
    out.misalignment_m -= estimator_.incision().R_base_inc.transpose() * (ws.shift_declared_base - ws.shift_applied_base);
  return out;
}

void OnlinePipeline::apply_rcm_shift(Workspace& ws, const Eigen::Vector3d& shift_base) const {
  if (ws.delay_line.empty()) {
    estimator_.apply_rcm_shift(ws.estimator, shift_base);
    return;
  }
  ws.shift_declared_base += shift_base;
  ws.estimator.output.misalignment_m -= estimator_.incision().R_base_inc.transpose() * shift_base;
}

const OptionTable<OnlineEstimatorOptions>& get_option_table(OptionTag<OnlineEstimatorOptions>) {
  const auto positive = OptionLimits::above(0);
  static const auto table =
      OptionTable<OnlineEstimatorOptions>("OnlineEstimatorOptions")
          .add("D_min", &OnlineEstimatorOptions::D_min, "lower bound of the coaxial offset D", "m")
          .add("D_max", &OnlineEstimatorOptions::D_max, "upper bound of D", "m")
          .add("radial_max", &OnlineEstimatorOptions::radial_max, "bound of |dr_x| and |dr_y|", "m", positive)
          .add("D_starts", &OnlineEstimatorOptions::D_starts, "one filter per start, at most 4", "m")
          .add("torque_sigma", &OnlineEstimatorOptions::torque_sigma, "the free-space model's error per joint",
               "N m, N m, N", positive)
          .add("correlation_time_s", &OnlineEstimatorOptions::correlation_time_s,
               "correlation time of the free-space model's error", "s", positive)
          .add("huber_scale", &OnlineEstimatorOptions::huber_scale, "innovations beyond this are down-weighted",
               "sigma", positive)
          .add("initial_radial_sd_m", &OnlineEstimatorOptions::initial_radial_sd_m, "prior sd of dr_x and dr_y", "m",
               positive)
          .add("initial_D_sd_m", &OnlineEstimatorOptions::initial_D_sd_m, "prior sd of D", "m", positive)
          .add("drift_sd_m_per_sqrt_s", &OnlineEstimatorOptions::drift_sd_m_per_sqrt_s,
               "random walk of the incision (patient motion)", "m/sqrt(s)", OptionLimits::at_least(0))
          .add("max_drift_gap_s", &OnlineEstimatorOptions::max_drift_gap_s,
               "a gap in the stream accrues the drift of at most this long", "s", positive)
          .add("hypothesis_memory_s", &OnlineEstimatorOptions::hypothesis_memory_s,
               "forgetting time of each filter's innovation cost", "s", positive)
          .add("onset_threshold", &OnlineEstimatorOptions::onset_threshold, "CUSUM threshold of the onset test",
               "nats per correlation time", positive)
          .add("jump_threshold", &OnlineEstimatorOptions::jump_threshold,
               "CUSUM threshold of the change-point test that restarts the filters (0: off)",
               "nats per correlation time", OptionLimits::at_least(0))
          .add("jump_allowance", &OnlineEstimatorOptions::jump_allowance,
               "the change-point test counts the innovation cost above its recent level plus this", "nats per sample",
               OptionLimits::at_least(0))
          .add("jump_holdoff_s", &OnlineEstimatorOptions::jump_holdoff_s,
               "the change-point test waits this long after a reset or a restart", "s", OptionLimits::at_least(0))
          .add("kept_holdoff_s", &OnlineEstimatorOptions::kept_holdoff_s,
               "the change-point test waits this long after a restart while the filter kept from before it is reported", "s",
               OptionLimits::at_least(0))
          .add("alarm_force_n", &OnlineEstimatorOptions::alarm_force_n, "incision force that raises the alarm (paper V-E)",
               "N", positive)
          .add("alarm_clear_fraction", &OnlineEstimatorOptions::alarm_clear_fraction,
               "the alarm clears below this fraction of its force", "", OptionLimits::above_up_to(0, 1))
          .add("max_theta_rad", &OnlineEstimatorOptions::max_theta_rad, "samples pivoting beyond this are not used",
               "rad", positive)
          .add("rest_angular_speed", &OnlineEstimatorOptions::rest_angular_speed,
               "joints 1-2 slower than this count as at rest", "rad/s", OptionLimits::at_least(0))
          .add("rest_linear_speed", &OnlineEstimatorOptions::rest_linear_speed,
               "joint 3 slower than this counts as at rest", "m/s", OptionLimits::at_least(0))
          .add("rest_sigma_factor", &OnlineEstimatorOptions::rest_sigma_factor,
               "the free-space model's error at rest, in units of torque_sigma", "", OptionLimits::at_least(1))
          .add("min_dt_s", &OnlineEstimatorOptions::min_dt_s, "samples closer in time count as this far apart", "s",
               positive)
          .add_check([](const OnlineEstimatorOptions& o) { o.check(); });
  return table;
}

const OptionTable<OnlineReplayOptions>& get_option_table(OptionTag<OnlineReplayOptions>) {
  static const auto table =
      OptionTable<OnlineReplayOptions>("OnlineReplayOptions")
          .add("settle_band_m", &OnlineReplayOptions::settle_band_m,
               "band around the final estimate for the settling time", "m", OptionLimits::above(0))
          .add("motion_speed", &OnlineReplayOptions::motion_speed, "joints 1-2 faster than this start the motion",
               "rad/s", OptionLimits::above(0));
  return table;
}

}  // namespace rcm
