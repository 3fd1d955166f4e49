#pragma once
// The torque residual dtau = tau - tau_fs of the first three joints (N m, N m,
// N), one row per sample of a recording: the torque the free-space model leaves
// unexplained, which the incision force explains. Every estimator starts from
// it (the force series, the tissue pairs, the three-step holds and coaxial
// solve, the joint samples); the online path forms the same difference sample
// by sample.

#include <Eigen/Core>

#include "rcm/io/recording.hpp"

namespace rcm {

using TorqueResidual = Eigen::Matrix<double, Eigen::Dynamic, 3>;

// Throws InputError naming the recording's file when tau_fs does not have one
// row of at least 3 values per sample or the recording has fewer than 3
// joints, and its line and field tau_fs_j for a prediction that is not finite.
void check_torque_prediction(const Recording& recording, const Eigen::MatrixXd& tau_fs);

// check_torque_prediction, then the residual.
TorqueResidual compute_torque_residual(const Recording& recording, const Eigen::MatrixXd& tau_fs);

}  // namespace rcm
