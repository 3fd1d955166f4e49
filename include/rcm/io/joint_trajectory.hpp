#pragma once
// A joint trajectory to play on the arm: time-stamped positions and
// velocities of N >= 3 joints, without efforts (what `rcm excite` writes and
// what `rcm simulate --free-space-trajectory` and a dVRK's CRTK servo_jp
// stream take). Its CSV follows the recording's rules (docs/formats.md,
// "Joint trajectory"): header on line 1 naming `time`, `position_1..N`,
// `velocity_1..N` in any order, every cell a finite number, time strictly
// increasing; other columns are ignored.

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace rcm {

struct JointTrajectory {
  std::string source;        // file path (for messages) or a description
  Eigen::VectorXd time;      // s, strictly increasing, size T
  Eigen::MatrixXd position;  // T x N: rad, rad, m, ...
  Eigen::MatrixXd velocity;  // T x N: rad/s, rad/s, m/s, ...
  std::vector<std::size_t> line;  // 1-based source line of every sample (empty in memory)

  std::size_t num_samples() const { return static_cast<std::size_t>(time.size()); }
  int num_joints() const { return static_cast<int>(position.cols()); }
};

// Reads and checks a trajectory; throws InputError naming file, line and
// column for a missing column, a cell that is not a finite number, time that
// does not increase, fewer than 3 joints or no rows.
JointTrajectory parse_joint_trajectory(const std::string& text, const std::string& source);
JointTrajectory load_joint_trajectory(const std::filesystem::path& path);

// Writes `time, position_1..N, velocity_1..N` atomically (io/atomic_file.hpp),
// numbers in their shortest round-trip form; the trajectory is checked first
// (sizes, finite values, increasing time: InputError naming its source).
void save_joint_trajectory(const std::filesystem::path& path, const JointTrajectory& trajectory);

}  // namespace rcm
