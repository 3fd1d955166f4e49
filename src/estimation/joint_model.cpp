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
  const double x2 = u.squaredNorm() + 1e-12;
  const double h = k1 + k3 * x2;
  const Eigen::Vector3d w = s_dot * d.z3 + s * d.z3_dot;
  const double th = std::tanh((d.qd3 - s_dot) / v0);
  const Eigen::Vector3d f = h * u + c * w + (F * th) * d.z3;
  // df/dD beyond the stretch's own dependence on D.
  const Eigen::Vector3d df_dD =
      c * (dsdot_dD * d.z3 + ds_dD * d.z3_dot) + (F * (1.0 - th * th) * (-dsdot_dD / v0)) * d.z3;
  // du/dp = -R + z3 ds/dD e3^T, so (du/dp)^T u and (du/dp)^T a for any a:
  // R^T v as three dot products: a fixed-size product expression costs more here
  // in an instrumented build than the arithmetic it does.
  auto R_T = [&R_base_inc](const Eigen::Vector3d& v) {
    return Eigen::Vector3d(R_base_inc.col(0).dot(v), R_base_inc.col(1).dot(v), R_base_inc.col(2).dot(v));
  };
  Eigen::Vector3d du_dp_T_u = -R_T(u);
  du_dp_T_u[2] += ds_dD * u.dot(d.z3);

  // tau_j = scale_j a_j . f with a = (dz3/dq1, dz3/dq2, z3), scale = (s, s, 1):
  // projections on each a_j, vectors of three rather than 3 x 4 products.
  const Eigen::Vector3d* axes[3] = {&d.dz3_dq1, &d.dz3_dq2, &d.z3};
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d& a = *axes[j];
    const double scale = j < 2 ? s : 1.0;
    const double a_u = a.dot(u), a_z3 = a.dot(d.z3), a_f = a.dot(f);
    Eigen::Vector3d grad = -h * R_T(a) + (2.0 * k3 * a_u) * du_dp_T_u;
    grad[2] += h * a_z3 * ds_dD + a.dot(df_dD);
    tau[j] = scale * a_f;
    dtau_dp.row(j) = scale * grad.transpose();
    if (j < 2) dtau_dp(j, 2) += ds_dD * a_f;
    dtau_dtissue.row(j) << scale * a_u, scale * x2 * a_u, scale * a.dot(w), scale * th * a_z3;
  }
}

}  // namespace rcm::detail
