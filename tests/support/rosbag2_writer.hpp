#pragma once
// Writers of ROS 2 recordings (rosbag2) for tests and benchmarks: a
// rcm::Recording as the dVRK's JointState (and WrenchStamped) topics, in every
// storage layout rcm reads, so that the readers can be checked on round trips
// and timed on recordings of any size without ROS 2.
//
// Files are written as rosbag2 and the MCAP reference writer lay them out
// (mcap.dev spec, version 0; rosbag2's SQLite schemas), and streamed: a
// recording of any length needs memory for one chunk, not for the file.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"

namespace rcm::test {

struct Rosbag2WriteOptions {
  enum class Storage { sqlite3, mcap } storage = Storage::mcap;
  int sqlite_schema = 3;                  // 0 (before Humble, no schema table), 3 (Humble), 4 (Jazzy)
  int metadata_version = 5;               // metadata.yaml of a directory: 5 (Humble) .. 9 (Jazzy)
  std::string mcap_compression = "zstd";  // "", "lz4", "zstd"
  bool mcap_chunked = true;
  std::size_t mcap_chunk_bytes = std::size_t{1} << 20;  // uncompressed records per chunk
  bool mcap_summary = true;
  bool mcap_message_indexes = true;
  std::string topic = "/PSM1/measured_js";
  std::string force_topic = "/PSM1/body/measured_cf";  // written only when the recording has force
  std::vector<std::string> joint_names;  // empty: default_joint_names(num_joints)
  // header.stamp of sample k = time_origin_ns + llround(time[k] * 1e9): a
  // recording whose times lie on a 1 ns grid reads back to within 1e-9 s.
  std::int64_t time_origin_ns = 1700000000000000000;
  std::int64_t receive_delay_ns = 500000;  // receive (log) time = stamp + delay
  std::size_t split_every = 0;  // > 0: a directory with a new storage file every N joint samples
};

// The dVRK PSM's joint names for `num_joints` joints; joint_8... beyond the seven.
std::vector<std::string> default_joint_names(int num_joints);

// Writes `recording` as a bag directory (metadata.yaml and files named
// <dirname>_<i>.db3 / .mcap, replacing what the directory held) or, when `path`
// ends in .db3 or .mcap, as one bare file. One JointState per sample; with
// force, one WrenchStamped (frame_id "PSM1_base", zero torque) per sample at
// the same stamp. Throws std::invalid_argument for options that cannot be
// written (a split bare file, joint names that do not match) and
// std::runtime_error for I/O failures.
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
