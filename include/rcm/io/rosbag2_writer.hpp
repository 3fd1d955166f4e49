#pragma once
// A recording as a ROS 2 bag (rosbag2), without ROS 2: the dVRK's JointState
// topic (and a WrenchStamped force topic when the recording has force), as
// `ros2 bag record` lays it out, in either storage: MCAP (rosbag2's default
// from Iron on) or SQLite (.db3, Humble's default). `rcm convert REC OUT.mcap`
// writes one; every reader of rcm reads it back (io/rosbag2.hpp).
//
// The files are streamed: a recording of any length needs memory for one MCAP
// chunk, not for the file.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"

namespace rcm {

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
  std::vector<std::string> joint_names;  // empty: get_dvrk_joint_names(num_joints)
  // header.stamp of sample k = time_origin_ns + llround(time[k] * 1e9): a
  // recording whose times lie on a 1 ns grid reads back to within 1e-9 s. A
  // zero stamp marks invalid data on ROS 2, hence an origin past the epoch.
  std::int64_t time_origin_ns = 1700000000000000000;
  // The log (receive) time of each message: its stamp plus this.
  std::int64_t receive_delay_ns = 0;
  std::size_t split_every = 0;  // > 0: a directory with a new storage file every N joint samples
};

// The dVRK PSM's joint names for `num_joints` joints; joint_8... beyond the seven.
std::vector<std::string> get_dvrk_joint_names(int num_joints);

// Writes `recording` as a bag directory (metadata.yaml and files named
// <dirname>_<i>.db3 / .mcap) or, when `path` ends in .db3 or .mcap, as one
// bare file. One JointState per sample; with force, one WrenchStamped
// (frame_id "PSM1_base", zero torque) per sample at the same stamp.
// A bare file appears whole or not at all (io/atomic_file.hpp); a directory is
// written beside its final name and renamed into place, and must not exist
// yet or be empty. Throws InputError for a recording that cannot be written
// (a stamp that does not fit builtin_interfaces/Time, times closer than 1 ns),
// a directory that holds files, or a failed write; std::invalid_argument for
// options that cannot be written (a split bare file, an extension that does
// not match the storage, joint names that do not match).
void save_rosbag2_recording(const std::filesystem::path& path, const Recording& recording,
                            const Rosbag2WriteOptions& options = {});

}  // namespace rcm
