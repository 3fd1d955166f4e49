#include "rcm/live/live_monitor.hpp"

#include <algorithm>
#include <stdexcept>

namespace rcm {

LiveMonitor::LiveMonitor(const OnlinePipeline& pipeline, std::vector<std::string> joint_names, ZeroStamp zero_stamp,
                         StampRules stamp_rules)
    : pipeline_(pipeline),
      workspace_(pipeline.create_workspace()),
      wanted_names_(std::move(joint_names)),
      zero_stamp_(zero_stamp),
      stamp_rules_(stamp_rules),
      gaps_(stamp_rules.max_gap_s) {
  if (!(stamp_rules_.max_lead_s >= 0.0) || stamp_rules_.retime_after < 0)
    throw std::invalid_argument("LiveMonitor: max_lead_s must be >= 0 and retime_after >= 0");
  if (!wanted_names_.empty()) {
    map_ = JointStateMap(wanted_names_);  // throws std::invalid_argument on empty or repeated names
    if (map_.num_joints() < pipeline_.model().num_joints())
      throw std::invalid_argument("LiveMonitor: " + std::to_string(map_.num_joints()) +
                                  " joint names given, the free-space model reads " +
                                  std::to_string(pipeline_.model().num_joints()) + " joints");
    map_ws_ = map_.create_workspace();
  }
}

LiveMonitor::Verdict LiveMonitor::compute_message(const JointStateView& m, std::int64_t stamp_ns,
                                                  std::int64_t receive_time_ns) {
  if (stamp_ns == 0 && zero_stamp_ == ZeroStamp::invalid) {
    ++counters_.bad_stamp;
    return Verdict::bad_stamp;
  }
  if (map_.num_joints() == 0) {
    // The first message that can define the joint order (allocates, once).
    try {
      map_ = JointStateMap::make_from_message(m, pipeline_.model().num_joints());
    } catch (const std::invalid_argument&) {  // no joints, or empty or repeated names
      defect_ = {};
      ++counters_.malformed;
      return Verdict::malformed;
    }
    if (map_.num_joints() < pipeline_.model().num_joints()) {
      map_ = JointStateMap();
      ++counters_.too_few_joints;
      return Verdict::too_few_joints;
    }
    map_ws_ = map_.create_workspace();
  }
  defect_ = map_.compute_sample(map_ws_, m);
  if (defect_) {
    ++counters_.malformed;
    return Verdict::malformed;
  }

  std::int64_t t_ns = 0;
  if (!started_) {
    receive_time_ = stamp_ns == 0;
    origin_ns_ = receive_time_ ? receive_time_ns : stamp_ns;
  } else {
    if (!receive_time_ && stamp_ns == 0) {
      ++counters_.bad_stamp;
      return Verdict::bad_stamp;
    }
    t_ns = (receive_time_ ? receive_time_ns : stamp_ns) - origin_ns_;
    if (t_ns == last_ns_) {
      ++counters_.duplicate_stamp;
      return Verdict::duplicate_stamp;
    }
    if (!receive_time_) {
      const double lead_s = static_cast<double>((t_ns - last_ns_) - (receive_time_ns - last_receive_ns_)) * 1e-9;
      const Verdict verdict = t_ns < last_ns_                      ? Verdict::out_of_order
                              : lead_s > stamp_rules_.max_lead_s ? Verdict::time_jump
                                                                 : Verdict::accepted;
      if (verdict != Verdict::accepted) {
        if (reject_by_time(verdict, stamp_ns, receive_time_ns) == Verdict::accepted) {
          // Follow the publisher's new timeline; the estimator's time goes on.
          const std::int64_t elapsed_ns = std::max<std::int64_t>(receive_time_ns - last_receive_ns_, 1);
          t_ns = last_ns_ + elapsed_ns;
          origin_ns_ = stamp_ns - t_ns;
          gaps_.restart_interval();
        } else {
          if (verdict == Verdict::out_of_order && t_ns > previous_ns_) count_late_arrival();
          return verdict;
        }
      } else {
        const std::uint64_t between = get_slot_rejections() - late_since_accept_ - rejected_at_accept_;
        gaps_.compute_interval(t_ns - last_ns_, between);
        copy_gap_counts();
      }
    } else if (t_ns < last_ns_) {
      ++counters_.out_of_order;
      return Verdict::out_of_order;
    }
  }
  candidates_ = 0;
  started_ = true;
  previous_ns_ = last_ns_;
  last_ns_ = t_ns;
  rejected_at_accept_ = get_slot_rejections();
  late_since_accept_ = 0;
  last_receive_ns_ = receive_time_ns;
  pipeline_.compute_sample(workspace_, static_cast<double>(t_ns) * 1e-9, map_ws_.position.data(),
                           map_ws_.velocity.data(), map_ws_.effort.data());
  ++counters_.accepted;
  return Verdict::accepted;
}

LiveMonitor::Verdict LiveMonitor::reject_by_time(Verdict verdict, std::int64_t stamp_ns, std::int64_t receive_time_ns) {
  const bool follows = candidates_ > 0 && stamp_ns > candidate_stamp_ns_ &&
                       static_cast<double>((stamp_ns - candidate_stamp_ns_) - (receive_time_ns - candidate_receive_ns_)) *
                               1e-9 <=
                           stamp_rules_.max_lead_s;
  candidates_ = follows ? candidates_ + 1 : 1;
  candidate_stamp_ns_ = stamp_ns;
  candidate_receive_ns_ = receive_time_ns;
  if (stamp_rules_.retime_after > 0 && candidates_ >= stamp_rules_.retime_after) {
    ++counters_.retimed;
    return Verdict::accepted;
  }
  if (verdict == Verdict::out_of_order) ++counters_.out_of_order;
  else ++counters_.time_jump;
  return verdict;
}

// Every rejection but a repeated stamp may be a message that held a slot of
// the stream (a late arrival included: count_late_arrival takes it back).
std::uint64_t LiveMonitor::get_slot_rejections() const { return counters_.get_rejected() - counters_.duplicate_stamp; }

void LiveMonitor::count_late_arrival() {
  ++late_since_accept_;
  gaps_.compute_late_arrival();
  copy_gap_counts();
}

// Counters is the snapshot of everything counted; StreamGaps keeps the totals.
void LiveMonitor::copy_gap_counts() {
  counters_.missing = gaps_.get_missing();
  counters_.gaps = gaps_.get_gaps();
}

std::string LiveMonitor::describe_rejection(Verdict v, const JointStateView& m, std::int64_t stamp_ns) const {
  const double stamp = static_cast<double>(stamp_ns) * 1e-9;
  switch (v) {
    case Verdict::accepted:
      return "accepted";
    case Verdict::duplicate_stamp:
      return "stamp " + std::to_string(stamp) + " s repeats the last accepted sample's";
    case Verdict::out_of_order:
      return "stamp " + std::to_string(stamp) + " s is earlier than the last accepted sample's (" +
             std::to_string(static_cast<double>(get_last_time_ns()) * 1e-9) + " s)";
    case Verdict::time_jump:
      return "stamp " + std::to_string(stamp) + " s is " +
             std::to_string(static_cast<double>(stamp_ns - get_last_time_ns()) * 1e-9) +
             " s after the last accepted sample's, more than the receive clock advanced";
    case Verdict::bad_stamp:
      return zero_stamp_ == ZeroStamp::invalid ? "header.stamp is zero: invalid data"
                                               : "header.stamp is zero in a stream whose first message had a stamp";
    case Verdict::too_few_joints:
      return "the message has " + std::to_string(m.position.size()) + " joints, the free-space model reads " +
             std::to_string(pipeline_.model().num_joints());
    case Verdict::malformed:
      if (map_.num_joints() == 0)
        return m.name.empty() ? "position: missing (empty array)" : "name: joint names must be unique and non-empty";
      return map_.describe(defect_, m);
  }
  return "unknown";
}

const char* to_string(LiveMonitor::Verdict v) {
  switch (v) {
    case LiveMonitor::Verdict::accepted: return "accepted";
    case LiveMonitor::Verdict::duplicate_stamp: return "duplicate stamp";
    case LiveMonitor::Verdict::out_of_order: return "out of order";
    case LiveMonitor::Verdict::bad_stamp: return "zero stamp";
    case LiveMonitor::Verdict::malformed: return "malformed";
    case LiveMonitor::Verdict::too_few_joints: return "too few joints";
    case LiveMonitor::Verdict::time_jump: return "time jump";
  }
  return "unknown";
}

}  // namespace rcm
