// Excitation trajectories (excitation.hpp): the series, its limits, and the
// design by Ceres' GradientProblemSolver.
#include "rcm/dynamics/excitation.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/common/options.hpp"

namespace rcm::dynamics {

namespace {
constexpr double kTwoPi = 6.283185307179586;
// Penalty weights: a squared limit excess (in units of the limit, summed over
// the objective's samples) against log cond, which moves by a few units
// between a poor and a good motion; and a missing reversal per joint, squared,
// strong enough that the L-BFGS steps find reversals rather than trade them.
constexpr double kLimitWeight = 100.0;
constexpr double kReversalWeight = 10.0;
// And a missing share of the room on one side of q0, squared.
constexpr double kCoverageWeight = 10.0;
// Speed (share of velocity_max) over which the soft reversal count's tanh turns.
constexpr double kReversalSpeed = 0.05;
// Central-difference step of the gradient, in units of velocity_max.
constexpr double kGradientStep = 1e-5;
// The random start uses this share of the limits.
constexpr double kStartShare = 0.8;
}  // namespace

void ExcitationOptions::check() const {
  auto require = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("ExcitationOptions: ") + what);
  };
  require(std::isfinite(duration_s) && duration_s > 0.0, "duration_s must be a positive number of seconds");
  require(std::isfinite(rate_hz) && rate_hz > 0.0, "rate_hz must be a positive number");
  require(duration_s * rate_hz >= 2.0, "duration_s x rate_hz must give at least 3 samples");
  require(duration_s * rate_hz <= 1e8, "duration_s x rate_hz must be at most 1e8 samples");
  require(std::isfinite(period_s) && period_s > 0.0, "period_s must be a positive number of seconds");
  require(harmonics >= 2 && harmonics <= 50, "harmonics must be in 2..50 (one harmonic cannot start and end at rest)");
  require(q0.allFinite(), "q0 must be finite");
  require(position_margin.allFinite() && (position_margin.array() >= 0.0).all(), "position_margin must be >= 0");
  require(velocity_max.allFinite() && (velocity_max.array() > 0.0).all(), "velocity_max must be > 0");
  require(acceleration_max.allFinite() && (acceleration_max.array() > 0.0).all(), "acceleration_max must be > 0");
  require(min_reversals >= 0, "min_reversals must be >= 0");
  require(position_coverage >= 0.0 && position_coverage <= 1.0, "position_coverage must be in [0, 1]");
  require(speed_coverage >= 0.0 && speed_coverage <= 1.0, "speed_coverage must be in [0, 1]");
  require(samples_per_period >= 8 * harmonics, "samples_per_period must be at least 8 x harmonics");
  require(max_iterations >= 0, "max_iterations must be >= 0");
}

const OptionTable<ExcitationOptions>& get_option_table(OptionTag<ExcitationOptions>) {
  using O = ExcitationOptions;
  static const auto table =
      OptionTable<O>("ExcitationOptions")
          .add("duration_s", &O::duration_s, "whole trajectory, from rest at q0 to rest at q0", "s",
               OptionLimits::above(0))
          .add("rate_hz", &O::rate_hz, "rate of the samples written", "Hz", OptionLimits::above(0))
          .add("period_s", &O::period_s,
               "wanted fundamental period; the series repeats a whole number of times over the duration", "s",
               OptionLimits::above(0))
          .add("harmonics", &O::harmonics, "harmonics of the fundamental per joint", "", OptionLimits::within(2, 50))
          .add("seed", &O::seed, "seed of the random start")
          .add("q0", &O::q0, "start and end configuration, strictly inside the limits less the margin",
               "rad, rad, m")
          .add("position_margin", &O::position_margin,
               "kept free inside the robot description's joint limits at each end", "rad, rad, m",
               OptionLimits::at_least(0))
          .add("velocity_max", &O::velocity_max, "largest joint speed (lower it for a first run on an arm)", "rad/s, rad/s, m/s",
               OptionLimits::above(0))
          .add("acceleration_max", &O::acceleration_max, "largest joint acceleration (lower it for a first run on an arm)",
               "rad/s^2, rad/s^2, m/s^2", OptionLimits::above(0))
          .add("min_reversals", &O::min_reversals, "velocity reversals wanted per joint and period", "",
               OptionLimits::at_least(0))
          .add("position_coverage", &O::position_coverage,
               "share of the room on each side of q0 every joint is asked to reach", "", OptionLimits::within(0, 1))
          .add("speed_coverage", &O::speed_coverage,
               "share of the speed limit (both directions) and the acceleration limit every joint is asked to reach",
               "", OptionLimits::within(0, 1))
          .add("samples_per_period", &O::samples_per_period, "samples of a period the objective is evaluated on",
               "", OptionLimits::at_least(16))
          .add("max_iterations", &O::max_iterations, "L-BFGS iterations (0: the random start as it is)", "",
               OptionLimits::at_least(0))
          .add_check([](const O& o) { o.check(); });
  return table;
}

