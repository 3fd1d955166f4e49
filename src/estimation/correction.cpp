#include "rcm/estimation/correction.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "rcm/common/options.hpp"

namespace rcm {

void CorrectionOptions::check() const {
  auto fail = [](const char* what) { throw std::invalid_argument(std::string("CorrectionOptions: ") + what); };
  if (!(tolerance_m > 0)) fail("tolerance_m must be > 0");
  if (!(compensate_limit_m >= tolerance_m)) fail("compensate_limit_m must be >= tolerance_m");
  if (!(max_rate_m_per_s > 0)) fail("max_rate_m_per_s must be > 0");
  if (!(confidence_z > 0)) fail("confidence_z must be > 0");
  if (!(release_fraction > 0 && release_fraction <= 1)) fail("release_fraction must be in (0, 1]");
  if (!(max_step_dt_s > 0)) fail("max_step_dt_s must be > 0");
  if (!(max_fit_cost > 0)) fail("max_fit_cost must be > 0");
  if (!(confirm_s >= 0)) fail("confirm_s must be >= 0");
  if (!(restart_confirm_s >= 0)) fail("restart_confirm_s must be >= 0");
}

const char* to_string(CorrectionAction action) {
  switch (action) {
    case CorrectionAction::hold: return "hold";
    case CorrectionAction::compensate: return "compensate";
    case CorrectionAction::reposition: return "reposition";
  }
  return "?";
}

const char* to_string(HoldReason reason) {
  switch (reason) {
    case HoldReason::none: return "none";
    case HoldReason::no_onset: return "no_onset";
    case HoldReason::model_mismatch: return "model_mismatch";
    case HoldReason::not_confident: return "not_confident";
    case HoldReason::within_tolerance: return "within_tolerance";
  }
  return "?";
}

RcmCorrector::RcmCorrector(const IncisionFrame& incision, const CorrectionOptions& options)
    : incision_(incision), options_(options) {
  options_.check();
}

RcmCorrector::Workspace RcmCorrector::create_workspace() const {
  Workspace ws;
  reset(ws);
  return ws;
}

void RcmCorrector::reset(Workspace& ws) const {
  ws.started = false;
  ws.last_time = 0.0;
  ws.jumps = 0;
  ws.sure_since = -1.0;
  ws.after_restart = false;
  ws.resumable = false;
  ws.output = CorrectionOutput{};
}

namespace {

struct MoveBounds {
  double distance = 0.0, low = 0.0, high = 0.0;
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // unit, or zero for no move
};

// The distance to move and its 95 % bounds: the standard deviation along the
// move, u^T C u from the estimate's covariance C (its axes' errors are
// correlated: the per-axis ones would misstate it); for no move, the largest
// spread.
MoveBounds compute_move_bounds(const Eigen::Vector3d& move, const Eigen::Matrix3d& covariance, double z) {
  MoveBounds b;
  b.distance = move.norm();
  double variance_along = covariance.diagonal().maxCoeff();
  if (b.distance > 0) {
    b.direction = move / b.distance;
    variance_along = b.direction.dot(covariance * b.direction);
  }
  const double sd_along = std::sqrt(std::max(0.0, variance_along));
  b.low = std::max(0.0, b.distance - z * sd_along);
  b.high = b.distance + z * sd_along;
  return b;
}

// An action starts once the estimate is out of tolerance and its 95 % interval
// is narrower than the move: the estimate then knows the direction, and a
// shift by at most its lower bound does not overshoot. Waiting for the lower
// bound to clear the tolerance instead leaves a remaining offset between the
// tolerance and about twice it uncorrected for good, since the evidence a
// misalignment leaves falls with its square near zero; and a lower bound past
// the tolerance under a wider interval (a restarted estimate: 42 mm, 3 to
// 85 mm) is no ground for re-docking advice.
bool is_sure_of_move(const MoveBounds& b) {
  const double interval = 2.0 * (b.distance - b.low);
  return b.low > 0 && interval < b.distance;
}

// A compensation that stopped at its lower bound (the evidence along the move
// ran out before the move did) resumes on the condition it ran on: the lower
// bound above zero. Asking again for an interval narrower than the move would
// leave the remaining offset, between the tolerance and a few millimetres, until
// the evidence has grown about fourfold (the interval shrinks with its square
// root): seconds of tissue stretched for nothing. The direction is not in
// question there, the first move having been sure of it.
bool starts_action(const MoveBounds& b, double tolerance, bool resumable) {
  return b.distance > tolerance && (resumable ? b.low > 0 : is_sure_of_move(b));
}

// The largest s >= 0 with |applied + s u| <= limit (u a unit vector, or zero
// for no move: then what is left of the limit in any direction).
double compute_shift_reach(const Eigen::Vector3d& applied, const Eigen::Vector3d& u, double limit) {
  const double left = limit * limit - applied.squaredNorm();
  if (left <= 0.0 && !(u.dot(applied) < 0.0)) return 0.0;
  if (u.isZero()) return std::sqrt(std::max(0.0, left));
  const double along = u.dot(applied);
  return std::max(0.0, -along + std::sqrt(std::max(0.0, along * along + left)));
}

}  // namespace

const CorrectionOutput& RcmCorrector::compute_correction(Workspace& ws, const OnlineOutput& estimate,
                                                         const Eigen::Vector3d& applied_base) const {
  return compute_correction(ws, estimate, applied_base, applied_base);
}

const CorrectionOutput& RcmCorrector::compute_correction(Workspace& ws, const OnlineOutput& estimate,
                                                         const Eigen::Vector3d& applied_base,
                                                         const Eigen::Vector3d& in_effect_base) const {
  const CorrectionOptions& o = options_;
  CorrectionOutput& out = ws.output;
  const CorrectionAction previous_action = out.action;
  const HoldReason previous_reason = out.reason;
  // A restarted estimate (the change-point test) starts from the prior: what
  // was being acted on is gone, and an action must start over.
  const bool restarted = ws.started && estimate.jumps != ws.jumps;
  ws.jumps = estimate.jumps;
  if (restarted) {
    ws.after_restart = true;
    ws.resumable = false;
  }
  const double confirm = ws.after_restart ? std::max(o.confirm_s, o.restart_confirm_s) : o.confirm_s;
  const CorrectionAction previous = restarted ? CorrectionAction::hold : out.action;
  const double dt = ws.started ? std::clamp(estimate.time - ws.last_time, 0.0, o.max_step_dt_s) : 0.0;
  ws.started = true;
  ws.last_time = estimate.time;

  out.time = estimate.time;
  out.step_base.setZero();
  out.applied_base = applied_base;
  // The misalignment left once the shift on its way has been taken.
  const Eigen::Vector3d p = estimate.misalignment_m - incision_.R_base_inc.transpose() * (applied_base - in_effect_base);
  const Eigen::Vector3d& sd = estimate.sd_m;
  const bool finite = p.allFinite() && estimate.covariance_m2.allFinite() && applied_base.allFinite();
  const MoveBounds b = finite ? compute_move_bounds(p, estimate.covariance_m2, o.confidence_z) : MoveBounds{};
  out.move_inc = finite ? p : Eigen::Vector3d::Zero();
  out.move_base = incision_.R_base_inc * out.move_inc;
  out.move_low_inc = out.move_inc - o.confidence_z * sd;
  out.move_high_inc = out.move_inc + o.confidence_z * sd;
  if (!finite) out.move_low_inc = out.move_high_inc = Eigen::Vector3d::Zero();
  out.distance_m = b.distance;
  out.distance_low_m = b.low;
  out.distance_high_m = b.high;
  out.fit_cost = estimate.fit_cost;

  // Since when the estimate has called for an action without a break.
  const bool calls_for_action = finite && estimate.onset && starts_action(b, o.tolerance_m, ws.resumable);
  if (!calls_for_action || restarted) ws.sure_since = -1.0;
  if (calls_for_action && ws.sure_since < 0) ws.sure_since = estimate.time;

  auto hold = [&](HoldReason reason) {
    out.action = CorrectionAction::hold;
    out.reason = reason;
  };
  // How far the software shift may still go along the move before the arm must
  // be re-docked: the limit bounds the shift from the docked RCM, so a move
  // back toward it (after a wrong one) is never refused for the way already
  // gone.
  const double budget = compute_shift_reach(applied_base, incision_.R_base_inc * b.direction, o.compensate_limit_m);
  // Holding: sure to be within tolerance (upper bound), with the same
  // hysteresis on the way out, or not sure either way.
  const double within_bound =
      previous_reason == HoldReason::within_tolerance ? o.tolerance_m / o.release_fraction : o.tolerance_m;
  const HoldReason settled = b.high <= within_bound ? HoldReason::within_tolerance : HoldReason::not_confident;
  if (!finite || !estimate.onset) {
    hold(HoldReason::no_onset);
  } else if (!(estimate.fit_cost <= o.max_fit_cost)) {
    hold(HoldReason::model_mismatch);
  } else if (previous == CorrectionAction::hold && !starts_action(b, o.tolerance_m, ws.resumable)) {
    hold(settled);
  } else if (previous == CorrectionAction::hold && estimate.time - ws.sure_since < confirm) {
    hold(HoldReason::not_confident);  // sure, not yet for long enough
  } else if (previous != CorrectionAction::hold && b.low <= 0.0) {
    hold(HoldReason::not_confident);  // the interval outgrew the move
    ws.resumable = previous == CorrectionAction::compensate;
  } else if (previous != CorrectionAction::hold && b.distance < o.release_fraction * o.tolerance_m) {
    hold(settled);
  } else {
    out.reason = HoldReason::none;
    if (previous == CorrectionAction::reposition)
      out.action = b.high <= budget ? CorrectionAction::compensate : CorrectionAction::reposition;
    else
      out.action = b.low > budget ? CorrectionAction::reposition : CorrectionAction::compensate;
  }
  if (out.action != CorrectionAction::hold) ws.after_restart = false;
  // Done, or nothing to resume on: the next action must be sure of its direction again.
  if (out.action == CorrectionAction::reposition ||
      (out.action == CorrectionAction::hold && out.reason != HoldReason::not_confident))
    ws.resumable = false;
  if (out.action == CorrectionAction::compensate) {
    const double step = std::min({o.max_rate_m_per_s * dt, b.low, budget});
    out.step_base = incision_.R_base_inc * (b.direction * step);
    out.applied_base = applied_base + out.step_base;
  }
  out.changed = out.action != previous_action || out.reason != previous_reason;
  return out;
}

CorrectionLoop::CorrectionLoop(OnlinePipeline pipeline, RcmCorrector corrector)
    : pipeline_(std::move(pipeline)), corrector_(std::move(corrector)) {}

CorrectionLoop::Workspace CorrectionLoop::create_workspace() const {
  Workspace ws{pipeline_.create_workspace(), corrector_.create_workspace(), Eigen::Vector3d::Zero()};
  return ws;
}

void CorrectionLoop::reset(Workspace& ws) const {
  pipeline_.reset(ws.pipeline);
  corrector_.reset(ws.corrector);
  ws.known_shift_base.setZero();
}

const CorrectionOutput& CorrectionLoop::compute_sample(Workspace& ws, double time, const double* q, const double* qd,
                                                       const double* effort, const Eigen::Vector3d& applied_base) const {
  return compute_sample(ws, time, q, qd, effort, applied_base, applied_base);
}

const CorrectionOutput& CorrectionLoop::compute_sample(Workspace& ws, double time, const double* q, const double* qd,
                                                       const double* effort, const Eigen::Vector3d& applied_base,
                                                       const Eigen::Vector3d& in_effect_base) const {
  if (!applied_base.allFinite() || !in_effect_base.allFinite())
    throw std::invalid_argument("CorrectionLoop: the commanded shift and the one in effect must be finite");
  // The estimator's offsets are relative to the RCM the arm had at the sample.
  if (in_effect_base != ws.known_shift_base) {
    pipeline_.apply_rcm_shift(ws.pipeline, in_effect_base - ws.known_shift_base);
    ws.known_shift_base = in_effect_base;
  }
  const OnlineOutput& estimate = pipeline_.compute_sample(ws.pipeline, time, q, qd, effort);
  return corrector_.compute_correction(ws.corrector, estimate, applied_base, in_effect_base);
}

namespace {

std::string format_mm(double m) {
  const double mm = std::abs(m) * 1e3;
  return mm < 9.95 ? fmt::format("{:.1f} mm", mm) : fmt::format("{:.0f} mm", mm);
}

}  // namespace

std::string describe_rcm_move(const Eigen::Vector3d& move_inc, const IncisionFrame& incision) {
  constexpr double kSmallest = 0.001;  // m: components below this are not worth saying
  std::string s;
  auto add = [&](const std::string& part) { s += (s.empty() ? "" : ", ") + part; };
  // Along the instrument: the team thinks of the insertion axis, into the patient.
  if (std::abs(move_inc[2]) >= kSmallest)
    add(format_mm(move_inc[2]) + (move_inc[2] > 0 ? " deeper along the instrument" : " shallower along the instrument"));
  // Across it: the base frame's axes, largest first.
  const Eigen::Vector3d lateral_base =
      incision.R_base_inc.col(0) * move_inc[0] + incision.R_base_inc.col(1) * move_inc[1];
  std::array<int, 3> axes = {0, 1, 2};
  std::sort(axes.begin(), axes.end(),
            [&](int a, int b) { return std::abs(lateral_base[a]) > std::abs(lateral_base[b]); });
  static constexpr const char* kAxis[3] = {"x_base", "y_base", "z_base"};
  for (int a : axes)
    if (std::abs(lateral_base[a]) >= kSmallest)
      add(format_mm(lateral_base[a]) + " toward " + (lateral_base[a] > 0 ? "+" : "-") + kAxis[a]);
  return s.empty() ? "less than 1 mm" : s;
}

std::string describe_correction(const CorrectionOutput& c, const RcmCorrector& corrector) {
  const CorrectionOptions& o = corrector.options();
  const std::string total = format_mm(c.distance_m);
  const std::string interval = fmt::format("95 % interval {:.1f} to {:.1f} mm", c.distance_low_m * 1e3, c.distance_high_m * 1e3);
  switch (c.action) {
    case CorrectionAction::hold:
      switch (c.reason) {
        case HoldReason::no_onset: return "hold: no misalignment detected";
        case HoldReason::model_mismatch:
          return fmt::format("hold: the model does not explain the joint torques (fit cost {:.1f} above {:.1f}): "
                             "check the free-space model (payload, instrument) before trusting the estimate",
                             c.fit_cost, o.max_fit_cost);
        case HoldReason::not_confident: return fmt::format("hold: not yet confident (estimate {}, {})", total, interval);
        case HoldReason::within_tolerance:
          return fmt::format("hold: the RCM is within {} of the incision (estimate {}, {})", format_mm(o.tolerance_m),
                             total, interval);
        case HoldReason::none: break;
      }
      return "hold";
    case CorrectionAction::compensate:
      return fmt::format("compensate: shifting the RCM {} at up to {}/s ({})",
                         describe_rcm_move(c.move_inc, corrector.incision()), format_mm(o.max_rate_m_per_s), interval);
    case CorrectionAction::reposition:
      return fmt::format("reposition: re-dock, move the RCM {} ({}; beyond the software limit of {})",
                         describe_rcm_move(c.move_inc, corrector.incision()), interval,
                         format_mm(o.compensate_limit_m));
  }
  return "?";
}

AlignmentCheck check_alignment(const OnlineOutput& estimate, const IncisionFrame& incision,
                               const CorrectionOptions& o) {
  o.check();
  AlignmentCheck c;
  if (!estimate.misalignment_m.allFinite() || !estimate.covariance_m2.allFinite()) {
    c.message = "no estimate yet: move the instrument about the RCM";
    return c;
  }
  const MoveBounds b = compute_move_bounds(estimate.misalignment_m, estimate.covariance_m2, o.confidence_z);
  c.within_m = b.high;
  c.confident = is_sure_of_move(b);
  if (b.high <= o.tolerance_m) {
    c.aligned = true;
    c.message = fmt::format("aligned within {} (95 %)", format_mm(b.high));
  } else if (!c.confident) {
    c.message = fmt::format("not yet sure: {} +- {}; keep moving the instrument about the RCM",
                            format_mm(b.distance), format_mm(b.high - b.distance));
  } else {
    c.message = fmt::format("{} remain ({} to {}): move the RCM {}", format_mm(b.distance), format_mm(b.low),
                            format_mm(b.high), describe_rcm_move(estimate.misalignment_m, incision));
  }
  return c;
}

const OptionTable<CorrectionOptions>& get_option_table(OptionTag<CorrectionOptions>) {
  static const auto table =
      OptionTable<CorrectionOptions>("CorrectionOptions")
          .add("tolerance_m", &CorrectionOptions::tolerance_m, "the RCM is aligned within this distance: hold", "m",
               OptionLimits::above(0))
          .add("compensate_limit_m", &CorrectionOptions::compensate_limit_m,
               "software RCM shifts up to this in all, beyond it re-docking advice", "m", OptionLimits::above(0))
          .add("max_rate_m_per_s", &CorrectionOptions::max_rate_m_per_s, "speed of the software RCM shift", "m/s",
               OptionLimits::above(0))
          .add("confidence_z", &CorrectionOptions::confidence_z, "the interval the gates read: 1.96 is 95 %", "",
               OptionLimits::above(0))
          .add("max_fit_cost", &CorrectionOptions::max_fit_cost,
               "hold above this OnlineOutput::fit_cost: the model does not explain the torques (1.5: a perfect fit)",
               "", OptionLimits::above(0))
          .add("release_fraction", &CorrectionOptions::release_fraction,
               "back to hold below this fraction of the tolerance", "", OptionLimits::above_up_to(0, 1))
          .add("confirm_s", &CorrectionOptions::confirm_s,
               "an action starts once the estimate has called for it this long without a break", "s",
               OptionLimits::at_least(0))
          .add("restart_confirm_s", &CorrectionOptions::restart_confirm_s,
               "the first action after a restart of the estimate waits this long instead", "s",
               OptionLimits::at_least(0))
          .add("max_step_dt_s", &CorrectionOptions::max_step_dt_s,
               "a sample after a gap moves the RCM by at most this long at max_rate", "s", OptionLimits::above(0))
          .add_check([](const CorrectionOptions& o) { o.check(); });
  return table;
}

}  // namespace rcm
