#include "acceleration.hpp"

#include <Eigen/LU>

namespace rcm::dynamics::detail {

Eigen::VectorXd compute_zero_phase_acceleration(const Eigen::VectorXd& time, const Eigen::VectorXd& velocity,
                                                double window_s) {
  const Eigen::Index T = time.size();
  const double h = 0.5 * window_s;
  Eigen::VectorXd out = Eigen::VectorXd::Zero(T);
  Eigen::Index lo = 0, hi = 0;  // window [lo, hi)
  for (Eigen::Index i = 0; i < T; ++i) {
    while (time(lo) < time(i) - h * (1.0 + 1e-9)) ++lo;
    if (hi < i + 1) hi = i + 1;
    while (hi < T && time(hi) <= time(i) + h * (1.0 + 1e-9)) ++hi;
    QuadraticMoments m;
    for (Eigen::Index k = lo; k < hi; ++k) m.add((time(k) - time(i)) / h, velocity(k));
    const double n = static_cast<double>(hi - lo);
    if (hi - lo >= 3 && m.get_normal_matrix().determinant() > 1e-9 * n * n * n) {
      out(i) = m.get_slope() / h;
    } else if (time(hi - 1) > time(lo)) {
      out(i) = (velocity(hi - 1) - velocity(lo)) / (time(hi - 1) - time(lo));
    }
  }
  return out;
}

}  // namespace rcm::dynamics::detail