ExcitationLimits get_excitation_limits(const PsmModel& robot, const ExcitationOptions& options) {
  ExcitationLimits limits;
  for (int j = 0; j < 3; ++j) {
    const DhJoint& joint = robot.joints()[static_cast<std::size_t>(j)];
    limits.position_min[j] = joint.q_min + options.position_margin[j];
    limits.position_max[j] = joint.q_max - options.position_margin[j];
    if (!(limits.position_min[j] < limits.position_max[j]))
      throw InputError(InputLocation::plain("ExcitationOptions", fmt::format("position_margin[{}]", j)),
                       fmt::format("leaves nothing of the joint range [{}, {}] of {}", joint.q_min, joint.q_max,
                                   joint.name));
  }
  limits.velocity_max = options.velocity_max;
  limits.acceleration_max = options.acceleration_max;
  return limits;
}

void check_excitation_start(const ExcitationLimits& limits, const Eigen::Vector3d& q0, const InputLocation& where) {
  for (int j = 0; j < 3; ++j)
    if (!(q0[j] > limits.position_min[j] && q0[j] < limits.position_max[j])) {
      InputLocation at = where;
      at.field += fmt::format("[{}]", j);
      throw InputError(at, fmt::format("{} is not inside the joint's limits less the margin, ({}, {})", q0[j],
                                       limits.position_min[j], limits.position_max[j]));
    }
}

// --- the series ---------------------------------------------------------------

ExcitationSeries::ExcitationSeries(const Eigen::Vector3d& q0, double period_s, Eigen::Matrix3Xd a,
                                   Eigen::Matrix3Xd b)
    : q0_(q0), period_s_(period_s), omega_(kTwoPi / period_s), a_(std::move(a)), b_(std::move(b)) {
  if (a_.cols() != b_.cols() || a_.cols() < 1 || !(period_s > 0))
    throw std::invalid_argument("ExcitationSeries: a and b need the same harmonics, period > 0");
  // q(0) = q0: the constant cancels the cosines at t = 0.
  c_.setZero();
  for (int k = 1; k <= harmonics(); ++k) c_ += b_.col(k - 1) / (omega_ * k);
}

ExcitationSeries ExcitationSeries::from_free_coefficients(const Eigen::Vector3d& q0, double period_s, int harmonics,
                                                          const Eigen::VectorXd& x) {
  const int H = harmonics, free = H - 1;
  if (H < 2 || x.size() != count_free_coefficients(H))
    throw std::invalid_argument("ExcitationSeries::from_free_coefficients: 2 (H - 1) values per joint, H >= 2");
  Eigen::Matrix3Xd a(3, H), b(3, H);
  for (int j = 0; j < 3; ++j) {
    const Eigen::Index at = 2 * free * j;
    a.row(j).tail(free) = x.segment(at, free).transpose();
    b.row(j).tail(free) = x.segment(at + free, free).transpose();
    // qd(0) = sum_k a_k = 0 and qdd(0) = w sum_k k b_k = 0.
    a(j, 0) = -a.row(j).tail(free).sum();
    double kb = 0.0;
    for (int k = 2; k <= H; ++k) kb += k * b(j, k - 1);
    b(j, 0) = -kb;
  }
  return ExcitationSeries(q0, period_s, std::move(a), std::move(b));
}

void ExcitationSeries::compute_state(double t, Eigen::Vector3d& q, Eigen::Vector3d& qd, Eigen::Vector3d& qdd) const {
  q = q0_ + c_;
  qd.setZero();
  qdd.setZero();
  for (int k = 1; k <= harmonics(); ++k) {
    const double wk = omega_ * k, s = std::sin(wk * t), c = std::cos(wk * t);
    for (int j = 0; j < 3; ++j) {
      const double a = a_(j, k - 1), b = b_(j, k - 1);
      q[j] += (a * s - b * c) / wk;
      qd[j] += a * c + b * s;
      qdd[j] += wk * (b * c - a * s);
    }
  }
}

ExcitationSeries ExcitationSeries::get_scaled(const Eigen::Vector3d& s) const {
  return ExcitationSeries(q0_, period_s_, Eigen::Matrix3Xd(s.asDiagonal() * a_), Eigen::Matrix3Xd(s.asDiagonal() * b_));
}

