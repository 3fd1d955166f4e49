#include "acceleration.hpp"

#include <Eigen/LU>
#include <stdexcept>

namespace rcm::dynamics::detail {

namespace {

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
  Eigen::Matrix4d get_normal_matrix() const {
    Eigen::Matrix4d A;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) A(r, c) = s[r + c];
    return A;
  }
  // The slope c1, or false when the samples cannot pin a cubic down.
  bool compute_slope(double& slope) const {
    const Eigen::Matrix4d A = get_normal_matrix();
    const double n = s[0];
    if (!(A.determinant() > 1e-12 * n * n * n * n)) return false;
    slope = A.ldlt().solve(Eigen::Vector4d(v[0], v[1], v[2], v[3]))(1);
    return true;
  }
};

}  // namespace

Eigen::VectorXd compute_zero_phase_acceleration(const Eigen::VectorXd& time, const Eigen::VectorXd& velocity,
                                                double window_s, int degree) {
  if (degree != 2 && degree != 3) throw std::invalid_argument("zero-phase qddot: degree must be 2 or 3");
  const Eigen::Index T = time.size();
  const double h = 0.5 * window_s;
  Eigen::VectorXd out = Eigen::VectorXd::Zero(T);
  Eigen::Index lo = 0, hi = 0;  // window [lo, hi)
  for (Eigen::Index i = 0; i < T; ++i) {
    while (time(lo) < time(i) - h * (1.0 + 1e-9)) ++lo;
    if (hi < i + 1) hi = i + 1;
    while (hi < T && time(hi) <= time(i) + h * (1.0 + 1e-9)) ++hi;
    if (degree == 3 && hi - lo >= 5) {
      CubicMoments m;
      for (Eigen::Index k = lo; k < hi; ++k) m.add((time(k) - time(i)) / h, velocity(k));
      double slope;
      if (m.compute_slope(slope)) {
        out(i) = slope / h;
        continue;
      }
    }
    const double n = static_cast<double>(hi - lo);
    QuadraticMoments m;
    for (Eigen::Index k = lo; k < hi; ++k) m.add((time(k) - time(i)) / h, velocity(k));
    if (hi - lo >= 3 && m.get_normal_matrix().determinant() > 1e-9 * n * n * n) {
      out(i) = m.get_slope() / h;
    } else if (time(hi - 1) > time(lo)) {
      out(i) = (velocity(hi - 1) - velocity(lo)) / (time(hi - 1) - time(lo));
    }
  }
  return out;
}

}  // namespace rcm::dynamics::detail
