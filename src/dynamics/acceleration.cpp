#include "acceleration.hpp"

#include <stdexcept>

namespace rcm::dynamics::detail {

Eigen::VectorXd compute_zero_phase_acceleration(const Eigen::VectorXd& time, const Eigen::VectorXd& velocity,
                                                double window_s, int degree) {
  if (degree != 2 && degree != 3) throw std::invalid_argument("zero-phase qddot: degree must be 2 or 3");
  const Eigen::Index T = time.size();
  Eigen::VectorXd out = Eigen::VectorXd::Zero(T);
  ZeroPhaseSlope slope(window_s, degree);
  for (Eigen::Index i = 0; i < T; ++i)
    out(i) = slope.compute(
        i, 0, T, [&](Eigen::Index k) { return time(k); }, [&](Eigen::Index k) { return velocity(k); });
  return out;
}

}  // namespace rcm::dynamics::detail
