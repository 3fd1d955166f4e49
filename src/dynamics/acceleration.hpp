#pragma once
// Internal: the qddot estimates of the model-based free-space model, shared by
// the model (linear_model.cpp) and its fit (linear_fit.cpp).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

namespace rcm::dynamics::detail {

// qddot estimate of model files that predate the choice: backward difference
// through a 30 ms first-order low-pass (it minimized the error of the filtered
// qddot against the true one on the simulated bench, 0.45 -> 0.15 rad/s^2 RMS
// for the yaw joint at 200 Hz, before the windowed fit existed).
constexpr double kDefaultAccelerationWindow = 0.0;
constexpr double kDefaultAccelerationFilter = 0.03;
// The ring buffer of the windowed fit holds the window at the model's sampling
// rate or at 2 kHz, whichever is faster; run faster still, the fit sees fewer
// samples than the window (a shorter effective window).
constexpr double kFastestSamplePeriod = 1.0 / 2000.0;
constexpr Eigen::Index kMaxWindowSamples = 4096;

inline Eigen::Index window_capacity(double window_s, double sample_period_s) {
  if (!(window_s > 0)) return 2;
  const double period = sample_period_s > 0 ? std::min(sample_period_s, kFastestSamplePeriod) : kFastestSamplePeriod;
  const double n = std::ceil(window_s / period * (1.0 + 1e-9)) + 2.0;
  return static_cast<Eigen::Index>(std::clamp(n, 3.0, static_cast<double>(kMaxWindowSamples)));
}

// The normal equations of a least-squares quadratic v = c0 + c1 s + c2 s^2,
// summed as moments: scalar sums rather than a 3x3 rank-one update per sample,
// several times cheaper over windows of hundreds of samples.
struct QuadraticMoments {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0, s4 = 0;  // sums of s^k
  double v0 = 0, v1 = 0, v2 = 0;                  // sums of v s^k
  void add(double s, double v) {
    const double ss = s * s;
    s0 += 1.0;
    s1 += s;
    s2 += ss;
    s3 += ss * s;
    s4 += ss * ss;
    v0 += v;
    v1 += v * s;
    v2 += v * ss;
  }
  Eigen::Matrix3d get_normal_matrix() const {
    Eigen::Matrix3d A;
    A << s0, s1, s2, s1, s2, s3, s2, s3, s4;
    return A;
  }
  // c1: the slope at s = 0.
  double get_slope() const { return get_normal_matrix().ldlt().solve(Eigen::Vector3d(v0, v1, v2))(1); }
};

// The normal equations of a least-squares cubic v = c0 + c1 s + c2 s^2 + c3 s^3,
// summed as moments (as QuadraticMoments).
struct CubicMoments {
  double s[7] = {};  // sums of s^k
  double v[4] = {};  // sums of v s^k
  void add(double x, double y) {
    double p = 1.0;
    for (int k = 0; k < 7; ++k, p *= x) {
      s[k] += p;
      if (k < 4) v[k] += y * p;
    }
  }
  // The slope c1, or false when the samples cannot pin a cubic down.
  bool compute_slope(double& slope) const {
    Eigen::Matrix4d A;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) A(r, c) = s[r + c];
    const double n = s[0];
    if (!(A.determinant() > 1e-12 * n * n * n * n)) return false;
    slope = A.ldlt().solve(Eigen::Vector4d(v[0], v[1], v[2], v[3]))(1);
    return true;
  }
};

// A sample belongs to the zero-phase window of half-width h about t_c when it
// lies within h of it, with this relative slack for stamps that are sums of
// periods.
constexpr double kWindowSlack = 1e-9;

// The zero-phase qddot at t_c from the samples k in [lo, hi) of one window
// (time_at(k), velocity_at(k)): the slope at t_c of the least-squares
// polynomial of `degree` (2 or 3) through them; with too few distinct times for
// the cubic, the quadratic; for the quadratic, the difference across the
// window. The one home of the estimate, over a recording
// (compute_zero_phase_acceleration) and over the live model's ring of samples.
template <class TimeAt, class VelocityAt>
double compute_local_slope(Eigen::Index lo, Eigen::Index hi, double t_c, double h, int degree, TimeAt time_at,
                           VelocityAt velocity_at) {
  if (degree == 3 && hi - lo >= 5) {
    CubicMoments m;
    for (Eigen::Index k = lo; k < hi; ++k) m.add((time_at(k) - t_c) / h, velocity_at(k));
    double slope;
    if (m.compute_slope(slope)) return slope / h;
  }
  const double n = static_cast<double>(hi - lo);
  QuadraticMoments m;
  for (Eigen::Index k = lo; k < hi; ++k) m.add((time_at(k) - t_c) / h, velocity_at(k));
  if (hi - lo >= 3 && m.get_normal_matrix().determinant() > 1e-9 * n * n * n) return m.get_slope() / h;
  if (hi - lo >= 2 && time_at(hi - 1) > time_at(lo))
    return (velocity_at(hi - 1) - velocity_at(lo)) / (time_at(hi - 1) - time_at(lo));
  return 0.0;
}

