#include "rcm/sim/trajectory.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/io/joint_trajectory.hpp"

namespace rcm::sim {

namespace {

constexpr double kTwoPi = 6.283185307179586;
// The start-up term that makes u(0) = 0 decays with this time constant (s of warped time).
constexpr double kStartDecay = 3.0;

double smoothstep(double x) { return x * x * (3.0 - 2.0 * x); }
double smoothstep_dot(double x) { return 6.0 * x * (1.0 - x); }
double smoothstep_int(double x) { return x * x * x - 0.5 * x * x * x * x; }  // int_0^x

}  // namespace

TeleopPath::TeleopPath(const TrajectoryParams& p, const Eigen::Vector3d& q0, std::uint64_t seed,
                       double duration_s)
    : q0_(q0), amplitude_(p.amplitude), segment_s_(p.segment_s), blend_s_(p.blend_s) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double log_min = std::log(p.min_frequency_hz), log_max = std::log(p.max_frequency_hz);
  // Warped time never exceeds real time, so duration / segment_s (+ the margin
  // the pauses use) bounds the segments needed.
  const std::size_t count = 1 + static_cast<std::size_t>(std::ceil((duration_s + 10.0) / segment_s_));
  segments_.resize(count);
  for (Harmonics& harmonics : segments_) {
    for (int j = 0; j < 3; ++j) {
      auto& h = harmonics[static_cast<std::size_t>(j)];
      h.resize(static_cast<std::size_t>(p.harmonics));
      double power = 0.0;
      for (auto& k : h) {
        const double f = std::exp(log_min + (log_max - log_min) * unit(rng));
        // Pink-ish spectrum: slower components carry more amplitude, as in hand motion.
        const double a = (0.5 + 0.5 * unit(rng)) / std::sqrt(f / p.min_frequency_hz);
        k = {a, kTwoPi * f, kTwoPi * unit(rng)};
        power += 0.5 * a * a;
      }
      // Unit RMS of u: tanh then uses most of the range without pinning at its ends.
      const double scale = 1.0 / std::sqrt(power);
      for (auto& k : h) k[0] *= scale;
    }
  }
  // Pauses: the time warp's rate falls smoothly to 0 and back. The first window
  // ends at t = 0.6 s, so the path starts at rest.
  pauses_.push_back({-1.2, 0.6, 0.6, 0.0});
  if (p.pause_fraction > 0.0) {
    const double mean_pause = 0.5 * (p.pause_min_s + p.pause_max_s);
    const double mean_move = mean_pause * (1.0 - p.pause_fraction) / p.pause_fraction;
    std::exponential_distribution<double> move_len(1.0 / mean_move);
    double t = 0.6;
    while (t < duration_s + 10.0) {
      const double a = t + std::max(0.8, move_len(rng));
      const double len = p.pause_min_s + (p.pause_max_s - p.pause_min_s) * unit(rng);
      const double r = std::min(0.35, len / 3.0);
      pauses_.push_back({a, a + len, r, 0.0});
      t = a + len;
    }
  }
  double lost = 0.0;
  for (auto& w : pauses_) {
    w.lost_before = lost;
    lost += w.b - w.a - w.r;
  }
}

double TeleopPath::warp(double t, double* rate, double* rate_dot) const {
  // Cumulative time lost in pauses up to t, L(t); tau(t) = t - (L(t) - L(0)).
  auto lost_until = [this](double time, double* bump, double* bump_dot) {
    *bump = 0.0;
    *bump_dot = 0.0;
    auto it = std::upper_bound(pauses_.begin(), pauses_.end(), time,
                               [](double v, const Pause& w) { return v < w.a; });
    if (it == pauses_.begin()) return 0.0;
    const Pause& w = *(it - 1);
    if (time >= w.b) return w.lost_before + (w.b - w.a - w.r);
    const double e = time - w.a;
    if (e < w.r) {
      const double x = e / w.r;
      *bump = smoothstep(x);
      *bump_dot = smoothstep_dot(x) / w.r;
      return w.lost_before + w.r * smoothstep_int(x);
    }
    const double fall_start = w.b - w.r;
    if (time < fall_start) {
      *bump = 1.0;
      return w.lost_before + 0.5 * w.r + (e - w.r);
    }
    const double x = (time - fall_start) / w.r;
    *bump = 1.0 - smoothstep(x);
    *bump_dot = -smoothstep_dot(x) / w.r;
    return w.lost_before + 0.5 * w.r + (fall_start - w.a - w.r) +
           w.r * (x - smoothstep_int(x));
  };
  double b0, bd0, b, bd;
  const double l0 = lost_until(0.0, &b0, &bd0);
  const double l = lost_until(t, &b, &bd);
  *rate = 1.0 - b;
  *rate_dot = -bd;
  return t - (l - l0);
}

