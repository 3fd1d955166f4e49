#pragma once
// What the rosbag2 tests share (test_io_rosbag2.cpp, test_io_rosbag2_cli.cpp):
// temporary directories, hand-made JointState and WrenchStamped messages, and
// located-error checks.

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "io/rosbag2/cdr.hpp"
#include "rcm/common/error.hpp"
#include "support/rosbag2_writer.hpp"
#include "temp_dir.hpp"

namespace rcm::test::rosbag2 {

namespace fs = std::filesystem;

// Temporary directories of this file are named rcm_test_rosbag2_<n>.
struct TempDir : rcm::test::TempDir {
  TempDir() : rcm::test::TempDir("rcm_test_rosbag2_") {}
};

inline const std::vector<std::string> kNames = {"outer_yaw", "outer_pitch", "outer_insertion", "outer_roll"};

inline rcm::cdr::JointState joint_state(int k, std::int64_t stamp_ns) {
  rcm::cdr::JointState m;
  m.header.sec = static_cast<std::int32_t>(stamp_ns / 1000000000);
  m.header.nanosec = static_cast<std::uint32_t>(stamp_ns % 1000000000);
  m.name = kNames;
  for (int j = 0; j < 4; ++j) {
    m.position.push_back(0.1 * (j + 1) + 0.001 * k);
    m.velocity.push_back(0.01 * (j + 1));
    m.effort.push_back(-0.05 * (j + 1) + 0.0001 * k);
  }
  return m;
}

inline rcm::cdr::WrenchStamped wrench(int k, std::int64_t stamp_ns) {
  rcm::cdr::WrenchStamped m;
  m.header.sec = static_cast<std::int32_t>(stamp_ns / 1000000000);
  m.header.nanosec = static_cast<std::uint32_t>(stamp_ns % 1000000000);
  m.header.frame_id = "PSM1";
  m.force[0] = 1.0 + 0.01 * k;
  m.force[1] = -2.0;
  m.force[2] = 0.5;
  return m;
}

using Topic = rcm::test::BagTopic;
using Message = rcm::test::BagMessage;
using rcm::test::metadata_yaml;
using rcm::test::write_db3;

inline void exec(sqlite3* db, const std::string& sql) {
  char* err = nullptr;
  ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err), SQLITE_OK) << (err ? err : "") << "\n" << sql;
}

constexpr std::int64_t kT0 = 1700000000000000000;  // ns
constexpr std::int64_t kDt = 10000000;             // 100 Hz

// `n` joint states (topic 1) and `n / 2` wrenches at half the rate (topic 2);
// receive time 1 ms after the stamp.
inline std::vector<Message> make_messages(int n, int first = 0) {
  std::vector<Message> out;
  for (int k = first; k < first + n; ++k) {
    const std::int64_t t = kT0 + k * kDt;
    out.push_back({1, t + 1000000, rcm::cdr::encode(joint_state(k, t))});
    if (k % 2 == 0) out.push_back({2, t + 1000000, rcm::cdr::encode(wrench(k, t))});
  }
  return out;
}

inline const std::vector<Topic> kTopics = {{"/PSM1/measured_js", "sensor_msgs/msg/JointState"},
                                    {"/PSM1/body/measured_cf", "geometry_msgs/msg/WrenchStamped"}};

inline void expect_error(const std::function<void()>& f, const std::vector<std::string>& needles) {
  try {
    f();
    ADD_FAILURE() << "accepted; expected an error containing '" << needles.front() << "'";
  } catch (const rcm::InputError& e) {
    for (const auto& n : needles)
      EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << "message: " << e.what() << "\nmissing: " << n;
  }
}

inline void write_text(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

}  // namespace rcm::test::rosbag2
