#include "rcm/sim/plant.hpp"

#include <Eigen/Cholesky>
#include <cmath>

namespace rcm::sim {

Plant::Plant(const ArmParams& arm_params, const std::array<JointFrictionParams, 3>& friction_params)
    : arm(arm_params), transmission(arm_params.transmission), friction(friction_params) {
  for (int j = 0; j < 3; ++j) {
    const auto& t = transmission[static_cast<std::size_t>(j)];
    rotor_inertia[j] = t.rotor_inertia;
    link_share[j] = t.friction_link_share;
    compliant[static_cast<std::size_t>(j)] = t.stiffness > 0.0;
  }
}

PlantState make_plant_state_at_rest(const Plant& plant, const Eigen::Vector3d& q) {
  PlantState s;
  s.q = q;
  s.qm = q;
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  const Eigen::Vector3d g = compute_inverse_dynamics(plant.arm, q, zero, zero, true);
  for (int j = 0; j < 3; ++j)
    if (plant.compliant[static_cast<std::size_t>(j)])
      s.qm[j] += g[j] / plant.transmission[static_cast<std::size_t>(j)].stiffness;
  return s;
}

PlantAcceleration compute_plant_acceleration(const Plant& plant, const PlantState& s, const Eigen::Vector3d& tau,
                                             const Eigen::Vector3d& tau_ext) {
  PlantAcceleration a;
  // Each side carries its share of the same friction law; the friction states of
  // the two sides follow their own velocities.
  const Eigen::Vector3d f_motor = compute_friction(plant.friction, s.friction_motor, s.qmd).tau;
  a.friction_motor = (Eigen::Vector3d::Ones() - plant.link_share).cwiseProduct(f_motor);
  if (plant.link_share.maxCoeff() > 0.0)
    a.friction_link = plant.link_share.cwiseProduct(compute_friction(plant.friction, s.friction_link, s.qd).tau);

  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  const Eigen::Vector3d h = compute_inverse_dynamics(plant.arm, s.q, s.qd, zero, true);
  const Eigen::Matrix3d M = compute_mass_matrix(plant.arm, s.q);
  Eigen::Matrix3d M_drive = M;
  Eigen::Vector3d drive, friction_on_link;
  for (int j = 0; j < 3; ++j) {
    const auto& t = plant.transmission[static_cast<std::size_t>(j)];
    if (plant.compliant[static_cast<std::size_t>(j)]) {
      a.cable[j] = t.stiffness * (s.qm[j] - s.q[j]) + t.damping * (s.qmd[j] - s.qd[j]);
      drive[j] = a.cable[j];
      friction_on_link[j] = a.friction_link[j];
    } else {
      M_drive(j, j) += plant.rotor_inertia[j];
      drive[j] = tau[j];
      friction_on_link[j] = a.friction_motor[j] + a.friction_link[j];
    }
  }
  a.qdd = M_drive.llt().solve(drive - h - friction_on_link - tau_ext);
  for (int j = 0; j < 3; ++j)
    a.qmdd[j] = plant.compliant[static_cast<std::size_t>(j)]
                    ? (tau[j] - a.cable[j] - a.friction_motor[j]) / plant.rotor_inertia[j]
                    : a.qdd[j];
  a.tau_fs = M * a.qdd + h + (a.friction_link + a.friction_motor) + plant.rotor_inertia.cwiseProduct(a.qmdd);
  return a;
}

void advance_plant_state(const Plant& plant, PlantState& s, const PlantAcceleration& a, double dt) {
  s.qd += dt * a.qdd;
  s.q += dt * s.qd;
  for (int j = 0; j < 3; ++j) {
    if (plant.compliant[static_cast<std::size_t>(j)]) {
      s.qmd[j] += dt * a.qmdd[j];
      s.qm[j] += dt * s.qmd[j];
    } else {
      s.qmd[j] = s.qd[j];
      s.qm[j] = s.q[j];
    }
  }
  s.friction_motor = advance_friction_state(plant.friction, s.friction_motor, s.qmd, dt);
  if (plant.link_share.maxCoeff() > 0.0)
    s.friction_link = advance_friction_state(plant.friction, s.friction_link, s.qd, dt);
}

double compute_plant_energy(const Plant& plant, const PlantState& s) {
  double e = compute_kinetic_energy(plant.arm, s.q, s.qd) + compute_potential_energy(plant.arm, s.q);
  for (int j = 0; j < 3; ++j) {
    e += 0.5 * plant.rotor_inertia[j] * s.qmd[j] * s.qmd[j];
    if (plant.compliant[static_cast<std::size_t>(j)]) {
      const double stretch = s.qm[j] - s.q[j];
      e += 0.5 * plant.transmission[static_cast<std::size_t>(j)].stiffness * stretch * stretch;
    }
  }
  return e;
}

double compute_cable_mode_hz(const Plant& plant, const Eigen::Vector3d& q, int joint) {
  const double k = plant.transmission[static_cast<std::size_t>(joint)].stiffness;
  if (k <= 0.0) return 0.0;
  const Eigen::Matrix3d M = compute_mass_matrix(plant.arm, q);
  return std::sqrt(k / M(joint, joint)) / (2.0 * M_PI);
}

}  // namespace rcm::sim
