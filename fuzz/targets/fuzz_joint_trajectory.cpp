// The joint trajectory CSV (time, position_i, velocity_i) that `rcm excite`
// writes and `rcm simulate --free-space-trajectory` reads: what
// parse_joint_trajectory accepts has the stated invariants and survives a
// save and a read back unchanged.
#include <string>

#include "fuzz_support.hpp"
#include "rcm/io/joint_trajectory.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  rcm::JointTrajectory trajectory;
  if (!rcm::fuzz::accepts([&] { trajectory = rcm::parse_joint_trajectory(text, "fuzz.csv"); })) return 0;
  RCM_FUZZ_CHECK(trajectory.num_joints() >= 3 && trajectory.num_samples() >= 1);
  RCM_FUZZ_CHECK(trajectory.position.rows() == trajectory.time.size() &&
                 trajectory.velocity.rows() == trajectory.time.size() &&
                 trajectory.velocity.cols() == trajectory.position.cols());
  RCM_FUZZ_CHECK(trajectory.time.allFinite() && trajectory.position.allFinite() && trajectory.velocity.allFinite());
  for (Eigen::Index t = 1; t < trajectory.time.size(); ++t) RCM_FUZZ_CHECK(trajectory.time[t] > trajectory.time[t - 1]);
  RCM_FUZZ_CHECK(trajectory.line.size() == trajectory.num_samples());
  const auto path = rcm::fuzz::scratch_dir() / "trajectory.csv";
  rcm::save_joint_trajectory(path, trajectory);
  const rcm::JointTrajectory back = rcm::load_joint_trajectory(path);
  RCM_FUZZ_CHECK(back.time == trajectory.time);
  RCM_FUZZ_CHECK(back.position == trajectory.position);
  RCM_FUZZ_CHECK(back.velocity == trajectory.velocity);
  return 0;
}
