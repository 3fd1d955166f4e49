#include "acceleration.hpp"

#include <stdexcept>

namespace rcm::dynamics::detail {

Eigen::VectorXd compute_zero_phase_acceleration(const Eigen::VectorXd& time, const Eigen::VectorXd& velocity,
                                                double window_s, int degree) {
  if (degree != 2 && degree != 3) throw std::invalid_argument("zero-phase qddot: degree must be 2 or 3");
  const Eigen::Index T = time.size();
  const double h = 0.5 * window_s;
  Eigen::VectorXd out = Eigen::VectorXd::Zero(T);
  Eigen::Index lo = 0, hi = 0;  // window [lo, hi)
  for (Eigen::Index i = 0; i < T; ++i) {
    while (time(lo) < time(i) - h * (1.0 + kWindowSlack)) ++lo;
    if (hi < i + 1) hi = i + 1;
    while (hi < T && time(hi) <= time(i) + h * (1.0 + kWindowSlack)) ++hi;
    out(i) = compute_local_slope(
        lo, hi, time(i), h, degree, [&](Eigen::Index k) { return time(k); },
        [&](Eigen::Index k) { return velocity(k); });
  }
  return out;
}

}  // namespace rcm::dynamics::detail