void compute_excitation_samples(const ExcitationSeries& series, double duration_s, double rate_hz,
                                ExcitationTrajectory& out) {
  const Eigen::Index n = static_cast<Eigen::Index>(std::llround(duration_s * rate_hz)) + 1;
  out.time.resize(n);
  out.position.resize(n, 3);
  out.velocity.resize(n, 3);
  out.acceleration.resize(n, 3);
  Eigen::Vector3d q, qd, qdd;
  for (Eigen::Index i = 0; i < n; ++i) {
    out.time[i] = static_cast<double>(i) / rate_hz;
    series.compute_state(out.time[i], q, qd, qdd);
    out.position.row(i) = q.transpose();
    out.velocity.row(i) = qd.transpose();
    out.acceleration.row(i) = qdd.transpose();
  }
}

namespace {

// Per joint, the largest share of its limits a state uses: position about q0
// toward the bound it moves to, speed, acceleration.
Eigen::Vector3d compute_limit_share(const ExcitationLimits& L, const Eigen::Vector3d& q0, const Eigen::Vector3d& q,
                                    const Eigen::Vector3d& qd, const Eigen::Vector3d& qdd) {
  Eigen::Vector3d share;
  for (int j = 0; j < 3; ++j) {
    const double d = q[j] - q0[j];
    const double p = d >= 0 ? d / (L.position_max[j] - q0[j]) : -d / (q0[j] - L.position_min[j]);
    share[j] = std::max({p, std::abs(qd[j]) / L.velocity_max[j], std::abs(qdd[j]) / L.acceleration_max[j]});
  }
  return share;
}

Eigen::Vector3d compute_limit_share(const ExcitationLimits& L, const Eigen::Vector3d& q0,
                                    const ExcitationTrajectory& samples) {
  Eigen::Vector3d share = Eigen::Vector3d::Zero();
  for (Eigen::Index i = 0; i < samples.time.size(); ++i)
    share = share.cwiseMax(compute_limit_share(L, q0, samples.position.row(i).transpose(),
                                               samples.velocity.row(i).transpose(),
                                               samples.acceleration.row(i).transpose()));
  return share;
}

// log cond + penalties over one period, on the free coefficients in units of
// each joint's velocity_max.
class ExcitationObjective {
 public:
  ExcitationObjective(const ExcitationLimits& limits, const ExcitationOptions& o, double period_s)
      : limits_(limits),
        q0_(o.q0),
        period_s_(period_s),
        harmonics_(o.harmonics),
        samples_(o.samples_per_period),
        min_reversals_(o.min_reversals),
        coverage_(o.position_coverage),
        speed_coverage_(o.speed_coverage),
        conditioning_(get_excitation_dahl_displacement(limits)),
        unit_(ExcitationSeries::count_free_coefficients(o.harmonics)) {
    const int per_joint = 2 * (o.harmonics - 1);
    for (int j = 0; j < 3; ++j) unit_.segment(per_joint * j, per_joint).setConstant(o.velocity_max[j]);
  }

  int size() const { return static_cast<int>(unit_.size()); }

  ExcitationSeries get_series(const double* y) const {
    const Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(y, size()).cwiseProduct(unit_);
    return ExcitationSeries::from_free_coefficients(q0_, period_s_, harmonics_, x);
  }

  // The largest share of the limits over the objective's samples, per joint.
  Eigen::Vector3d get_limit_share(const ExcitationSeries& series) const {
    Eigen::Vector3d share = Eigen::Vector3d::Zero(), q, qd, qdd;
    for (int i = 0; i < samples_; ++i) {
      series.compute_state(period_s_ * i / samples_, q, qd, qdd);
      share = share.cwiseMax(compute_limit_share(limits_, q0_, q, qd, qdd));
    }
    return share;
  }

