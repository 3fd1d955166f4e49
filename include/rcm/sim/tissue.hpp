#pragma once
// The phantom: a pad whose plane lies at the coaxial offset D along z3(q0), with
// the incision anchored at R_base_inc [delta_r_x, delta_r_y, D]. Where the shaft
// crosses the pad (s = D sec(theta) from the RCM along z3(q)) it stretches the
// incision by u = p_cross - p_anchor, within the pad plane. The force the
// instrument applies to the tissue (contract sign) is
//   f = g(|u|) u/|u| + c du/dt + F_axial z3,
// applied at the shaft's material point at the crossing, so the joints feel
// J_D^T f with J_D = [s dz3/dq1, s dz3/dq2, z3].

#include <Eigen/Core>

#include "rcm/sim/sim_config.hpp"

namespace rcm::sim {

// Immutable: one docking configuration and one misalignment.
struct TissueModel {
  TissueParams params;
  Eigen::Vector3d q0 = Eigen::Vector3d::Zero();
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();  // [dr_x, dr_y, D], incision frame
  Eigen::Matrix3d R_base_inc = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p_anchor_base = Eigen::Vector3d::Zero();
  // How fast the incision moves relative to the RCM (incision frame, m/s): a
  // moving patient or a moving software RCM. The pad plane moves with D, and
  // the damping and the axial friction see the shaft relative to the tissue.
  Eigen::Vector3d misalignment_rate_m_per_s = Eigen::Vector3d::Zero();

  TissueModel(const TissueParams& p, const Eigen::Vector3d& q0,
              const Eigen::Vector3d& misalignment_m);
  double coaxial_offset() const { return misalignment_m.z(); }
};

// g(x) of the elastic law (N), x >= 0 in m.
double compute_tissue_law(const TissueParams& params, double stretch_m);

struct TissueOutput {
  Eigen::Vector3d f_inc_base = Eigen::Vector3d::Zero();  // on the tissue, base frame, N
  Eigen::Vector3d tau = Eigen::Vector3d::Zero();         // J_D^T f: what the actuators must add
  Eigen::Matrix3d J_inc_base = Eigen::Matrix3d::Zero();
  Eigen::Vector3d p_cross_base = Eigen::Vector3d::Zero();
  Eigen::Vector3d stretch_base = Eigen::Vector3d::Zero();
  double shaft_distance = 0.0;  // s = D sec(theta)
  double theta = 0.0;
  double axial_velocity = 0.0;  // shaft relative to the tissue along z3, m/s
  double axial_force = 0.0;     // N, along z3 on the tissue
  double axial_zdot = 0.0;
};

// Throws std::domain_error when the shaft is too flat to the pad
// (cos(theta) < params.min_pad_cosine): the simulated motion is invalid there.
TissueOutput compute_tissue_force(const TissueModel& model, const Eigen::Vector3d& q,
                                  const Eigen::Vector3d& qd, double axial_z);
double advance_tissue_state(const TissueModel& model, double axial_z, double axial_velocity,
                            double dt);

}  // namespace rcm::sim
