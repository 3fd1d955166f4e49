#pragma once
// A recording assembled from messages: what every message-based reader (ROS 1
// bags, rosbag2 SQLite and MCAP) shares once it has decoded a message, so that
// all of them hold a JointState topic to the CSV reader's rules and word their
// errors alike.
//
// - JointStateRecordingBuilder takes the JointState messages of one topic in
//   recording order, each with the time its reader chose (header stamp or
//   receive time, integer ns): JointStateMap checks and orders every message;
//   finish() makes the Recording (seconds from the first kept sample, exact to
//   1 ns), counts repeated samples, drops them under --dedupe, and checks that
//   time increases strictly.
// - ForceSamples takes a geometry_msgs/WrenchStamped topic: force at the
//   incision in the base frame (the session format's convention; frame_id is
//   only reported), linearly interpolated at the joint samples' times. Joint
//   samples up to one median force period outside the force topic's span take
//   its end value; beyond that it is an error.
//
// Errors name the file, the topic, the message index (0-based, in recording
// order, on that topic), its time when known, and the field:
//   run.mcap: /PSM1/measured_js message 1204 (t = 6.02 s): effort[2] ('outer_insertion'): expected a finite number, got nan

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rcm/io/joint_state_map.hpp"
#include "rcm/io/recording.hpp"

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

// The force samples of a WrenchStamped topic, in recording order.
class ForceSamples {
 public:
  ForceSamples(std::string file, std::string topic, std::string time_label);
  // Throws InputError for a non-finite component, a time outside [0, 2^62) ns
  // or one that does not increase.
  void add(std::size_t index, std::int64_t t_ns, const Eigen::Vector3d& force);
  std::size_t size() const { return t_ns_.size(); }
  const std::string& topic() const { return topic_; }

 private:
  friend class JointStateRecordingBuilder;
  std::string file_, topic_, time_label_;
  std::vector<std::int64_t> t_ns_;
  std::vector<Eigen::Vector3d> force_;
};

class JointStateRecordingBuilder {
 public:
  // `time_label` names the clock in errors ("header.stamp", "bag time", "receive time").
  JointStateRecordingBuilder(std::string file, std::string topic, const TopicReadOptions& options,
                             std::string time_label);

  // Message `index` of the topic at `t_ns`. Throws InputError for a time outside
  // [0, 2^62) ns (1970 to 2116), a message the joint map rejects, or a first
  // message with too few joints.
  void add(std::size_t index, std::int64_t t_ns, const JointStateView& message);

  std::size_t size() const { return t_ns_.size(); }
  // The recording's joint order; empty when the messages carry no names.
  const std::vector<std::string>& joint_names() const { return map_.names(); }

  // The recording (source = file, the given layout). Throws InputError when no
  // message was added or time does not increase strictly.
  Recording finish(RecordingLayout layout);
  // Absolute time (ns) of sample 0 of the finished recording.
  std::int64_t time_origin_ns() const { return origin_ns_; }
  // Fills `recording.force` from `force` at the finished recording's samples.
  void attach_force(Recording& recording, const ForceSamples& force) const;

 private:
  std::string file_, topic_, time_label_;
  TopicReadOptions options_;
  JointStateMap map_;
  JointStateMap::Workspace ws_;
  std::vector<std::int64_t> t_ns_;
  std::vector<std::size_t> index_;
  std::vector<double> values_;  // per message: position, velocity, effort (num_joints each)
  std::vector<std::size_t> kept_;  // after finish(): the messages in the recording
  std::int64_t origin_ns_ = 0;
};

}  // namespace rcm
