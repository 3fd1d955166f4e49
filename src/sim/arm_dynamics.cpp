#include "rcm/sim/arm_dynamics.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace rcm::sim {

Eigen::Vector3d get_yaw_axis_base() { return Eigen::Vector3d(0.0, -1.0, 0.0); }

namespace {

Eigen::Matrix3d diag_inertia(const Eigen::Vector3d& d) { return d.asDiagonal(); }

// Rotation of the yaw link: q1 about the yaw axis (dz3/dq1 = axis x z3 fixes the sign).
Eigen::Matrix3d rotation_yaw(double q1) {
  return Eigen::AngleAxisd(q1, get_yaw_axis_base()).toRotationMatrix();
}

// Kinematic quantities of the three bodies in the base frame.
struct BodyKinematics {
  Eigen::Matrix3d R_yaw, R_3;
  ShaftFrame shaft;
  Eigen::Vector3d w1, w2;            // angular velocities of yaw link and of frame 3
  Eigen::Vector3d p_yaw, p_pitch, p_ins;  // centres of mass
};

BodyKinematics compute_body_kinematics(const ArmDynamics& m, const Eigen::Vector3d& q,
                                       const Eigen::Vector3d& qd) {
  BodyKinematics k;
  k.shaft = compute_shaft_frame(q);
  k.R_yaw = rotation_yaw(q[0]);
  k.R_3.col(0) = k.shaft.x3;
  k.R_3.col(1) = k.shaft.y3;
  k.R_3.col(2) = k.shaft.z3;
  const Eigen::Vector3d a1 = get_yaw_axis_base();
  k.w1 = qd[0] * a1;
  k.w2 = k.w1 + qd[1] * k.shaft.y3;
  k.p_yaw = k.R_yaw * m.params.yaw_link.com_m;
  k.p_pitch = k.R_3 * m.params.pitch_link.com_m;
  k.p_ins = k.R_3 * m.params.insertion_stage.com_m + q[2] * k.shaft.z3;
  return k;
}

}  // namespace

ArmDynamics::ArmDynamics(const ArmParams& p)
    : params(p),
      inertia_yaw_body(diag_inertia(p.yaw_link.inertia_diag_kg_m2)),
      inertia_pitch_body(diag_inertia(p.pitch_link.inertia_diag_kg_m2)),
      inertia_insertion_body(diag_inertia(p.insertion_stage.inertia_diag_kg_m2)) {}

