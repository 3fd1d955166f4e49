#include "rcm/dynamics/torque_residual.hpp"

#include <fmt/format.h>

#include <cmath>

#include "rcm/common/error.hpp"

namespace rcm {

void check_torque_prediction(const Recording& recording, const Eigen::MatrixXd& tau_fs) {
  const Eigen::Index T = recording.time.size();
  if (recording.num_joints() < 3 || recording.effort.cols() < 3 || recording.effort.rows() != T)
    throw InputError(InputLocation::plain(recording.source, ""), "the recording needs at least 3 joints");
  if (tau_fs.rows() != T || tau_fs.cols() < 3)
    throw InputError(InputLocation::plain(recording.source, "tau_fs"),
                     fmt::format("the free-space torque prediction is {} x {}, expected {} x (>= 3), one row per "
                                 "sample of the recording",
                                 tau_fs.rows(), tau_fs.cols(), T));
  for (Eigen::Index t = 0; t < T; ++t)
    for (Eigen::Index j = 0; j < 3; ++j)
      if (!std::isfinite(tau_fs(t, j))) {
        const auto i = static_cast<std::size_t>(t);
        InputLocation where = InputLocation::plain(recording.source, fmt::format("tau_fs_{}", j + 1));
        where.line = i < recording.line.size() ? recording.line[i] : 0;
        throw InputError(where, fmt::format("the free-space torque prediction of sample {} is not finite", t));
      }
}

TorqueResidual compute_torque_residual(const Recording& recording, const Eigen::MatrixXd& tau_fs) {
  check_torque_prediction(recording, tau_fs);
  return recording.effort.leftCols<3>() - tau_fs.leftCols<3>();
}

}  // namespace rcm
