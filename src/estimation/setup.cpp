#include "rcm/estimation/setup.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "rcm/common/options.hpp"
#include "rcm/dynamics/excitation.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm {

void SetupOptions::check() const {
  if (curve_fractions.empty() || curve_fractions.back() != 1.0)
    throw std::invalid_argument("curve_fractions must end with 1 (the whole fitted data)");
  for (std::size_t i = 0; i < curve_fractions.size(); ++i) {
    if (!(curve_fractions[i] > 0.0 && curve_fractions[i] <= 1.0))
      throw std::invalid_argument("curve_fractions must lie in (0, 1]");
    if (i > 0 && !(curve_fractions[i] > curve_fractions[i - 1]))
      throw std::invalid_argument("curve_fractions must increase");
  }
}

const OptionTable<SetupOptions>& get_option_table(OptionTag<SetupOptions>) {
  static const auto table =
      OptionTable<SetupOptions>("SetupOptions")
          .add("min_free_space_s", &SetupOptions::min_free_space_s, "free-space motion wanted", "s",
               OptionLimits::at_least(0))
          .add("workspace_half_range", &SetupOptions::workspace_half_range,
               "range around q0 the free space must reach on each joint, besides the calibration's (0: only the "
               "calibration's)",
               "rad, rad, m", OptionLimits::at_least(0))
          .add("min_reversals", &SetupOptions::min_reversals, "velocity reversals wanted per joint in the free space",
               "", OptionLimits::at_least(0))
          .add("reversal_speed_fraction", &SetupOptions::reversal_speed_fraction,
               "a reversal counts once the velocity passed this fraction of the joint's peak speed on both sides", "",
               OptionLimits::above_up_to(0, 1))
          .add("min_calibration_s", &SetupOptions::min_calibration_s, "calibration motion wanted", "s",
               OptionLimits::at_least(0))
          .add("min_calibration_pivot_rad", &SetupOptions::min_calibration_pivot_rad,
               "pivot angle about the incision the calibration must reach", "rad", OptionLimits::at_least(0))
          .add("max_outside_regime_fraction", &SetupOptions::max_outside_regime_fraction,
               "calibration samples outside the free-space model's regime beyond which it is not covered", "",
               OptionLimits::within(0, 1))
          .add("check_offset_m", &SetupOptions::check_offset_m,
               "coaxial offset at which the model's torque error is stated as an incision force", "m",
               OptionLimits::above(0))
          .add("check_pivot_rad", &SetupOptions::check_pivot_rad, "pivot (yaw from q0) of that statement", "rad",
               OptionLimits::within(0, 1.4))
          .add("max_force_error_n", &SetupOptions::max_force_error_n,
               "incision force the spread of the model's held-out error may cause there", "N", OptionLimits::above(0))
          .add("max_spike_ratio", &SetupOptions::max_spike_ratio,
               "a note when a joint's held-out RMSE exceeds this many times the spread of its bulk (rare spikes)", "",
               OptionLimits::at_least(1))
          .add("max_calibration_error_m", &SetupOptions::max_calibration_error_m,
               "offset the identified models may find on the calibration beyond its known one", "m",
               OptionLimits::above(0))
          .add("curve_fractions", &SetupOptions::curve_fractions,
               "shares of the fitted data the learning curve refits on, increasing, the last 1", "")
          .add("curve_improvement", &SetupOptions::curve_improvement,
               "more data would still help when the whole's error is below (1 - this) x the previous share's", "",
               OptionLimits::within(0, 1))
          .add_check([](const SetupOptions& o) { o.check(); });
  return table;
}

const char* to_string(SetupSeverity severity) {
  switch (severity) {
    case SetupSeverity::ok: return "ok";
    case SetupSeverity::note: return "note";
    case SetupSeverity::missing: return "missing";
  }
  return "?";
}

double compute_force_error_rms(const IncisionFrame& incision, const Eigen::Vector3d& q, double D,
                               const Eigen::Vector3d& sigma) {
  double sum = 0.0;
  for (int j = 0; j < 3; ++j) {
    Eigen::Vector3d dtau = Eigen::Vector3d::Zero();
    dtau[j] = sigma[j];
    sum += compute_incision_force(incision, q, D, dtau).f_inc_base.squaredNorm();
  }
  return std::sqrt(sum);
}

