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
// A publisher's clock can misbehave: one stamp hours ahead or behind (a glitch),
// or the whole timeline stepped (a clock reset, a restarted publisher, a bag
// replayed from its start). A stamp ahead of the last accepted one by more than
// the receive clock advanced plus LiveStampRules::max_lead_s is a `time_jump`; an
// earlier one is `out_of_order`. Both are rejected, so that one bad stamp cannot
// lock the stream out; when LiveStampRules::retime_after consecutive rejected
// messages agree among themselves (increasing, and no lead between them), the
// publisher's timeline has moved: the monitor follows it (`retimed`), and the
// estimator's time goes on from the last accepted sample by what the receive
// clock says elapsed, so that its own time never runs backwards.
//
// Messages the stream skipped (lost on the way, overwritten in a full queue)
// are counted from the stamps (StreamGaps), not rejections: `missing` in
// `gaps`. Not with receive times, whose jitter is not the publisher's.
//
// No allocation per message once the first message has been accepted (the
// joint order and the buffers are set up then).

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "rcm/estimation/online.hpp"
#include "rcm/io/joint_state_map.hpp"
#include "rcm/live/stream_gaps.hpp"

namespace rcm {

// How LiveMonitor tells a publisher's clock misbehaving from a silence.
struct LiveStampRules {
  // How far a stamp may run ahead of the receive clock between two messages.
  // A 10-minute silence advances both clocks alike; a bag played faster than
  // real time leads by its sample period at most, unless the bag has a gap.
  double max_lead_s = 1.0;
  // Consecutive rejected but mutually consistent messages that make the
  // monitor follow the publisher's new timeline (0: never).
  int retime_after = 10;
  // An interval between two stamps longer than this is a silence (the
  // publisher paused), not messages missing.
  double max_gap_s = 1.0;
};

class LiveMonitor {
 public:
  enum class Verdict {
    accepted,
    duplicate_stamp,   // the same time as the last accepted sample
    out_of_order,      // earlier than the last accepted sample
    bad_stamp,         // zero stamp: invalid data, or a stream that has stamps
    malformed,         // see get_last_defect()
    too_few_joints,    // the first message has fewer joints than the model reads
    time_jump,         // later than the last accepted sample by more than the receive clock allows
  };
  struct Counters {
    std::uint64_t accepted = 0, duplicate_stamp = 0, out_of_order = 0, bad_stamp = 0, malformed = 0,
                  too_few_joints = 0, time_jump = 0;
    std::uint64_t retimed = 0;  // times the monitor followed a publisher's timeline that moved (not a rejection)
    // Messages the stamps say the stream skipped, and the intervals they were
    // in (not rejections: they never arrived).
    std::uint64_t missing = 0, gaps = 0;
    std::uint64_t get_rejected() const {
      return duplicate_stamp + out_of_order + bad_stamp + malformed + too_few_joints + time_jump;
    }
  };
  using StampRules = LiveStampRules;

  enum class ZeroStamp {
    receive_time_when_unstamped,  // ROS 1: a stream whose first message has no stamp uses the receive time
    invalid,                      // ROS 2 dVRK: a zero stamp marks invalid data
  };

  // `pipeline` must outlive the monitor. `joint_names`: the joint order the
  // free-space model was trained on, by name; empty: the first message's order.
  LiveMonitor(const OnlinePipeline& pipeline, std::vector<std::string> joint_names = {},
              ZeroStamp zero_stamp = ZeroStamp::receive_time_when_unstamped, StampRules stamp_rules = {});

  // One message with its header stamp (0: zero stamp) and the time it was
  // received (any steady clock): the time when the stream carries no stamps,
  // else the reference that tells a clock jump from a silence.
  Verdict compute_message(const JointStateView& message, std::int64_t stamp_ns, std::int64_t receive_time_ns);

  const OnlineOutput& get_output() const { return get_online_output(workspace_.estimator); }
  // The RCM moved by `shift_base` (base frame, m) before the next message (a
  // software shift): OnlinePipeline::apply_rcm_shift.
  void apply_rcm_shift(const Eigen::Vector3d& shift_base) { pipeline_.apply_rcm_shift(workspace_, shift_base); }
  const Counters& get_counters() const { return counters_; }
  bool started() const { return started_; }
  bool uses_receive_time() const { return receive_time_; }
  std::int64_t get_time_origin_ns() const { return origin_ns_; }
  // The absolute time (ns) of the last accepted sample.
  std::int64_t get_last_time_ns() const { return origin_ns_ + last_ns_; }
  // The messages missing just before the last accepted sample, the interval
  // (ns) it closed, and the stream's median interval (ns; 0 until known).
  std::uint64_t get_last_missing() const { return gaps_.get_last_missing(); }
  std::int64_t get_last_interval_ns() const { return last_ns_ - previous_ns_; }
  std::int64_t get_median_interval_ns() const { return gaps_.get_median_interval_ns(); }
  // The absolute time (ns) of the sample get_output() is for, the stamp to
  // publish it with: the last accepted one's, or, with a model whose torque
  // trails, that of the sample that long before (exact to the nanosecond for
  // streams up to weeks long).
  std::int64_t get_output_time_ns() const { return origin_ns_ + std::llround(get_output().time * 1e9); }
  const JointStateMap& get_joint_map() const { return map_; }
  const JointStateDefect& get_last_defect() const { return defect_; }

  // A sentence for a log line about the last rejection (allocates).
  std::string describe_rejection(Verdict verdict, const JointStateView& message, std::int64_t stamp_ns) const;

 private:
  const OnlinePipeline& pipeline_;
  OnlinePipeline::Workspace workspace_;
  std::vector<std::string> wanted_names_;
  ZeroStamp zero_stamp_;
  StampRules stamp_rules_;
  JointStateMap map_;
  JointStateMap::Workspace map_ws_;
  bool started_ = false, receive_time_ = false;
  std::int64_t origin_ns_ = 0, last_ns_ = 0, last_receive_ns_ = 0;
  // The run of rejected messages that may be a moved timeline.
  int candidates_ = 0;
  std::int64_t candidate_stamp_ns_ = 0, candidate_receive_ns_ = 0;
  Counters counters_;
  JointStateDefect defect_;
  StreamGaps gaps_;
  std::int64_t previous_ns_ = 0;            // the accepted sample before the last
  std::uint64_t rejected_at_accept_ = 0;    // rejections that may hold a slot, at the last acceptance
  std::uint64_t late_since_accept_ = 0;     // late arrivals since then (they held a slot before it)

  std::uint64_t get_slot_rejections() const;
  void count_late_arrival();
  void copy_gap_counts();

  Verdict reject_by_time(Verdict verdict, std::int64_t stamp_ns, std::int64_t receive_time_ns);
};

const char* to_string(LiveMonitor::Verdict verdict);

}  // namespace rcm
