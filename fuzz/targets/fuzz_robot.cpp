// Robot kinematics files (rcm-robot/1, PsmModel::load). An accepted robot's
// forward kinematics is computed at its joint limits and mid-range, and the
// limit check is run as a session's q0 is checked.
#include <optional>

#include "fuzz_support.hpp"
#include "rcm/kinematics/psm_model.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  const auto path = fuzz::write_input("robot.json", data, size);
  std::optional<PsmModel> model;
  if (!fuzz::accepts([&] { model.emplace(PsmModel::load(path)); })) return 0;
  RCM_FUZZ_CHECK(model->num_joints() >= 3);
  KinematicsData kin;
  const auto& j = model->joints();
  for (double s : {0.0, 0.5, 1.0}) {
    Eigen::Vector3d q;
    for (int i = 0; i < 3; ++i) q[i] = j[i].q_min + s * (j[i].q_max - j[i].q_min);
    compute_forward_kinematics(*model, kin, q);
    InputLocation where;
    where.file = "q";
    (void)fuzz::accepts([&] { model->check_within_limits(q, where); });
  }
  (void)model->tool_offset();
  return 0;
}
