#pragma once
// Rosbag recordings: the sensor_msgs/JointState topic of a bag (the dVRK's CRTK
// /PSM1/measured_js) read into an rcm::Recording, held to the CSV reader's
// rules by the reader that every message format shares
// (io/message_recording.hpp), and optionally a geometry_msgs/WrenchStamped
// topic as the evaluation-only force columns.
//
// Time: header.stamp of each message. Only when the topic's first message has a
// zero stamp (a publisher that never sets it) is the bag's receive time used,
// and then for every message of that topic; a topic that mixes zero and
// non-zero stamps is an error. Recording::time is in seconds from the first
// sample's stamp (computed in integer nanoseconds, so differences are exact to
// 1 ns); the absolute origin is in BagReadInfo.
//
// Force (optional): WrenchStamped.wrench.force, taken as the force at the
// incision in the robot base frame (the session format's convention; no frame
// is transformed, header.frame_id is only reported), linearly interpolated at
// the joint samples' times. Joint samples up to one force period outside the
// force topic's span take its end value; beyond that it is an error.
//
// Every defect throws InputError naming the bag, the topic, the message index
// (0-based, in bag order, on that topic) and the field:
//   run.bag: /PSM1/measured_js message 1204 (t = 6.02 s): effort[2] ('outer_insertion'): expected a finite number, got nan

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "rcm/io/message_recording.hpp"

namespace rcm {

// The options of every message-based reader (io/message_recording.hpp).
// MessageTime::receive takes the bag's receive time for every message.
using BagReadOptions = TopicReadOptions;

struct BagReadInfo {
  std::vector<std::string> joint_names;  // the recording's joint order; empty when the messages carry no names
  std::int64_t time_origin_ns = 0;       // absolute time of sample 0 (header stamp or bag time)
  bool bag_time = false;                 // true: stamps were zero, the bag's receive time was used
  std::size_t messages = 0;              // JointState messages on the topic
  std::size_t force_messages = 0;
  std::string force_frame_id;
  bool force_bag_time = false;
};

// The bag as a stream of chunks (io/recording_reader.hpp), both topics read
// in one pass in bag-time order. rosbag_storage itself holds the bag's index
// in memory (an entry per message, tens of bytes each), which rcm cannot
// avoid through that library; rcm's own memory does not grow with the bag.
// Throws InputError as described below; opening checks the topics and reads
// up to the first JointState message.
class BagRecordingReader : public MessageRecordingReader {
 public:
  // What was read so far; complete once read_chunk() has returned false.
  const BagReadInfo& info() const;

 protected:
  std::size_t fill_chunk(Recording& chunk, std::size_t filled) override;

 private:
  friend std::unique_ptr<BagRecordingReader> open_bag_recording(const std::filesystem::path&, const BagReadOptions&,
                                                                std::size_t);
  BagRecordingReader(const std::filesystem::path& path, const BagReadOptions& options, std::size_t chunk_rows,
                     std::unique_ptr<BagReadInfo> info, std::unique_ptr<MessageSource> source);
  std::unique_ptr<BagReadInfo> info_;
  std::filesystem::path path_;
};
std::unique_ptr<BagRecordingReader> open_bag_recording(const std::filesystem::path& path,
                                                       const BagReadOptions& options = {},
                                                       std::size_t chunk_rows = kDefaultChunkRows);

// The whole recording. Throws InputError as described above (also for a file
// that is not a bag, a topic that is absent or of another type).
Recording load_bag_recording(const std::filesystem::path& path, const BagReadOptions& options = {},
                             BagReadInfo* info = nullptr);

// Makes load_recording() and open_recording() (and so every command, and
// sessions whose manifest names .bag files) read files ending in ".bag" with
// these options; the
// RecordingReadOptions of each call replace `options.read`.
void register_bag_recording_reader(const BagReadOptions& options = {});

}  // namespace rcm