// Newton-Euler in the base frame. Joints 1 and 2 rotate about axes through the
// RCM (the origin), so the torque each must supply is the axial component of the
// total moment about the origin needed by all bodies outboard of it; the
// insertion joint supplies the z3 component of the stage's net force.
Eigen::Vector3d compute_inverse_dynamics(const ArmDynamics& m, const Eigen::Vector3d& q,
                                         const Eigen::Vector3d& qd, const Eigen::Vector3d& qdd,
                                         bool with_gravity) {
  const BodyKinematics k = compute_body_kinematics(m, q, qd);
  const Eigen::Vector3d a1 = get_yaw_axis_base();
  const Eigen::Vector3d& y3 = k.shaft.y3;
  const Eigen::Vector3d& z3 = k.shaft.z3;
  const Eigen::Vector3d g = with_gravity ? m.params.gravity_base_m_s2 : Eigen::Vector3d::Zero();

  const Eigen::Vector3d alpha1 = qdd[0] * a1;
  // y3 turns with the yaw link: d(y3)/dt = w1 x y3.
  const Eigen::Vector3d alpha2 = alpha1 + qdd[1] * y3 + qd[1] * k.w1.cross(y3);

  // Yaw link.
  const auto& P = m.params;
  const Eigen::Vector3d acc_yaw = alpha1.cross(k.p_yaw) + k.w1.cross(k.w1.cross(k.p_yaw));
  const Eigen::Vector3d F_yaw = P.yaw_link.mass_kg * (acc_yaw - g);
  const Eigen::Matrix3d I_yaw = k.R_yaw * m.inertia_yaw_body * k.R_yaw.transpose();
  const Eigen::Vector3d L_yaw = k.p_yaw.cross(F_yaw) + I_yaw * alpha1 + k.w1.cross(I_yaw * k.w1);

  // Pitch parallelogram.
  const Eigen::Vector3d acc_pitch = alpha2.cross(k.p_pitch) + k.w2.cross(k.w2.cross(k.p_pitch));
  const Eigen::Vector3d F_pitch = P.pitch_link.mass_kg * (acc_pitch - g);
  const Eigen::Matrix3d I_pitch = k.R_3 * m.inertia_pitch_body * k.R_3.transpose();
  const Eigen::Vector3d L_pitch =
      k.p_pitch.cross(F_pitch) + I_pitch * alpha2 + k.w2.cross(I_pitch * k.w2);

  // Insertion stage: a body-fixed point of frame 3 plus the slide q3 z3.
  const Eigen::Vector3d acc_ins = alpha2.cross(k.p_ins) + k.w2.cross(k.w2.cross(k.p_ins)) +
                                  2.0 * qd[2] * k.w2.cross(z3) + qdd[2] * z3;
  const Eigen::Vector3d F_ins = P.insertion_stage.mass_kg * (acc_ins - g);
  const Eigen::Matrix3d I_ins = k.R_3 * m.inertia_insertion_body * k.R_3.transpose();
  const Eigen::Vector3d L_ins = k.p_ins.cross(F_ins) + I_ins * alpha2 + k.w2.cross(I_ins * k.w2);

  Eigen::Vector3d tau;
  tau[2] = z3.dot(F_ins) +
           (with_gravity ? P.insertion_counterbalance_n + P.insertion_stiffness_n_per_m * q[2] : 0.0);
  tau[1] = y3.dot(L_pitch + L_ins);
  tau[0] = a1.dot(L_yaw + L_pitch + L_ins);
  return tau;
}

Eigen::Matrix3d compute_mass_matrix(const ArmDynamics& model, const Eigen::Vector3d& q) {
  Eigen::Matrix3d M;
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  for (int j = 0; j < 3; ++j)
    M.col(j) = compute_inverse_dynamics(model, q, zero, Eigen::Vector3d::Unit(j), false);
  // Symmetric up to rounding; make it exactly so for the solver.
  return 0.5 * (M + M.transpose());
}

double compute_kinetic_energy(const ArmDynamics& m, const Eigen::Vector3d& q,
                              const Eigen::Vector3d& qd) {
  const BodyKinematics k = compute_body_kinematics(m, q, qd);
  const auto& P = m.params;
  const Eigen::Vector3d v_yaw = k.w1.cross(k.p_yaw);
  const Eigen::Vector3d v_pitch = k.w2.cross(k.p_pitch);
  const Eigen::Vector3d v_ins = k.w2.cross(k.p_ins) + qd[2] * k.shaft.z3;
  const Eigen::Vector3d w1_body = k.R_yaw.transpose() * k.w1;
  const Eigen::Vector3d w2_body = k.R_3.transpose() * k.w2;
  return 0.5 * (P.yaw_link.mass_kg * v_yaw.squaredNorm() +
                P.pitch_link.mass_kg * v_pitch.squaredNorm() +
                P.insertion_stage.mass_kg * v_ins.squaredNorm() +
                w1_body.dot(m.inertia_yaw_body * w1_body) +
                w2_body.dot(m.inertia_pitch_body * w2_body) +
                w2_body.dot(m.inertia_insertion_body * w2_body));
}

double compute_potential_energy(const ArmDynamics& m, const Eigen::Vector3d& q) {
  const BodyKinematics k = compute_body_kinematics(m, q, Eigen::Vector3d::Zero());
  const auto& P = m.params;
  const Eigen::Vector3d& g = P.gravity_base_m_s2;
  return -(P.yaw_link.mass_kg * g.dot(k.p_yaw) + P.pitch_link.mass_kg * g.dot(k.p_pitch) +
           P.insertion_stage.mass_kg * g.dot(k.p_ins)) +
         P.insertion_counterbalance_n * q[2] + 0.5 * P.insertion_stiffness_n_per_m * q[2] * q[2];
}