  double evaluate(const double* y) {
    const ExcitationSeries series = get_series(y);
    Eigen::Vector3d q, qd, qdd;
    conditioning_.reset();
    // The Dahl states as they are after a whole period: periodic from then on.
    for (int i = 0; i < samples_; ++i) {
      series.compute_state(period_s_ * i / samples_, q, qd, qdd);
      conditioning_.compute_dahl_step(q);
    }
    double penalty = 0.0;
    Eigen::Vector3d reversals = Eigen::Vector3d::Zero(), first_sign = Eigen::Vector3d::Zero(),
                    last_sign = Eigen::Vector3d::Zero(), reach_up = Eigen::Vector3d::Zero(),
                    reach_down = Eigen::Vector3d::Zero(), speed_up = Eigen::Vector3d::Zero(),
                    speed_down = Eigen::Vector3d::Zero(), acceleration_reach = Eigen::Vector3d::Zero();
    auto excess = [](double share) { return share > 1.0 ? (share - 1.0) * (share - 1.0) : 0.0; };
    for (int i = 0; i < samples_; ++i) {
      series.compute_state(period_s_ * i / samples_, q, qd, qdd);
      conditioning_.add_sample(q, qd, qdd);
      for (int j = 0; j < 3; ++j) {
        const double d = q[j] - q0_[j];
        const double up = d / (limits_.position_max[j] - q0_[j]), down = -d / (q0_[j] - limits_.position_min[j]);
        penalty += excess(d >= 0 ? up : down);
        reach_up[j] = std::max(reach_up[j], up);
        reach_down[j] = std::max(reach_down[j], down);
        const double speed = qd[j] / limits_.velocity_max[j], acceleration = qdd[j] / limits_.acceleration_max[j];
        penalty += excess(std::abs(speed));
        penalty += excess(std::abs(acceleration));
        speed_up[j] = std::max(speed_up[j], speed);
        speed_down[j] = std::max(speed_down[j], -speed);
        acceleration_reach[j] = std::max(acceleration_reach[j], std::abs(acceleration));
        // A smooth count of sign changes: half the total variation of a
        // smooth sign of qd (a reversal from +1 to -1 counts 1). The first
        // sample is left out: there the velocity touches 0 by construction
        // without changing sign, which the count would take for a reversal.
        if (i == 0) continue;
        const double sign = std::tanh(qd[j] / (kReversalSpeed * limits_.velocity_max[j]));
        if (i == 1)
          first_sign[j] = sign;
        else
          reversals[j] += 0.5 * std::abs(sign - last_sign[j]);
        last_sign[j] = sign;
      }
    }
    double missing = 0.0, uncovered = 0.0;
    for (int j = 0; j < 3; ++j) {
      // The positions a later motion will visit lie on both sides of q0.
      const double u = std::max(0.0, coverage_ - reach_up[j]), v = std::max(0.0, coverage_ - reach_down[j]);
      uncovered += u * u + v * v;
      // And the speeds: the regime's velocity range is signed, its acceleration
      // a magnitude.
      for (const double reach : {speed_up[j], speed_down[j], acceleration_reach[j]}) {
        const double w = std::max(0.0, speed_coverage_ - reach);
        uncovered += w * w;
      }
      reversals[j] += 0.5 * std::abs(first_sign[j] - last_sign[j]);  // the period wraps around
      const double m = std::max(0.0, min_reversals_ - reversals[j]);
      missing += m * m;
    }
    return conditioning_.get_log_condition_number() + kLimitWeight * penalty + kReversalWeight * missing +
           kCoverageWeight * uncovered;
  }

 private:
  ExcitationLimits limits_;
  Eigen::Vector3d q0_;
  double period_s_;
  int harmonics_, samples_;
  double min_reversals_, coverage_, speed_coverage_;
  RegressorConditioning conditioning_;
  Eigen::VectorXd unit_;
};

// The objective with its gradient by central differences (the regressor
// functions give values, not derivatives).
class ExcitationCost final : public ceres::FirstOrderFunction {
 public:
  explicit ExcitationCost(ExcitationObjective& objective) : objective_(objective) {}
  bool Evaluate(const double* y, double* cost, double* gradient) const override {
    *cost = objective_.evaluate(y);
    if (!std::isfinite(*cost)) return false;
    if (!gradient) return true;
    std::vector<double> p(y, y + NumParameters());
    for (int i = 0; i < NumParameters(); ++i) {
      const double h = kGradientStep * std::max(1.0, std::abs(y[i]));
      p[i] = y[i] + h;
      const double up = objective_.evaluate(p.data());
      p[i] = y[i] - h;
      const double down = objective_.evaluate(p.data());
      p[i] = y[i];
      gradient[i] = (up - down) / (2.0 * h);
      if (!std::isfinite(gradient[i])) return false;
    }
    return true;
  }
  int NumParameters() const override { return objective_.size(); }

 private:
  ExcitationObjective& objective_;
};

// Joint j's motion scaled so that its largest share of the limits on `samples` is at most 1.
ExcitationSeries scale_into_limits(const ExcitationSeries& series, const ExcitationLimits& limits,
                                   const ExcitationTrajectory& samples, Eigen::Vector3d& scale) {
  const Eigen::Vector3d share = compute_limit_share(limits, series.q0(), samples);
  for (int j = 0; j < 3; ++j) scale[j] = share[j] > 1.0 ? (1.0 - 1e-12) / share[j] : 1.0;
  return (scale.array() < 1.0).any() ? series.get_scaled(scale) : series;
}

}  // namespace

