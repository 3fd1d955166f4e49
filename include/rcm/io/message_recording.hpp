#pragma once
// A recording assembled from messages: what every message-based reader (ROS 1
// bags, rosbag2 SQLite and MCAP) shares once it has decoded a message, so that
// all of them hold a JointState topic to the CSV reader's rules, word their
// errors alike, and stream (io/recording_reader.hpp).
//
// - A storage format gives its messages as a MessageSource: the JointState and
//   WrenchStamped messages of the two topics in recording order, each with the
//   time its reader chose (header stamp or receive time, integer ns).
// - MessageRecordingReader turns them into chunks of samples. Each JointState
//   message is held to JointStateMap's rules (JointStateSampler); time is in
//   seconds from the first valid sample (exact to 1 ns); repeated samples are
//   counted and dropped under --dedupe; time increases strictly.
// - The force topic (geometry_msgs/WrenchStamped): force at the incision in
//   the base frame (the session format's convention; frame_id is only
//   reported), linearly interpolated at the joint samples' times. Joint
//   samples up to one median force period outside the force topic's span take
//   its end value; beyond that it is an error. A joint sample waits until the
//   force topic has passed its time: memory holds the samples between the two
//   topics' positions in the file (milliseconds of data in a recorder's
//   bag), never the recording.
//
// Errors name the file, the topic, the message index (0-based, in recording
// order, on that topic), its time when known, and the field:
//   run.mcap: /PSM1/measured_js message 1204 (t = 6.02 s): effort[2] ('outer_insertion'): expected a finite number, got nan

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "rcm/io/joint_state_map.hpp"
#include "rcm/io/recording_reader.hpp"

namespace rcm {

inline constexpr const char* kDefaultJointStateTopic = "/PSM1/measured_js";

// The clock a message recording's time comes from.
enum class MessageTime {
  header,   // header.stamp (the dVRK's; zero marks invalid data in rosbag2 recordings)
  receive,  // the time the recorder received the message
};

// What the message-based readers are asked for; one struct for ROS 1 and ROS 2.
struct TopicReadOptions {
  std::string topic = kDefaultJointStateTopic;  // sensor_msgs/JointState
  std::string force_topic;                      // geometry_msgs/WrenchStamped; empty: no force columns
  // Joint order of the recording by name; empty: the first message's order
  // (by its names, or positional when it has none).
  std::vector<std::string> joint_names;
  MessageTime time = MessageTime::header;
  RecordingReadOptions read;  // dedupe and min_joints apply; assumed_rate_hz is ignored (messages carry time)
};

// `options` for one recording read with `read`: `read` replaces options.read,
// and the session's topics it carries (read.joint_topic, read.force_topic)
// replace options' topics unless the command line named them (`keep_topic`,
// `keep_force_topic`).
TopicReadOptions with_session_topics(TopicReadOptions options, const RecordingReadOptions& read,
                                     bool keep_topic = false, bool keep_force_topic = false);

// "/PSM1/measured_js message 12 (t = 0.12 s)"; t relative to `origin_ns`, left
// out when unknown.
std::string describe_message_place(const std::string& topic, std::size_t index, std::optional<std::int64_t> t_ns,
                                   std::int64_t origin_ns);

// The checks of one JointState topic, message by message.
class JointStateSampler {
 public:
  // `time_label` names the clock in errors ("header.stamp", "bag time", "receive time").
  JointStateSampler(std::string file, std::string topic, const TopicReadOptions& options, std::string time_label);

  // Message `index` of the topic at `t_ns`. Throws InputError for a time outside
  // [0, 2^62) ns (1970 to 2116), a message the joint map rejects, a first
  // message with too few joints, or a time that does not increase strictly
  // over the last kept sample. Returns true when the message is a sample of
  // the recording (false: a repeat dropped under --dedupe); its values are
  // then get_values() and its time get_time_ns().
  bool add(std::size_t index, std::int64_t t_ns, const JointStateView& message);

  int num_joints() const { return map_.num_joints(); }
  // The recording's joint order; empty when the messages carry no names.
  const std::vector<std::string>& joint_names() const { return map_.names(); }
  std::size_t messages() const { return messages_; }
  std::size_t repeated() const { return repeated_; }
  // Absolute time (ns) of sample 0: the first message added.
  std::int64_t time_origin_ns() const { return origin_ns_; }
  // The last message added: position, velocity, effort (num_joints() each).
  const std::vector<double>& get_values() const { return values_; }
  std::int64_t get_time_ns() const { return last_ns_; }

 private:
  std::string file_, topic_, time_label_;
  TopicReadOptions options_;
  JointStateMap map_;
  JointStateMap::Workspace ws_;
  std::vector<double> values_, previous_;
  std::size_t messages_ = 0, repeated_ = 0;
  std::int64_t origin_ns_ = 0, last_ns_ = 0;
  // The last kept sample, for time order.
  bool has_kept_ = false;
  std::int64_t kept_ns_ = 0;
  std::size_t kept_index_ = 0;
};

// One message of a recording as a storage format's reader gives it.
struct RecordingMessage {
  enum class Topic { joints, force } topic = Topic::joints;
  std::size_t index = 0;      // on its topic, 0-based, in recording order
  std::int64_t t_ns = 0;      // the time the reader chose
  std::optional<JointStateView> joints;  // Topic::joints: valid until the next call
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // Topic::force
};

// The messages of the JointState topic and, when asked, the force topic of one
// recording, in recording order (the order of the storage, which recorders
// write by receive time).
class MessageSource {
 public:
  virtual ~MessageSource() = default;
  // The next message; false at the end. Messages a format skips (a zero
  // header.stamp in rosbag2) are counted by the source, not returned.
  virtual bool next(RecordingMessage& message) = 0;
  // The clock of `topic` in errors ("header.stamp", "bag time", "receive
  // time"), known once its first message has been returned.
  virtual std::string get_time_label(RecordingMessage::Topic topic) const = 0;
  // Called once next() has returned false: what only the end tells (a topic
  // that is absent or has no valid message, two clocks that differ).
  virtual void finish() {}
  // A new source of the force topic alone, from the start, for a median
  // force period that needs the periods again (stream_median.hpp).
  virtual std::unique_ptr<MessageSource> reopen_force() const = 0;
};

// The chunks of a message recording. Throws InputError as the header says;
// opening reads the first JointState message (joints and order known).
class MessageRecordingReader : public RecordingReader {
 public:
  MessageRecordingReader(std::string file, const TopicReadOptions& options, RecordingLayout layout,
                         std::unique_ptr<MessageSource> source, std::size_t chunk_rows);
  ~MessageRecordingReader() override;

  const std::vector<std::string>& joint_names() const;
  std::int64_t time_origin_ns() const;
  std::size_t force_samples() const;
  MessageSource& get_source() { return *source_; }

 protected:
  std::size_t fill_chunk(Recording& chunk, std::size_t filled) override;

 private:
  struct State;
  void pull();
  void check_first_sample();
  std::unique_ptr<MessageSource> source_;
  std::unique_ptr<State> state_;
};

}  // namespace rcm
