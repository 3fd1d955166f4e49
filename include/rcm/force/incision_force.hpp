#pragma once
// Force at the misaligned incision from the joint-torque residual (paper Eq. 6):
// f_inc_base = J_D^{-T} (tau - tau_fs), the force the instrument applies to the
// tissue, in the base frame.

#include <Eigen/Core>
#include <vector>

#include "rcm/io/recording.hpp"
#include "rcm/kinematics/incision.hpp"

namespace rcm {

struct IncisionForceSample {
  Eigen::Vector3d f_inc_base = Eigen::Vector3d::Zero();
  double theta = 0.0;           // rad
  double shaft_distance = 0.0;  // D sec(theta), m
  JacobianCondition condition;
};

// One sample. dtau = tau - tau_fs of the first three joints (N m, N m, N).
// For a singular J_D the force is set to NaN and the status says so: a huge
// number is never returned as if it were a measurement. Allocation free.
IncisionForceSample compute_incision_force(const IncisionFrame& incision,
                                           const Eigen::Vector3d& q, double D,
                                           const Eigen::Vector3d& dtau,
                                           const JacobianCheckOptions& options = {});

struct IncisionForceSeries {
  Eigen::MatrixXd f_inc_base;  // T x 3
  Eigen::VectorXd theta;       // T
  Eigen::VectorXd condition;   // T
  std::vector<JacobianStatus> status;
  std::size_t num_ill_conditioned = 0;
  std::size_t num_singular = 0;
};

// A whole recording; tau_fs is T x (>= 3), the free-space prediction.
IncisionForceSeries compute_incision_force_series(const IncisionFrame& incision,
                                                  const Recording& recording,
                                                  const Eigen::MatrixXd& tau_fs, double D,
                                                  const JacobianCheckOptions& options = {});

}  // namespace rcm