std::string ExcitationSummary::brief_report() const {
  return fmt::format("{}, {} iterations, condition number {:.4g} -> {:.4g}, limits {}, {} period(s) of {:.4g} s",
                     termination, iterations, initial_condition_number, condition_number,
                     limits_satisfied ? "satisfied" : "NOT satisfied", periods, period_s);
}

ExcitationTrajectory design_excitation(const PsmModel& robot, const ExcitationOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  o.check();
  const ExcitationLimits limits = get_excitation_limits(robot, o);
  check_excitation_start(limits, o.q0, InputLocation::plain("ExcitationOptions", "q0"));
  // A whole number of periods, so that the last sample is at rest at q0.
  const double duration = static_cast<double>(std::llround(o.duration_s * o.rate_hz)) / o.rate_hz;
  const int periods = static_cast<int>(std::max<long long>(1, std::llround(duration / o.period_s)));
  const double period = duration / periods;
  ExcitationObjective objective(limits, o, period);

  // The random start: coefficients falling as 1/k (most of the motion in the
  // low harmonics), the bits of mt19937_64 read directly so that the start is
  // the same with every standard library.
  std::mt19937_64 rng(o.seed);
  auto unit = [&rng]() { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  const int per_joint = 2 * (o.harmonics - 1);
  std::vector<double> y(static_cast<std::size_t>(objective.size()));
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < per_joint; ++i) {
      const int k = 2 + i % (o.harmonics - 1);
      y[static_cast<std::size_t>(per_joint * j + i)] = (2.0 * unit() - 1.0) / k;
    }
  {
    const Eigen::Vector3d share = objective.get_limit_share(objective.get_series(y.data()));
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < per_joint; ++i)
        y[static_cast<std::size_t>(per_joint * j + i)] *= share[j] > 0 ? kStartShare / share[j] : 1.0;
  }

  ExcitationTrajectory out;
  out.limits = limits;
  ExcitationSummary& summary = out.summary;
  summary.periods = periods;
  summary.period_s = period;
  const Eigen::Vector3d dahl = get_excitation_dahl_displacement(limits);
  {
    Eigen::Vector3d scale;
    ExcitationTrajectory initial;
    compute_excitation_samples(objective.get_series(y.data()), duration, o.rate_hz, initial);
    const ExcitationSeries start_series = scale_into_limits(objective.get_series(y.data()), limits, initial, scale);
    if ((scale.array() < 1.0).any()) compute_excitation_samples(start_series, duration, o.rate_hz, initial);
    summary.initial_condition_number =
        compute_regressor_condition_number(initial.position, initial.velocity, initial.acceleration, dahl);
  }

  if (o.max_iterations > 0) {
    ceres::GradientProblem problem(new ExcitationCost(objective));
    ceres::GradientProblemSolver::Options so;
    so.line_search_direction_type = ceres::LBFGS;
    so.max_num_iterations = o.max_iterations;
    so.logging_type = ceres::SILENT;
    so.function_tolerance = 1e-8;
    so.gradient_tolerance = 1e-8;
    ceres::GradientProblemSolver::Summary s;
    ceres::Solve(so, problem, y.data(), &s);
    summary.converged = s.termination_type == ceres::CONVERGENCE;
    summary.termination = ceres::TerminationTypeToString(s.termination_type);
    summary.message = s.message;
    summary.iterations = std::max(0, static_cast<int>(s.iterations.size()) - 1);
  } else {
    summary.termination = "NO_OPTIMISATION";
    summary.message = "max_iterations 0: the random start";
  }

  // The optimum into the limits on the samples written, joint by joint.
  compute_excitation_samples(objective.get_series(y.data()), duration, o.rate_hz, out);
  out.series = scale_into_limits(objective.get_series(y.data()), limits, out, summary.limit_scale);
  if ((summary.limit_scale.array() < 1.0).any()) compute_excitation_samples(out.series, duration, o.rate_hz, out);
  summary.limits_satisfied = (compute_limit_share(limits, o.q0, out).array() <= 1.0).all();
  summary.condition_number = compute_regressor_condition_number(out.position, out.velocity, out.acceleration, dahl);
  out.reversals = count_velocity_reversals(out.velocity);
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace rcm::dynamics