void TeleopPath::evaluate_segment(std::size_t segment, int joint, double tau, double decay, double* u,
                                  double* du, double* ddu) const {
  *u = *du = *ddu = 0.0;
  for (const auto& k : segments_[segment][static_cast<std::size_t>(joint)]) {
    const double a = k[0], w = k[1], ph = k[2];
    const double s = std::sin(w * tau + ph), c = std::cos(w * tau + ph);
    const double s0 = a * std::sin(ph) * decay;  // starts the path at rest at q0
    *u += a * s - s0;
    *du += a * w * c + s0 / kStartDecay;
    *ddu += -a * w * w * s - s0 / (kStartDecay * kStartDecay);
  }
}

ReferenceSample TeleopPath::evaluate(double t) const {
  double rate, rate_dot;
  const double tau = warp(t, &rate, &rate_dot);
  const double decay = std::exp(-tau / kStartDecay);
  // Segment k covers [k S, (k + 1) S) of warped time; the last blend_s of it
  // cross-fades into segment k + 1 with a smoothstep weight beta.
  const std::size_t k = std::min(segments_.size() - 1, static_cast<std::size_t>(std::max(0.0, tau) / segment_s_));
  const double blend_start = (static_cast<double>(k) + 1.0) * segment_s_ - blend_s_;
  const bool blending = tau > blend_start && k + 1 < segments_.size();
  const double x = blending ? (tau - blend_start) / blend_s_ : 0.0;
  // Quintic smootherstep: C2, so the reference acceleration stays continuous.
  const double beta = blending ? x * x * x * (10.0 + x * (-15.0 + 6.0 * x)) : 0.0;
  const double beta_d = blending ? 30.0 * x * x * (1.0 - x) * (1.0 - x) / blend_s_ : 0.0;
  const double beta_dd = blending ? 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / (blend_s_ * blend_s_) : 0.0;
  ReferenceSample r;
  for (int j = 0; j < 3; ++j) {
    double u, du, ddu;
    evaluate_segment(k, j, tau, decay, &u, &du, &ddu);
    if (blending) {
      double u1, du1, ddu1;
      evaluate_segment(k + 1, j, tau, decay, &u1, &du1, &ddu1);
      const double diff = u1 - u, diff_d = du1 - du, diff_dd = ddu1 - ddu;
      ddu = ddu + beta * diff_dd + 2.0 * beta_d * diff_d + beta_dd * diff;
      du = du + beta * diff_d + beta_d * diff;
      u = u + beta * diff;
    }
    const double th = std::tanh(u);
    const double sech2 = 1.0 - th * th;
    const double A = amplitude_[j];
    const double u_dot = du * rate;
    const double u_ddot = ddu * rate * rate + du * rate_dot;
    r.q[j] = q0_[j] + A * th;
    r.qd[j] = A * sech2 * u_dot;
    r.qdd[j] = A * sech2 * (u_ddot - 2.0 * th * u_dot * u_dot);
  }
  return r;
}

