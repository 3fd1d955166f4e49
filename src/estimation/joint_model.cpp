#include "joint_model.hpp"

#include <cmath>

namespace rcm::detail {

// The chain of predict_joint_torque, term by term: with s = D / cos(theta) and
// the stretch u = s z3 - R p, the elastic force is h u with h = g(x) / x =
// k1 + k3 x^2 and x^2 = |u|^2 + 1e-12 (the smoothed norm); the damping c w and
// the axial friction F tanh(a) z3 depend on p only through D.
void compute_joint_torque_jacobians(const JointSample& d, const Eigen::Matrix3d& R_base_inc, double v0, const double* p,
                                    const double* tissue, Eigen::Vector3d& tau, Eigen::Matrix3d& dtau_dp,
                                    Eigen::Matrix<double, 3, 4>& dtau_dtissue) {
  const double k1 = tissue[0], k3 = tissue[1], c = tissue[2], F = tissue[3];
  const double ct = d.cos_theta;
  const double D = p[2];
  const double s = D / ct, ds_dD = 1.0 / ct;
  const double dsdot_dD = -R_base_inc.col(2).dot(d.z3_dot) / (ct * ct);
  const double s_dot = D * dsdot_dD;

  const Eigen::Vector3d u = s * d.z3 - R_base_inc * Eigen::Vector3d(p[0], p[1], p[2]);
  Eigen::Matrix3d du_dp = -R_base_inc;
  du_dp.col(2) += ds_dD * d.z3;
  const double x2 = u.squaredNorm() + 1e-12;
  const double h = k1 + k3 * x2;
  Eigen::Vector3d f = h * u;
  Eigen::Matrix3d df_dp = h * du_dp + (2.0 * k3) * u * (u.transpose() * du_dp);
  Eigen::Matrix<double, 3, 4> df_dtissue;
  df_dtissue.col(0) = u;
  df_dtissue.col(1) = x2 * u;

  const Eigen::Vector3d w = s_dot * d.z3 + s * d.z3_dot;
  f += c * w;
  df_dtissue.col(2) = w;
  Eigen::Vector3d df_dD = c * (dsdot_dD * d.z3 + ds_dD * d.z3_dot);

  const double th = std::tanh((d.qd3 - s_dot) / v0);
  f += (F * th) * d.z3;
  df_dtissue.col(3) = th * d.z3;
  df_dD += (F * (1.0 - th * th) * (-dsdot_dD / v0)) * d.z3;
  df_dp.col(2) += df_dD;

  tau << s * d.dz3_dq1.dot(f), s * d.dz3_dq2.dot(f), d.z3.dot(f);
  dtau_dp.row(0) = s * d.dz3_dq1.transpose() * df_dp;
  dtau_dp.row(1) = s * d.dz3_dq2.transpose() * df_dp;
  dtau_dp.row(2) = d.z3.transpose() * df_dp;
  dtau_dp(0, 2) += ds_dD * d.dz3_dq1.dot(f);
  dtau_dp(1, 2) += ds_dD * d.dz3_dq2.dot(f);
  dtau_dtissue.row(0) = s * d.dz3_dq1.transpose() * df_dtissue;
  dtau_dtissue.row(1) = s * d.dz3_dq2.transpose() * df_dtissue;
  dtau_dtissue.row(2) = d.z3.transpose() * df_dtissue;
}

}  // namespace rcm::detail
