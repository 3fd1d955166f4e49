#pragma once
// The per-message path of the live nodes (ROS 1 and DDS) without any
// middleware: one sensor_msgs/JointState in (seen through JointStateView),
// checked (joint order by name, finite values, lengths, time strictly
// increasing), the online pipeline of `rcm monitor` stepped once. Bad messages
// are rejected and counted, never thrown on, so a live stream survives them.
//
// Time: header.stamp. What a zero stamp means is the middleware's convention
// (ZeroStamp): for ROS 1 publishers that never set stamps, the receive time
// when the stream's first accepted message has a zero stamp (then for every
// message); for the dVRK on ROS 2 (cisst-ros 4.0 and later), invalid data,
// rejected and counted. The estimator sees seconds from the first accepted
// sample, computed in integer nanoseconds, as the bag readers do, so that a
// bag and its live replay give the same numbers.
//
// No allocation per message once the first message has been accepted (the
// joint order and the buffers are set up then).

#include <cstdint>
#include <string>
#include <vector>

#include "rcm/estimation/online.hpp"
#include "rcm/io/joint_state_map.hpp"

namespace rcm {

class LiveMonitor {
 public:
  enum class Verdict {
    accepted,
    duplicate_stamp,   // the same time as the last accepted sample
    out_of_order,      // earlier than the last accepted sample
    bad_stamp,         // zero stamp: invalid data, or a stream that has stamps
    malformed,         // see get_last_defect()
    too_few_joints,    // the first message has fewer joints than the model reads
  };
  struct Counters {
    std::uint64_t accepted = 0, duplicate_stamp = 0, out_of_order = 0, bad_stamp = 0, malformed = 0,
                  too_few_joints = 0;
    std::uint64_t get_rejected() const { return duplicate_stamp + out_of_order + bad_stamp + malformed + too_few_joints; }
  };

  enum class ZeroStamp {
    receive_time_when_unstamped,  // ROS 1: a stream whose first message has no stamp uses the receive time
    invalid,                      // ROS 2 dVRK: a zero stamp marks invalid data
  };

  // `pipeline` must outlive the monitor. `joint_names`: the joint order the
  // free-space model was trained on, by name; empty: the first message's order.
  LiveMonitor(const OnlinePipeline& pipeline, std::vector<std::string> joint_names = {},
              ZeroStamp zero_stamp = ZeroStamp::receive_time_when_unstamped);

  // One message with its header stamp (0: zero stamp); `receive_time_ns` is
  // used only when the stream carries no stamps.
  Verdict compute_message(const JointStateView& message, std::int64_t stamp_ns, std::int64_t receive_time_ns);

  const OnlineOutput& get_output() const { return get_online_output(workspace_.estimator); }
  const Counters& get_counters() const { return counters_; }
  bool started() const { return started_; }
  bool uses_receive_time() const { return receive_time_; }
  std::int64_t get_time_origin_ns() const { return origin_ns_; }
  // The absolute time (ns) of the last accepted sample: the stamp to publish with.
  std::int64_t get_last_time_ns() const { return origin_ns_ + last_ns_; }
  const JointStateMap& get_joint_map() const { return map_; }
  const JointStateDefect& get_last_defect() const { return defect_; }

  // A sentence for a log line about the last rejection (allocates).
  std::string describe_rejection(Verdict verdict, const JointStateView& message, std::int64_t stamp_ns) const;

 private:
  const OnlinePipeline& pipeline_;
  OnlinePipeline::Workspace workspace_;
  std::vector<std::string> wanted_names_;
  ZeroStamp zero_stamp_;
  JointStateMap map_;
  JointStateMap::Workspace map_ws_;
  bool started_ = false, receive_time_ = false;
  std::int64_t origin_ns_ = 0, last_ns_ = 0;
  Counters counters_;
  JointStateDefect defect_;
};

const char* to_string(LiveMonitor::Verdict verdict);

}  // namespace rcm