QuinticMove QuinticMove::make(double t0, double T, const ReferenceSample& from,
                              const Eigen::Vector3d& to) {
  QuinticMove m;
  m.t0 = t0;
  m.duration = T;
  for (int j = 0; j < 3; ++j) {
    const double h = to[j] - from.q[j], v0 = from.qd[j], a0 = from.qdd[j];
    m.coeff(j, 0) = from.q[j];
    m.coeff(j, 1) = v0;
    m.coeff(j, 2) = 0.5 * a0;
    m.coeff(j, 3) = (20.0 * h - 12.0 * v0 * T - 3.0 * a0 * T * T) / (2.0 * T * T * T);
    m.coeff(j, 4) = (-30.0 * h + 16.0 * v0 * T + 3.0 * a0 * T * T) / (2.0 * T * T * T * T);
    m.coeff(j, 5) = (12.0 * h - 6.0 * v0 * T - a0 * T * T) / (2.0 * T * T * T * T * T);
  }
  return m;
}

ReferenceSample QuinticMove::evaluate(double t) const {
  const double x = std::clamp(t - t0, 0.0, duration);
  ReferenceSample r;
  for (int j = 0; j < 3; ++j) {
    const auto c = coeff.row(j);
    r.q[j] = c[0] + x * (c[1] + x * (c[2] + x * (c[3] + x * (c[4] + x * c[5]))));
    r.qd[j] = c[1] + x * (2 * c[2] + x * (3 * c[3] + x * (4 * c[4] + x * 5 * c[5])));
    r.qdd[j] = 2 * c[2] + x * (6 * c[3] + x * (12 * c[4] + x * 20 * c[5]));
  }
  if (t - t0 >= duration) {
    r.qd.setZero();
    r.qdd.setZero();
  }
  return r;
}

ExcitationPath::ExcitationPath(const TrajectoryParams& p, const Eigen::Vector3d& q0, std::uint64_t seed)
    : q0_(q0), omega_(2.0 * M_PI / p.excitation_period_s), ramp_s_(p.excitation_ramp_s) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int j = 0; j < 3; ++j) {
    auto& c = coeff_[static_cast<std::size_t>(j)];
    double bound = 0.0;
    for (int k = 1; k <= p.excitation_harmonics; ++k) {
      const double scale = std::pow(static_cast<double>(k), p.excitation_falloff);
      const double a = normal(rng) / scale, b = normal(rng) / scale;
      c.push_back({a, b});
      bound += std::abs(a) + 2.0 * std::abs(b);
    }
    for (auto& ab : c) {
      ab[0] *= p.amplitude[j] / bound;
      ab[1] *= p.amplitude[j] / bound;
    }
  }
}

ReferenceSample ExcitationPath::evaluate(double t) const {
  // Quintic smoothstep r(s) = 10 s^3 - 15 s^4 + 6 s^5 and its derivatives in t.
  const double s = std::clamp(t / ramp_s_, 0.0, 1.0);
  const bool ramping = t < ramp_s_;
  const double r = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
  const double dr = ramping ? 30.0 * s * s * (1.0 - s) * (1.0 - s) / ramp_s_ : 0.0;
  const double ddr = ramping ? 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / (ramp_s_ * ramp_s_) : 0.0;
  ReferenceSample out;
  for (int j = 0; j < 3; ++j) {
    double f = 0.0, df = 0.0, ddf = 0.0;
    int k = 1;
    for (const auto& [a, b] : coeff_[static_cast<std::size_t>(j)]) {
      const double w = k * omega_, sn = std::sin(w * t), cs = std::cos(w * t);
      f += a * sn + b * (cs - 1.0);
      df += w * (a * cs - b * sn);
      ddf -= w * w * (a * sn + b * cs);
      ++k;
    }
    out.q[j] = q0_[j] + r * f;
    out.qd[j] = dr * f + r * df;
    out.qdd[j] = ddr * f + 2.0 * dr * df + r * ddf;
  }
  return out;
}

SampledPath::SampledPath(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                         const Eigen::MatrixXd& velocity) {
  if (time.size() < 1 || position.rows() != time.size() || velocity.rows() != time.size() || position.cols() < 3 ||
      velocity.cols() < 3)
    throw std::invalid_argument("SampledPath: samples of at least 3 joints, as many as time stamps");
  for (Eigen::Index i = 1; i < time.size(); ++i)
    if (!(time[i] > time[i - 1])) throw std::invalid_argument("SampledPath: time must increase strictly");
  time_ = time.array() - time[0];
  q_ = position.leftCols<3>();
  qd_ = velocity.leftCols<3>();
}