namespace {

double lugre_g(double coulomb_pos, double coulomb_neg, double stiction_ratio, double vs,
               double v) {
  const double fc = v >= 0.0 ? coulomb_pos : coulomb_neg;
  const double r = v / vs;
  return fc * (1.0 + (stiction_ratio - 1.0) * std::exp(-r * r));
}

}  // namespace

double compute_lugre_force(double coulomb_pos, double coulomb_neg, double stiction_ratio,
                           double stribeck_velocity, double sigma0, double sigma1, double z,
                           double v, double* zdot) {
  double zd = v;
  if (v != 0.0) {
    const double g = lugre_g(coulomb_pos, coulomb_neg, stiction_ratio, stribeck_velocity, v);
    zd = v - sigma0 * std::abs(v) * z / g;
  }
  if (zdot) *zdot = zd;
  return sigma0 * z + sigma1 * zd;
}

double advance_lugre_state(double coulomb_pos, double coulomb_neg, double stiction_ratio,
                           double stribeck_velocity, double sigma0, double z, double v,
                           double dt) {
  if (v == 0.0 || sigma0 <= 0.0) return z;
  const double g = lugre_g(coulomb_pos, coulomb_neg, stiction_ratio, stribeck_velocity, v);
  const double z_ss = (v > 0.0 ? g : -g) / sigma0;
  const double rate = sigma0 * std::abs(v) / g;
  return z_ss + (z - z_ss) * std::exp(-rate * dt);
}

namespace {

// One joint's slip elements: force and, while sticking, damping.
double compute_slip_force(const JointFrictionParams& p, const FrictionState& state, int joint, double v) {
  double f = 0.0, k_sticking = 0.0, k_total = 0.0;
  for (std::size_t i = 0; i < p.slip_elements.size(); ++i) {
    const double width = p.slip_elements[i][0], level = p.slip_elements[i][1];
    const double z = state.slip(joint, static_cast<Eigen::Index>(i));
    const double k = level / width;
    f += k * z;
    k_total += k;
    // Sticking: not at its limit, or at it and moving back from it.
    if (std::abs(z) < width || z * v < 0.0) k_sticking += k;
  }
  if (p.slip_damping > 0.0 && k_total > 0.0) f += p.slip_damping * (k_sticking / k_total) * v;
  return f;
}

}  // namespace

FrictionOutput compute_friction(const std::array<JointFrictionParams, 3>& params, const FrictionState& state,
                                const Eigen::Vector3d& qd) {
  FrictionOutput out;
  for (int j = 0; j < 3; ++j) {
    const auto& p = params[static_cast<std::size_t>(j)];
    double f = p.viscous * qd[j] + p.offset;
    if (p.coulomb_pos > 0.0 || p.coulomb_neg > 0.0) {
      double zd = 0.0;
      f += compute_lugre_force(p.coulomb_pos, p.coulomb_neg, p.stiction_ratio, p.stribeck_velocity,
                               p.bristle_stiffness, p.bristle_damping, state.bristles[j], qd[j], &zd);
      out.zdot[j] = zd;
    }
    if (!p.slip_elements.empty()) f += compute_slip_force(p, state, j, qd[j]);
    out.tau[j] = f;
  }
  return out;
}

FrictionState advance_friction_state(const std::array<JointFrictionParams, 3>& params, const FrictionState& state,
                                     const Eigen::Vector3d& qd, double dt) {
  FrictionState out = state;
  for (int j = 0; j < 3; ++j) {
    const auto& p = params[static_cast<std::size_t>(j)];
    if (p.coulomb_pos > 0.0 || p.coulomb_neg > 0.0)
      out.bristles[j] = advance_lugre_state(p.coulomb_pos, p.coulomb_neg, p.stiction_ratio, p.stribeck_velocity,
                                            p.bristle_stiffness, state.bristles[j], qd[j], dt);
    for (std::size_t i = 0; i < p.slip_elements.size(); ++i) {
      const double width = p.slip_elements[i][0];
      const Eigen::Index c = static_cast<Eigen::Index>(i);
      out.slip(j, c) = std::clamp(state.slip(j, c) + qd[j] * dt, -width, width);
    }
  }
  return out;
}

}  // namespace rcm::sim