namespace {

// Samples times their period: 24000 samples at 200 Hz are 120 s of motion.
double duration_of(const Recording& r) {
  const Eigen::Index n = r.time.size();
  return n > 1 ? (r.time[n - 1] - r.time[0]) * static_cast<double>(n) / static_cast<double>(n - 1) : 0.0;
}

bool is_prismatic(const PsmModel& robot, int j) { return robot.joints()[static_cast<std::size_t>(j)].type == JointType::prismatic; }

std::string with_unit(const PsmModel& robot, int j, double v) {
  return is_prismatic(robot, j) ? fmt::format("{:.3f} m", v) : fmt::format("{:.2f} rad", v);
}

std::string range_text(const PsmModel& robot, int j, double lo, double hi) {
  return is_prismatic(robot, j) ? fmt::format("{:.3f}..{:.3f} m", lo, hi) : fmt::format("{:.2f}..{:.2f} rad", lo, hi);
}

// Where the free space should go to reach the wanted range on joint j, in the
// words of the arm: the insertion goes deeper or is withdrawn, a revolute joint
// goes toward an angle. NaN: that side is covered.
std::string direction_to(const PsmModel& robot, int j, double low, double high) {
  const std::string& name = robot.joints()[static_cast<std::size_t>(j)].name;
  std::vector<std::string> parts;
  if (is_prismatic(robot, j)) {
    if (!std::isnan(low)) parts.push_back("withdraw the instrument to " + with_unit(robot, j, low));
    if (!std::isnan(high)) parts.push_back("insert the instrument deeper, to " + with_unit(robot, j, high));
    return parts.size() == 2 ? parts[0] + " and " + parts[1] + " (" + name + ")" : parts[0] + " (" + name + ")";
  }
  if (!std::isnan(low)) parts.push_back(with_unit(robot, j, low));
  if (!std::isnan(high)) parts.push_back(with_unit(robot, j, high));
  return "move the instrument further toward " + name + " " + parts[0] + (parts.size() == 2 ? " and " + parts[1] : "");
}

// The linear fit's learning curve on the session's own free space: refitted on
// the first share of every recording's fitted part, scored on the whole fit's
// held-out end.
std::vector<SetupCurvePoint> compute_setup_curve(const std::vector<Recording>& free_space,
                                                 const FreeSpaceModelStep& step, const StudyOptions& study,
                                                 const SetupOptions& options, const TorqueModelFitter& fitter) {
  std::vector<SetupCurvePoint> curve;
  const dynamics::TimeSplit split =
      dynamics::split_in_time(free_space, study.fit.train_fraction, study.fit.validation_fraction);
  const double fitted_share = std::min(1.0, study.fit.train_fraction + study.fit.validation_fraction);
  double fitted_s = 0.0;
  for (const auto& r : free_space) fitted_s += fitted_share * duration_of(r);
  dynamics::FitOptions fit = study.fit;
  fit.verbose = false;
  for (double fraction : options.curve_fractions) {
    SetupCurvePoint point;
    point.fraction = fraction;
    point.seconds_of_data = fraction * fitted_s;
    if (fraction == 1.0) {
      point.errors = step.errors;
    } else {
      std::vector<Recording> head;
      for (const auto& r : free_space) {
        const auto n = static_cast<Eigen::Index>(std::floor(fraction * fitted_share * static_cast<double>(r.time.size())));
        if (n >= 50) head.push_back(get_recording_rows(r, 0, n));
      }
      // Too little to fit at this share: the curve starts further on.
      if (head.empty()) continue;
      try {
        const dynamics::FitResult f = fitter(step.kind, head, fit);
        point.errors = dynamics::evaluate_on_segments(*f.model, free_space, split.test);
      } catch (const InputError&) {
        continue;  // a share too short to determine the model's terms
      }
    }
    curve.push_back(std::move(point));
  }
  return curve;
}

SetupReport finish(SetupReport& r, std::chrono::steady_clock::time_point start) {
  r.ready = std::none_of(r.findings.begin(), r.findings.end(),
                         [](const SetupFinding& f) { return f.severity == SetupSeverity::missing; });
  r.compute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return std::move(r);
}

Eigen::Vector3d get_rmse3(const std::vector<dynamics::JointTorqueError>& errors) {
  Eigen::Vector3d out = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  for (const auto& e : errors)
    if (e.index >= 1 && e.index <= 3) out[e.index - 1] = e.rmse;
  return out;
}

// The spread of the errors' bulk (JointTorqueError::robust_sd), the RMSE where
// it was not computed.
Eigen::Vector3d get_robust_sd3(const std::vector<dynamics::JointTorqueError>& errors) {
  Eigen::Vector3d out = get_rmse3(errors);
  for (const auto& e : errors)
    if (e.index >= 1 && e.index <= 3 && std::isfinite(e.robust_sd)) out[e.index - 1] = e.robust_sd;
  return out;
}

}  // namespace

