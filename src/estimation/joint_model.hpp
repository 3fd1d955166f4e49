#pragma once
// The joint torque-space model of joint.hpp: as a template, for the online
// (Jet-differentiated EKF) estimator and every plain evaluation, and with its
// Jacobians in closed form for the batch estimator's cost, which evaluates
// them for every sample at every iteration of every bootstrap solve.

#include <ceres/jet.h>

#include <Eigen/Core>

#include "rcm/estimation/joint.hpp"

namespace rcm::detail {

// tau_pred = J_D(q; s)^T f for offsets p = [dr_x, dr_y, D] and tissue
// [k1, k3, c, F]; T is double or a ceres::Jet. f_out, when given, receives f.
template <typename T>
void predict_joint_torque(const JointSample& d, const Eigen::Matrix3d& R_base_inc, double v0, const T* p,
                          const T* tissue, T* tau, Eigen::Matrix<T, 3, 1>* f_out = nullptr) {
  using V3 = Eigen::Matrix<T, 3, 1>;
  const V3 z3 = d.z3.cast<T>(), a1 = d.dz3_dq1.cast<T>(), a2 = d.dz3_dq2.cast<T>(), z3_dot = d.z3_dot.cast<T>();
  const T D = p[2];
  const T s = D / d.cos_theta;
  const double n_dot_z3dot = R_base_inc.col(2).dot(d.z3_dot);
  const T s_dot = -D * n_dot_z3dot / (d.cos_theta * d.cos_theta);
  const V3 anchor = R_base_inc.cast<T>() * V3(p[0], p[1], p[2]);
  const V3 stretch = s * z3 - anchor;
  // Smoothed norm (1 um): the radial force is continuous through zero stretch.
  using std::sqrt;
  using std::tanh;
  const T x = sqrt(stretch.squaredNorm() + T(1e-12));
  const T g = tissue[0] * x + tissue[1] * x * x * x;
  V3 f = (g / x) * stretch;
  f += tissue[2] * (s_dot * z3 + s * z3_dot);
  f += tissue[3] * tanh((T(d.qd3) - s_dot) / T(v0)) * z3;
  tau[0] = s * a1.dot(f);
  tau[1] = s * a2.dot(f);
  tau[2] = z3.dot(f);
  if (f_out) *f_out = f;
}

// tau_pred = J_D(q; s)^T f as predict_joint_torque<double> gives it, with
// d tau / d p (row j: joint j) and d tau / d tissue in closed form (checked
// against central differences in tests/test_joint_model.cpp).
void compute_joint_torque_jacobians(const JointSample& d, const Eigen::Matrix3d& R_base_inc, double v0, const double* p,
                                    const double* tissue, Eigen::Vector3d& tau, Eigen::Matrix3d& dtau_dp,
                                    Eigen::Matrix<double, 3, 4>& dtau_dtissue);

}  // namespace rcm::detail
