#pragma once
// Shared by the ROS tests: the fixture's simulated session, writing a recording
// as a bag the way the dVRK would record it, and running the rcm CLI.

#include <rosbag/bag.h>
#include <geometry_msgs/WrenchStamped.h>
#include <sensor_msgs/JointState.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include "rcm/io/recording.hpp"

namespace rcm::test {

// Made by make_test_session.cmake (CTest fixture live_test_session).
inline std::filesystem::path get_fixture_dir() { return RCM_ROS_TEST_DIR; }
inline std::filesystem::path get_session_manifest() { return get_fixture_dir() / "session" / "session.json"; }
inline std::filesystem::path get_model_file() { return get_fixture_dir() / "model.json"; }
// A trial with a hybrid offset and forces above 10 N.
inline std::filesystem::path get_trial_csv() { return get_fixture_dir() / "session" / "D30_r10_15.csv"; }
inline bool fixture_present() {
  return std::filesystem::exists(get_session_manifest()) && std::filesystem::exists(get_model_file());
}
inline const char* kFixtureHint = "the fixture is missing: run the tests through ctest (fixture live_test_session)";

// Stamps an absolute epoch-like time base + t, in whole nanoseconds.
constexpr std::int64_t kStampBaseNs = 1700000000LL * 1000000000LL;
inline std::int64_t to_stamp_ns(double t) { return kStampBaseNs + std::llround(t * 1e9); }

inline std::vector<std::string> make_joint_names(int n) {
  static const char* dvrk[] = {"outer_yaw", "outer_pitch", "outer_insertion", "outer_roll", "outer_wrist_pitch",
                               "outer_wrist_yaw", "jaw"};
  std::vector<std::string> names;
  for (int j = 0; j < n; ++j) names.push_back(j < 7 ? dvrk[j] : "joint_" + std::to_string(j + 1));
  return names;
}

// Sample k of `rec` as the dVRK publishes it; `order` permutes the joints (empty: as recorded).
inline sensor_msgs::JointState make_joint_state(const Recording& rec, Eigen::Index k, const std::vector<int>& order = {},
                                                bool with_names = true) {
  sensor_msgs::JointState m;
  m.header.stamp.fromNSec(static_cast<std::uint64_t>(to_stamp_ns(rec.time(k))));
  const auto names = make_joint_names(rec.num_joints());
  for (int i = 0; i < rec.num_joints(); ++i) {
    const int j = order.empty() ? i : order[static_cast<std::size_t>(i)];
    if (with_names) m.name.push_back(names[static_cast<std::size_t>(j)]);
    m.position.push_back(rec.position(k, j));
    m.velocity.push_back(rec.velocity(k, j));
    m.effort.push_back(rec.effort(k, j));
  }
  return m;
}

// The recording as a bag: JointState on `topic` (bag time 0.3 ms after the
// stamp, as a recorder on the same machine), the force columns as WrenchStamped
// in the base frame on `force_topic` when present.
inline void write_bag(const std::filesystem::path& path, const Recording& rec, const std::string& topic,
                      const std::string& force_topic = "") {
  rosbag::Bag bag;
  bag.open(path.string(), rosbag::bagmode::Write);
  for (Eigen::Index k = 0; k < rec.time.size(); ++k) {
    const sensor_msgs::JointState m = make_joint_state(rec, k);
    bag.write(topic, m.header.stamp + ros::Duration(0.0003), m);
    if (!force_topic.empty() && rec.force) {
      geometry_msgs::WrenchStamped w;
      w.header.stamp = m.header.stamp;
      w.header.frame_id = "PSM1_base";
      w.wrench.force.x = (*rec.force)(k, 0);
      w.wrench.force.y = (*rec.force)(k, 1);
      w.wrench.force.z = (*rec.force)(k, 2);
      bag.write(force_topic, m.header.stamp + ros::Duration(0.0005), w);
    }
  }
  bag.close();
}

struct CliRun {
  int status = -1;
  std::string out, err;
};
// Runs `rcm ARGS`, stdout and stderr captured.
inline CliRun run_cli(const std::string& args) {
  const auto err_file = std::filesystem::temp_directory_path() / ("rcm_ros_test_err_" + std::to_string(::getpid()));
  const std::string cmd = std::string(RCM_CLI_PATH) + " " + args + " 2> " + err_file.string();
  CliRun r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  std::array<char, 4096> buf;
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(p);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(err_file);
  std::stringstream ss;
  ss << in.rdbuf();
  r.err = ss.str();
  std::filesystem::remove(err_file);
  return r;
}

}  // namespace rcm::test