ReferenceSample SampledPath::evaluate(double t) const {
  ReferenceSample r;
  const Eigen::Index n = time_.size();
  if (n == 1 || t <= 0.0 || t >= time_[n - 1]) {
    r.q = (t <= 0.0 ? q_.row(0) : q_.row(n - 1)).transpose();
    return r;
  }
  // The interval [t_i, t_i+1) that holds t.
  const Eigen::Index i =
      std::max<Eigen::Index>(0, std::upper_bound(time_.data(), time_.data() + n, t) - time_.data() - 1);
  const double h = time_[i + 1] - time_[i], s = (t - time_[i]) / h, s2 = s * s, s3 = s2 * s;
  for (int j = 0; j < 3; ++j) {
    const double p0 = q_(i, j), p1 = q_(i + 1, j), m0 = h * qd_(i, j), m1 = h * qd_(i + 1, j);
    r.q[j] = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (3 * s2 - 2 * s3) * p1 + (s3 - s2) * m1;
    r.qd[j] = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0 + (6 * s - 6 * s2) * p1 + (3 * s2 - 2 * s) * m1) / h;
    r.qdd[j] = ((12 * s - 6) * p0 + (6 * s - 4) * m0 + (6 - 12 * s) * p1 + (6 * s - 2) * m1) / (h * h);
  }
  return r;
}

std::shared_ptr<const SampledPath> load_sampled_path(const std::filesystem::path& path, const PsmModel& robot) {
  const JointTrajectory trajectory = load_joint_trajectory(path);
  for (Eigen::Index t = 0; t < trajectory.time.size(); ++t)
    for (int j = 0; j < 3; ++j) {
      const DhJoint& joint = robot.joints()[static_cast<std::size_t>(j)];
      const double q = trajectory.position(t, j);
      if (q < joint.q_min || q > joint.q_max) {
        InputLocation where;
        where.file = trajectory.source;
        where.line = trajectory.line[static_cast<std::size_t>(t)];
        where.field = "position_" + std::to_string(j + 1);
        where.kind = InputLocation::Kind::csv_column;
        throw InputError(where, fmt::format("{} is outside the joint range [{}, {}] of {} ({})", q, joint.q_min,
                                            joint.q_max, joint.name, robot.name()));
      }
    }
  return std::make_shared<const SampledPath>(trajectory.time, trajectory.position, trajectory.velocity);
}

void ReferenceTrajectory::add_path(double t_start, std::shared_ptr<const ReferencePath> path) {
  Piece p{t_start, 0, std::move(path), {}, Eigen::Vector3d::Zero()};
  pieces_.push_back(std::move(p));
}

void ReferenceTrajectory::add_move(double t_start, double duration, const Eigen::Vector3d& to) {
  const ReferenceSample from = pieces_.empty() ? ReferenceSample{to, {}, {}} : evaluate(t_start);
  Piece p{t_start, 1, nullptr, QuinticMove::make(t_start, duration, from, to), Eigen::Vector3d::Zero()};
  pieces_.push_back(std::move(p));
}

void ReferenceTrajectory::add_hold(double t_start, const Eigen::Vector3d& q) {
  Piece p{t_start, 2, nullptr, {}, q};
  pieces_.push_back(std::move(p));
}

ReferenceSample ReferenceTrajectory::evaluate(double t) const {
  if (pieces_.empty()) return {};
  auto it = std::upper_bound(pieces_.begin(), pieces_.end(), t,
                             [](double v, const Piece& p) { return v < p.t_start; });
  const Piece& p = it == pieces_.begin() ? pieces_.front() : *(it - 1);
  const double tt = std::max(t, p.t_start);
  switch (p.kind) {
    case 0: return p.path->evaluate(tt - p.t_start);
    case 1: return p.move.evaluate(tt);
    default: {
      ReferenceSample r;
      r.q = p.hold;
      return r;
    }
  }
}

}  // namespace rcm::sim
