#pragma once
// Internal: the qddot estimates of the model-based free-space model, shared by
// the model (linear_model.cpp) and its fit (linear_fit.cpp).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <iterator>

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

// The slope at s = 0 of the least-squares polynomial v(s) of `degree` (2 or 3)
// from the moments about that point, m[p] = sum s^p (p <= 6) and w[p] = sum
// v s^p (p <= 3) over m[0] samples; false when the samples cannot pin the
// polynomial down (too few, or too few distinct times).
inline bool compute_moment_slope(const double* m, const double* w, int degree, double& slope) {
  const double n = m[0];
  if (degree == 3) {
    if (n < 5) return false;
    Eigen::Matrix4d A;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) A(r, c) = m[r + c];
    if (!(A.determinant() > 1e-12 * n * n * n * n)) return false;
    slope = A.ldlt().solve(Eigen::Vector4d(w[0], w[1], w[2], w[3]))(1);
    return true;
  }
  if (n < 3) return false;
  Eigen::Matrix3d A;
  A << m[0], m[1], m[2], m[1], m[2], m[3], m[2], m[3], m[4];
  if (!(A.determinant() > 1e-9 * n * n * n)) return false;
  slope = A.ldlt().solve(Eigen::Vector3d(w[0], w[1], w[2]))(1);
  return true;
}

// A sample belongs to the zero-phase window of half-width h about t_c when it
// lies within h of it, with this relative slack for stamps that are sums of
// periods.
constexpr double kWindowSlack = 1e-9;

// The zero-phase qddot of one joint at successive samples c of a stream whose
// time never decreases: the slope at sample c of the least-squares polynomial
// of `degree` (2 or 3) through the samples within +- window / 2 of it, cut
// where the stream begins or ends (one-sided there); with too few distinct
// times for the cubic, the quadratic; for the quadratic, the difference across
// the window. The one home of that estimate, over a recording
// (compute_zero_phase_acceleration) and over the live model's ring of samples.
// The window's moments are kept about an anchor time as samples enter and
// leave, so that a slope costs the same however many samples the window holds
// (600 in 0.4 s at 1.5 kHz). The anchor moves to the sample, the sums
// recomputed from the window's samples, once the sample is more than half a
// half-window from it: the powers of (t - anchor) / h then stay within 1.5^6,
// and the shift of the moments to the sample loses no more than a few hundred
// ulps. Calls with c not increasing, or a window reaching below `begin` (the
// oldest sample kept), recompute the sums. No allocation.
class ZeroPhaseSlope {
 public:
  ZeroPhaseSlope(double window_s, int degree) : h_(0.5 * window_s), degree_(degree) {}
  void reset() { valid_ = false; }
  // The samples k in [begin, end) are the stream's (time_at(k), velocity_at(k)),
  // c among them.
  template <class TimeAt, class VelocityAt>
  double compute(Eigen::Index c, Eigen::Index begin, Eigen::Index end, TimeAt time_at, VelocityAt velocity_at) {
    const double t_c = time_at(c);
    const double lower = t_c - h_ * (1.0 + kWindowSlack), upper = t_c + h_ * (1.0 + kWindowSlack);
    if (!valid_ || c < last_ || lo_ < begin || std::abs(t_c - anchor_) > 0.5 * h_) {
      anchor_ = t_c;
      velocity_ref_ = velocity_at(c);
      std::fill(std::begin(s_), std::end(s_), 0.0);
      std::fill(std::begin(w_), std::end(w_), 0.0);
      lo_ = c;
      while (lo_ > begin && time_at(lo_ - 1) >= lower) --lo_;
      for (hi_ = lo_; hi_ <= c || (hi_ < end && time_at(hi_) <= upper); ++hi_) add(time_at(hi_), velocity_at(hi_), 1.0);
      valid_ = true;
    } else {
      for (; hi_ < end && time_at(hi_) <= upper; ++hi_) add(time_at(hi_), velocity_at(hi_), 1.0);
      for (; lo_ < c && time_at(lo_) < lower; ++lo_) add(time_at(lo_), velocity_at(lo_), -1.0);
    }
    last_ = c;
    // The moments about t_c from those about the anchor (binomial shift).
    static constexpr double kBinomial[7][7] = {{1}, {1, 1}, {1, 2, 1}, {1, 3, 3, 1}, {1, 4, 6, 4, 1},
                                               {1, 5, 10, 10, 5, 1}, {1, 6, 15, 20, 15, 6, 1}};
    double power[7] = {1.0};  // (-delta)^p
    const double delta = (t_c - anchor_) / h_;
    for (int p = 1; p < 7; ++p) power[p] = -delta * power[p - 1];
    double m[7], w[4];
    for (int p = 0; p < 7; ++p) {
      m[p] = 0.0;
      for (int i = 0; i <= p; ++i) m[p] += kBinomial[p][i] * s_[i] * power[p - i];
      if (p < 4) {
        w[p] = 0.0;
        for (int i = 0; i <= p; ++i) w[p] += kBinomial[p][i] * w_[i] * power[p - i];
      }
    }
    m[0] = static_cast<double>(hi_ - lo_);
    double slope;
    if (degree_ == 3 && compute_moment_slope(m, w, 3, slope)) return slope / h_;
    if (compute_moment_slope(m, w, 2, slope)) return slope / h_;
    const Eigen::Index last = hi_ - 1;
    if (last > lo_ && time_at(last) > time_at(lo_))
      return (velocity_at(last) - velocity_at(lo_)) / (time_at(last) - time_at(lo_));
    return 0.0;
  }

 private:
  void add(double t, double v, double sign) {
    const double x = (t - anchor_) / h_, dv = v - velocity_ref_;
    double p = sign;
    for (int k = 0; k < 7; ++k, p *= x) {
      s_[k] += p;
      if (k < 4) w_[k] += dv * p;
    }
  }

  double h_;
  int degree_;
  bool valid_ = false;
  Eigen::Index lo_ = 0, hi_ = 0, last_ = 0;  // the window [lo_, hi_) of sample last_
  // Sums of x^k and (v - velocity_ref_) x^k, x = (t - anchor_) / h_: the
  // velocity at the anchor taken out, which the slope does not depend on, so
  // that an offset far above the velocity's swing costs no digits.
  double anchor_ = 0.0, velocity_ref_ = 0.0;
  double s_[7] = {}, w_[4] = {};
};

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