// Causal qddot of one joint from its measured qdot (velocity is itself a filtered
// difference of quantized encoders, so differentiating it again is mostly noise
// at 200 Hz). A first-order low-pass of the backward difference (window 0) lags
// by about its time constant; the slope at the newest sample of a least-squares
// quadratic through the last `window` seconds has no lag while qddot changes
// linearly over the window and averages the noise over the window instead. The
// optional low-pass follows the fit. A sample at the same time as the previous
// one is ignored; one earlier than it restarts the window (as the backward
// difference of window 0 does). Sized once; update() does not allocate.
class AccelerationEstimator {
 public:
  AccelerationEstimator(double window_s, double filter_s, double sample_period_s)
      : window_(window_s), filter_(filter_s) {
    const Eigen::Index n = window_capacity(window_s, sample_period_s);
    t_.resize(n);
    v_.resize(n);
  }
  void reset() {
    count_ = 0;
    head_ = 0;
    filtered_ = 0.0;
  }
  double value() const { return filtered_; }
  double update(double t, double v) {
    if (count_ > 0 && t == t_[head_]) return filtered_;
    if (count_ > 0 && !(t > t_[head_])) count_ = 0;  // time went back: restart the window
    const double dt = count_ > 0 ? t - t_[head_] : 0.0;
    const Eigen::Index cap = t_.size();
    head_ = (head_ + 1) % cap;
    t_[head_] = t;
    v_[head_] = v;
    count_ = std::min(count_ + 1, cap);
    if (count_ < 2) return filtered_;
    const double raw = window_ > 0 ? fitted_slope() : (v - previous(1)) / dt;
    filtered_ = filter_ > 0 ? filtered_ + dt / (filter_ + dt) * (raw - filtered_) : raw;
    return filtered_;
  }

 private:
  double previous(Eigen::Index k) const { return v_[(head_ - k + t_.size()) % t_.size()]; }
  double previous_time(Eigen::Index k) const { return t_[(head_ - k + t_.size()) % t_.size()]; }
  // Slope at the newest sample of the least-squares quadratic through the
  // samples no older than the window (s = (t_k - t) / window in [-1, 0]).
  double fitted_slope() const {
    const double t = t_[head_];
    QuadraticMoments m;
    Eigen::Index n = 0;
    for (Eigen::Index k = 0; k < count_; ++k) {
      const double s = (previous_time(k) - t) / window_;
      if (s < -1.0 - 1e-9) break;
      m.add(s, previous(k));
      ++n;
    }
    if (n < 3) return (previous(0) - previous(1)) / (t - previous_time(1));
    return m.get_slope() / window_;
  }

  double window_, filter_;
  Eigen::VectorXd t_, v_;  // ring buffer, newest at head_
  Eigen::Index head_ = 0, count_ = 0;
  double filtered_ = 0.0;
};

inline bool is_time_sorted(const Eigen::VectorXd& time) {
  const Eigen::Index T = time.size();
  return T < 2 || ((time.tail(T - 1) - time.head(T - 1)).array() >= 0).all();
}

// Zero-phase qddot of a whole recording (time never decreasing): at each sample
// the slope there of the least-squares polynomial of `degree` (2 or 3) through
// the samples within +- window / 2 of it. Symmetric inside the recording; near
// either end the window is cut and the fit becomes one-sided. Why the cubic: over
// a symmetric window a quadratic's slope is a straight line's, which passes a
// sinusoid of angular frequency w at 1 - (w window / 2)^2 / 10 of its size, so
// the inertia fitted at one speed takes in the droop at that speed's
// frequencies and mispredicts another speed; the cubic's passes it at
// 1 - O((w window / 2)^4) (0.998 at w window / 2 = 1, where the quadratic's
// is 0.90). With too few distinct times for the cubic, the quadratic; for the
// quadratic, the difference across the window.
Eigen::VectorXd compute_zero_phase_acceleration(const Eigen::VectorXd& time, const Eigen::VectorXd& velocity,
                                                double window_s, int degree);

}  // namespace rcm::dynamics::detail
