#pragma once
// Bags for tests and benchmarks: rcm's own writer (rcm/io/rosbag2_writer.hpp)
// with the tests' defaults, and a raw layer for the defects and layouts that
// writer does not make.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"
#include "rcm/io/rosbag2_writer.hpp"

namespace rcm::test {

using Rosbag2WriteOptions = rcm::Rosbag2WriteOptions;

inline std::vector<std::string> default_joint_names(int num_joints) { return rcm::get_dvrk_joint_names(num_joints); }

// rcm::save_rosbag2_recording over whatever `path` held before (a test writes
// the same bag again with other options).
void write_rosbag2(const std::filesystem::path& path, const rcm::Recording& recording,
                   const Rosbag2WriteOptions& options = {});

// The raw layer, for tests that need defects or layouts write_rosbag2 does not make.

struct BagTopic {
  std::string name, type, format = "cdr";
};
struct BagMessage {
  int topic_id = 0;  // 1-based index in the topic list
  std::int64_t receive_ns = 0;
  std::vector<std::uint8_t> data;
};

// A .db3 as rosbag2 writes it: schema 0 before Humble (no schema table; `qos`
// adds the offered_qos_profiles column, as Foxy wrote it), 3 Humble, 4 Jazzy.
// Messages are stored in the given order. Replaces an existing file.
void write_db3(const std::filesystem::path& path, int schema, const std::vector<BagTopic>& topics,
               const std::vector<BagMessage>& messages, bool qos = true);

// A minimal metadata.yaml naming `files` (relative to the bag directory).
std::string metadata_yaml(int version, const std::string& storage, const std::vector<std::string>& files);

}  // namespace rcm::test
