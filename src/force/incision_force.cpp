#include "rcm/force/incision_force.hpp"

#include <cmath>
#include <limits>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_residual.hpp"

namespace rcm {

IncisionForceSample compute_incision_force(const IncisionFrame& incision,
                                           const Eigen::Vector3d& q, double D,
                                           const Eigen::Vector3d& dtau,
                                           const JacobianCheckOptions& options) {
  IncisionForceSample out;
  out.theta = compute_pivot_angle(incision, q);
  out.shaft_distance = compute_shaft_distance(incision, q, D);
  out.condition = compute_incision_jacobian_condition(q, out.shaft_distance, options);
  if (out.condition.status == JacobianStatus::singular) {
    out.f_inc_base.setConstant(std::numeric_limits<double>::quiet_NaN());
    return out;
  }
  // The columns of J_D are orthogonal with J^T J = diag(s^2 c2^2, s^2, 1), hence
  // J^{-T} = J (J^T J)^{-1}: exact and cheaper than a factorization.
  const double s = out.shaft_distance;
  const double c2 = std::cos(q[1]);
  const Eigen::Matrix3d J = compute_incision_jacobian(q, s);
  out.f_inc_base = J.col(0) * (dtau[0] / (s * s * c2 * c2)) + J.col(1) * (dtau[1] / (s * s)) +
                   J.col(2) * dtau[2];
  return out;
}

IncisionForceSeries compute_incision_force_series(const IncisionFrame& incision,
                                                  const Recording& recording,
                                                  const Eigen::MatrixXd& tau_fs, double D,
                                                  const JacobianCheckOptions& options) {
  const Eigen::Index T = recording.time.size();
  const TorqueResidual dtau = compute_torque_residual(recording, tau_fs);
  IncisionForceSeries series;
  series.f_inc_base.resize(T, 3);
  series.theta.resize(T);
  series.condition.resize(T);
  series.status.resize(static_cast<std::size_t>(T));
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Vector3d q = recording.position.row(t).head<3>().transpose();
    const IncisionForceSample sample = compute_incision_force(incision, q, D, dtau.row(t).transpose(), options);
    series.f_inc_base.row(t) = sample.f_inc_base.transpose();
    series.theta[t] = sample.theta;
    series.condition[t] = sample.condition.condition;
    series.status[static_cast<std::size_t>(t)] = sample.condition.status;
    if (sample.condition.status == JacobianStatus::ill_conditioned) ++series.num_ill_conditioned;
    if (sample.condition.status == JacobianStatus::singular) ++series.num_singular;
  }
  return series;
}

}  // namespace rcm
