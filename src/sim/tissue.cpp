#include "rcm/sim/tissue.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>
#include <string>

#include "rcm/sim/arm_dynamics.hpp"

namespace rcm::sim {

TissueModel::TissueModel(const TissueParams& p, const Eigen::Vector3d& q0_in,
                         const Eigen::Vector3d& misalignment)
    : params(p), q0(q0_in), misalignment_m(misalignment) {
  const ShaftFrame f0 = compute_shaft_frame(q0);
  R_base_inc.col(0) = f0.x3;
  R_base_inc.col(1) = f0.y3;
  R_base_inc.col(2) = f0.z3;
  p_anchor_base = R_base_inc * misalignment_m;
}

double compute_tissue_law(const TissueParams& params, double x) {
  return params.stiffness_n_per_m * x + params.cubic_n_per_m3 * x * x * x;
}

TissueOutput compute_tissue_force(const TissueModel& model, const Eigen::Vector3d& q,
                                  const Eigen::Vector3d& qd, double axial_z) {
  const TissueParams& P = model.params;
  const ShaftFrame f = compute_shaft_frame(q);
  const Eigen::Vector3d n = model.R_base_inc.col(2);
  const double D = model.coaxial_offset();
  const double c = n.dot(f.z3);
  if (!(c >= P.min_pad_cosine))
    throw std::domain_error("simulated shaft too flat to the pad: cos(theta) = " +
                            std::to_string(c));
  TissueOutput out;
  out.theta = std::atan2(n.cross(f.z3).norm(), c);
  const double s = D / c;
  out.shaft_distance = s;
  out.p_cross_base = s * f.z3;
  out.stretch_base = out.p_cross_base - model.p_anchor_base;

  // Velocity of the crossing point (the incision is dragged with it); the pad
  // plane moves with D.
  const Eigen::Vector3d z3_dot = f.dz3_dq1 * qd[0] + f.x3 * qd[1];
  const double D_dot = model.misalignment_rate_m_per_s.z();
  const double s_dot = D_dot / c - D * n.dot(z3_dot) / (c * c);
  const Eigen::Vector3d p_cross_dot = s_dot * f.z3 + s * z3_dot;
  const Eigen::Vector3d stretch_dot = p_cross_dot - model.R_base_inc * model.misalignment_rate_m_per_s;

  const double x = out.stretch_base.norm();
  Eigen::Vector3d f_el = Eigen::Vector3d::Zero();
  if (x > 0.0) f_el = compute_tissue_law(P, x) * (out.stretch_base / x);
  const Eigen::Vector3d f_visc = P.damping_n_s_per_m * stretch_dot;

  // The shaft slides through the incision at qd3 - s_dot; friction drags the
  // tissue along z3 with it (on the shaft it acts the other way).
  out.axial_velocity = qd[2] - s_dot;
  if (P.axial_friction_n > 0.0) {
    out.axial_force = compute_lugre_force(P.axial_friction_n, P.axial_friction_n, 1.0, 1.0,
                                          P.axial_bristle_n_per_m,
                                          P.axial_bristle_damping_n_s_per_m, axial_z,
                                          out.axial_velocity, &out.axial_zdot);
  }
  out.f_inc_base = f_el + f_visc + out.axial_force * f.z3;

  // Jacobian of the shaft's material point at the crossing.
  out.J_inc_base.col(0) = s * f.dz3_dq1;
  out.J_inc_base.col(1) = s * f.x3;
  out.J_inc_base.col(2) = f.z3;
  out.tau = out.J_inc_base.transpose() * out.f_inc_base;
  return out;
}

double advance_tissue_state(const TissueModel& model, double axial_z, double axial_velocity,
                            double dt) {
  const TissueParams& P = model.params;
  if (P.axial_friction_n <= 0.0) return 0.0;
  return advance_lugre_state(P.axial_friction_n, P.axial_friction_n, 1.0, 1.0,
                             P.axial_bristle_n_per_m, axial_z, axial_velocity, dt);
}

}  // namespace rcm::sim
