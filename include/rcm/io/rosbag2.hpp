#pragma once
// ROS 2 recordings (rosbag2), read without ROS 2: a bag directory
// (metadata.yaml, versions 1 to 9, and its files, split bags in order), or a
// bare .db3 (SQLite storage) or .mcap (MCAP storage) file. Messages must be in
// the "cdr" serialization; the JointState topic is decoded as
// sensor_msgs/msg/JointState and the force topic as
// geometry_msgs/msg/WrenchStamped, any other type is an error naming it.
//
// Time (integer ns throughout; Recording::time in s from the first sample):
// - MessageTime::header (default): header.stamp. A zero stamp marks invalid
//   data (the dVRK since cisst-ros 4.0): such messages are skipped and counted
//   (Rosbag2ReadInfo), and a topic with no valid message is an error.
// - MessageTime::receive: the recorder's receive time (SQLite timestamp, MCAP
//   log_time), for every message.
//
// Every message is held to the same rules as a CSV row or a ROS 1 bag message
// (io/message_recording.hpp), and errors name the file, the topic, the message
// index (0-based on that topic, across the bag's files) and the field. An MCAP
// file cut off by a crash (no footer) is read up to its last complete record
// with a warning; every other defect of a file is an error.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "rcm/io/message_recording.hpp"

namespace rcm {

struct Rosbag2ReadInfo {
  std::string storage;                   // "sqlite3" or "mcap"
  std::vector<std::string> files;        // the storage files read, in order
  int metadata_version = 0;              // 0: no metadata.yaml (a bare file)
  int sqlite_schema = 0;                 // SQLite schema version (0: before Humble, or MCAP)
  std::string ros_distro;                // as recorded, when it is
  std::string topic, force_topic;        // the topics read (force_topic empty: none)
  bool receive_time = false;             // MessageTime::receive
  std::vector<std::string> joint_names;  // the recording's joint order; empty when the messages carry no names
  std::int64_t time_origin_ns = 0;       // absolute time of sample 0
  std::size_t messages = 0;              // JointState messages on the topic
  std::size_t zero_stamp_messages = 0;   // of them, skipped for a zero header.stamp
  std::size_t force_messages = 0;
  std::size_t force_zero_stamp_messages = 0;
  std::string force_frame_id;
  std::vector<std::string> warnings;     // e.g. an MCAP file cut off by a crash
};

// What a rosbag2 recording holds, whatever its topics: for `rcm inspect`,
// also when the JointState topic is missing.
struct Rosbag2Contents {
  std::string storage;                  // "sqlite3" or "mcap"
  std::vector<std::string> files;
  int metadata_version = 0, sqlite_schema = 0;
  std::string ros_distro;
  std::string layout;                   // e.g. "SQLite schema 4", "MCAP, 5 chunks, with summary"
  struct Topic {
    std::string name, type, serialization;
    std::size_t messages = 0;
    std::int64_t first_ns = 0, last_ns = 0;  // receive time
    double get_rate_hz() const {
      return messages > 1 && last_ns > first_ns ? static_cast<double>(messages - 1) * 1e9 / static_cast<double>(last_ns - first_ns) : 0.0;
    }
  };
  std::vector<Topic> topics;            // by name
  std::vector<std::string> warnings;
};
// Reads every file of the recording (every message of an MCAP file). Throws
// InputError for a file that cannot be read, as load_rosbag2_recording.
Rosbag2Contents list_rosbag2_contents(const std::filesystem::path& path);

// True when `path` is read as a rosbag2 recording: a directory, or a file
// ending in .db3 or .mcap.
bool is_rosbag2_path(const std::filesystem::path& path);

// The recording as a stream of chunks (io/recording_reader.hpp): the bag's
// files read in order, an MCAP chunk or an SQLite row at a time. Throws
// InputError as described above; opening reads up to the first JointState
// sample.
class Rosbag2RecordingReader : public MessageRecordingReader {
 public:
  struct Opening;
  ~Rosbag2RecordingReader() override;
  // What was read so far; complete once read_chunk() has returned false.
  const Rosbag2ReadInfo& info() const;

 private:
  friend std::unique_ptr<Rosbag2RecordingReader> open_rosbag2_recording(const std::filesystem::path&,
                                                                        const TopicReadOptions&, std::size_t);
  Rosbag2RecordingReader(const std::filesystem::path& path, const TopicReadOptions& options, std::size_t chunk_rows,
                         std::unique_ptr<Opening> opening);
  std::unique_ptr<Opening> opening_;
};
std::unique_ptr<Rosbag2RecordingReader> open_rosbag2_recording(const std::filesystem::path& path,
                                                               const TopicReadOptions& options = {},
                                                               std::size_t chunk_rows = kDefaultChunkRows);

// The whole recording (every chunk). Throws InputError as described above.
Recording load_rosbag2_recording(const std::filesystem::path& path, const TopicReadOptions& options = {},
                                 Rosbag2ReadInfo* info = nullptr);

}  // namespace rcm