SetupReport run_setup(const Session& session, const StudyOptions& study, const SetupOptions& options,
                      const TorqueModelFitter& fitter) {
  const auto start = std::chrono::steady_clock::now();
  check_options(study, "StudyOptions");
  check_options(options, "SetupOptions");
  SetupReport r;
  r.robot = session.robot;
  r.check_offset_m = options.check_offset_m;
  r.check_pivot_rad = options.check_pivot_rad;
  auto add = [&r](std::string check, SetupSeverity severity, std::string message) {
    r.findings.push_back({std::move(check), severity, std::move(message)});
  };
  const PsmModel robot = load_robot_model(session.robot, session.manifest.string() + ": robot");
  const RecordingReadOptions read = get_read_options(session, study.read);
  std::vector<Recording> free_space;
  for (const auto& p : session.free_space) free_space.push_back(load_recording(p, read));
  for (const auto& f : free_space) r.free_space_s += duration_of(f);
  if (session.baseline) r.baseline_s = duration_of(load_recording(*session.baseline, read));
  std::optional<Recording> calibration;
  if (session.calibration) {
    calibration = load_recording(session.calibration->recording, read);
    r.calibration_s = duration_of(*calibration);
  }
  const IncisionFrame incision = make_incision_frame(session.q0);

  // The free space's duration, range, speeds and reversals.
  if (r.free_space_s < options.min_free_space_s)
    add("free_space.duration", SetupSeverity::missing,
        fmt::format("free space: {:.0f} s of motion, at least {:.0f} s wanted: record {:.0f} s more", r.free_space_s,
                    options.min_free_space_s, std::ceil(options.min_free_space_s - r.free_space_s)));
  else
    add("free_space.duration", SetupSeverity::ok, fmt::format("free space: {:.0f} s of motion", r.free_space_s));
  const double position_margin = dynamics::RegimeCheckOptions{}.position_margin;
  for (int j = 0; j < 3; ++j) {
    SetupJointCoverage c;
    c.name = robot.joints()[static_cast<std::size_t>(j)].name;
    c.position_min = std::numeric_limits<double>::infinity();
    c.position_max = -c.position_min;
    for (const auto& f : free_space) {
      c.position_min = std::min(c.position_min, f.position.col(j).minCoeff());
      c.position_max = std::max(c.position_max, f.position.col(j).maxCoeff());
      c.speed_max = std::max(c.speed_max, f.velocity.col(j).cwiseAbs().maxCoeff());
    }
    for (const auto& f : free_space)
      c.reversals += dynamics::count_velocity_reversals(f.velocity.col(j), options.reversal_speed_fraction).front();
    c.wanted_min = c.wanted_max = session.q0[j];
    if (options.workspace_half_range[j] > 0) {
      c.wanted_min = session.q0[j] - options.workspace_half_range[j];
      c.wanted_max = session.q0[j] + options.workspace_half_range[j];
    }
    if (calibration) {
      c.wanted_min = std::min(c.wanted_min, calibration->position.col(j).minCoeff());
      c.wanted_max = std::max(c.wanted_max, calibration->position.col(j).maxCoeff());
      c.calibration_speed_max = calibration->velocity.col(j).cwiseAbs().maxCoeff();
    }
    // The live flag forgives this much beyond the range: so does the check.
    const double margin = position_margin * (c.position_max - c.position_min);
    const std::string covered =
        fmt::format("{}: free space covers {}, wanted {}", c.name, range_text(robot, j, c.position_min, c.position_max),
                    range_text(robot, j, c.wanted_min, c.wanted_max));
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double low = c.wanted_min < c.position_min - margin ? c.wanted_min : nan;
    const double high = c.wanted_max > c.position_max + margin ? c.wanted_max : nan;
    if (std::isnan(low) && std::isnan(high))
      add("free_space.position." + c.name, SetupSeverity::ok, covered);
    else
      add("free_space.position." + c.name, SetupSeverity::missing,
          covered + ": " + direction_to(robot, j, low, high));
    if (c.reversals < options.min_reversals)
      add("free_space.reversals." + c.name, SetupSeverity::missing,
          fmt::format("{}: {} velocity reversals in free space, at least {} wanted: move it back and forth more "
                      "often (friction is identified where the motion reverses)",
                      c.name, c.reversals, options.min_reversals));
    else
      add("free_space.reversals." + c.name, SetupSeverity::ok,
          fmt::format("{}: {} velocity reversals in free space", c.name, c.reversals));
    r.joints.push_back(c);
  }

  // The calibration.
  if (!calibration) {
    add("calibration", SetupSeverity::missing,
        "calibration: none in the session; record teleoperation at a known coaxial offset (paper step 2)");
  } else {
    r.has_calibration = true;
    if (r.calibration_s < options.min_calibration_s)
      add("calibration.duration", SetupSeverity::missing,
          fmt::format("calibration: {:.0f} s of motion, at least {:.0f} s wanted: record {:.0f} s more",
                      r.calibration_s, options.min_calibration_s,
                      std::ceil(options.min_calibration_s - r.calibration_s)));
    else
      add("calibration.duration", SetupSeverity::ok, fmt::format("calibration: {:.0f} s of motion", r.calibration_s));
    for (Eigen::Index i = 0; i < calibration->position.rows(); ++i)
      r.calibration_pivot_max_rad = std::max(
          r.calibration_pivot_max_rad,
          compute_pivot_angle(incision, calibration->position.row(i).head<3>().transpose()));
    const double pivot_deg = r.calibration_pivot_max_rad * 180.0 / M_PI;
    if (r.calibration_pivot_max_rad < options.min_calibration_pivot_rad)
      add("calibration.pivot", SetupSeverity::missing,
          fmt::format("calibration: pivots {:.0f} deg about the incision at most, at least {:.0f} deg wanted: pivot "
                      "the instrument further (the tissue law is identified over the pivots it sees)",
                      pivot_deg, options.min_calibration_pivot_rad * 180.0 / M_PI));
    else
      add("calibration.pivot", SetupSeverity::ok,
          fmt::format("calibration: pivots up to {:.0f} deg about the incision", pivot_deg));
  }

  // The model, and its error as a force at the incision.
  try {
    r.free_space = fit_free_space_step(free_space, study, fitter);
  } catch (const InputError& e) {
    // Data too poor to fit is a finding like the others: the checks above say why.
    add("model.fit", SetupSeverity::missing, std::string("free-space model: not fitted: ") + e.what());
    return finish(r, start);
  }
  // The force error counts the spread of the held-out error's bulk: rare
  // spikes (a servo setpoint a period late, then two at once; a bump) can hold
  // most of the RMSE, and the estimate, which averages over seconds, hardly
  // feels them. They are a note.
  const Eigen::Vector3d rmse = get_rmse3(r.free_space.errors);
  const Eigen::Vector3d sigma = get_robust_sd3(r.free_space.errors);
  const Eigen::Vector3d q_check = session.q0 + Eigen::Vector3d(options.check_pivot_rad, 0.0, 0.0);
  r.force_error_n = compute_force_error_rms(incision, q_check, options.check_offset_m, sigma);
  const std::string model_error = fmt::format(
      "free-space model ({}): held-out error {:.3f} N m / {:.3f} N m / {:.3f} N (the spread of its bulk), {:.1f} N at "
      "the incision at D = {:.0f} mm, theta = {:.0f} deg",
      dynamics::to_string(r.free_space.kind), sigma[0], sigma[1], sigma[2], r.force_error_n,
      options.check_offset_m * 1e3, options.check_pivot_rad * 180.0 / M_PI);
  int spiky = -1;
  for (int j = 0; j < 3; ++j)
    if (rmse[j] > options.max_spike_ratio * sigma[j] && (spiky < 0 || rmse[j] / sigma[j] > rmse[spiky] / sigma[spiky]))
      spiky = j;
  if (spiky >= 0)
    add("model.spikes", SetupSeverity::note,
        fmt::format("{}: the held-out error's RMS is {:.1f} times the spread of its bulk: rare torque spikes (a servo "
                    "stream that missed the arm's periods, a bump) hold most of it; the force error leaves them "
                    "out",
                    r.joints[static_cast<std::size_t>(spiky)].name, rmse[spiky] / sigma[spiky]));
  if (!(r.force_error_n <= options.max_force_error_n))
    add("model.force_error", SetupSeverity::missing,
        model_error + fmt::format("; at most {:.1f} N wanted: the model does not explain this arm's free space well "
                                  "enough (record it along an excitation trajectory, `rcm excite`, and check the "
                                  "instrument and payload)",
                                  options.max_force_error_n));
  else
    add("model.force_error", SetupSeverity::ok, model_error);
  if (!study.model_file && r.free_space.kind == dynamics::TorqueModelKind::linear) {
    r.curve = compute_setup_curve(free_space, r.free_space, study, options, fitter);
    if (r.curve.size() >= 2) {
      const Eigen::Vector3d before = get_rmse3(r.curve[r.curve.size() - 2].errors);
      const Eigen::Vector3d after = get_rmse3(r.curve.back().errors);
      int worst = 0;
      double worst_gain = 0.0;
      for (int j = 0; j < 3; ++j) {
        const double gain = 1.0 - after[j] / before[j];
        if (gain > worst_gain) worst_gain = gain, worst = j;
      }
      const std::string shares = fmt::format("from {:.0f} s to {:.0f} s of fitted data",
                                             r.curve[r.curve.size() - 2].seconds_of_data, r.curve.back().seconds_of_data);
      if (worst_gain > options.curve_improvement)
        add("model.learning_curve", SetupSeverity::note,
            fmt::format("the model still improves with data: its held-out error on {} fell by {:.0f} % {}: more "
                        "free-space motion would lower it",
                        r.joints[static_cast<std::size_t>(worst)].name, 100.0 * worst_gain, shares));
      else
        add("model.learning_curve", SetupSeverity::ok,
            fmt::format("the model's held-out error changed by less than {:.0f} % {}: more of the same motion would "
                        "not lower it",
                        100.0 * options.curve_improvement, shares));
    }
  }

  // What needs the model on the calibration.
  if (calibration) {
    dynamics::TrainingRegime regime = r.free_space.model->info().regime;
    if (regime.empty()) regime = dynamics::compute_training_regime(free_space, 3);
    r.calibration_regime = dynamics::compute_regime_summary(dynamics::RegimeMonitor(regime), *calibration);
    const std::string regime_text = "calibration: " + r.calibration_regime.to_text();
    if (r.calibration_regime.get_fraction() > options.max_outside_regime_fraction)
      add("calibration.regime", SetupSeverity::missing,
          regime_text + fmt::format("; at most {:.0f} % wanted: record free space over the positions and speeds of "
                                    "the calibration",
                                    100.0 * options.max_outside_regime_fraction));
    else
      add("calibration.regime", r.calibration_regime.flagged > 0 ? SetupSeverity::note : SetupSeverity::ok,
          regime_text);
    std::optional<MonitorSetup> monitor;
    try {
      monitor = prepare_monitor(session, study, r.free_space, *calibration);
    } catch (const InputError& e) {
      add("calibration.tissue", SetupSeverity::missing, std::string("tissue model: not identified: ") + e.what());
      return finish(r, start);
    }
    r.tissue = monitor->tissue;
    r.calibration_error_m = monitor->tissue.calibration_bias_m.norm();
    const std::string self_check = fmt::format(
        "calibration self-check: the identified models place the known offset (D* = {:.1f} mm) {:.2f} mm off",
        session.calibration->coaxial_offset_m * 1e3, *r.calibration_error_m * 1e3);
    if (*r.calibration_error_m > options.max_calibration_error_m)
      add("calibration.self_check", SetupSeverity::missing,
          self_check + fmt::format("; at most {:.1f} mm wanted: the free-space model or the tissue law does not fit "
                                   "this calibration",
                                   options.max_calibration_error_m * 1e3));
    else
      add("calibration.self_check", SetupSeverity::ok, self_check);
  }

  return finish(r, start);
}

}  // namespace rcm
