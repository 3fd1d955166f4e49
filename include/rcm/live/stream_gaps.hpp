#pragma once
// Messages a live stream skipped, told from its stamps. Neither ROS 1 nor DDS
// says when a message is lost on the way or overwritten in a full queue
// (Cyclone 0.10's sample-lost status stays at zero for both), yet the
// estimator then sees fewer samples than the arm sent.
//
// An accepted sample later than the one before by more than kGapRatio of the
// stream's median interval closes a gap. The messages missing in it are its
// length in median intervals less one, less the messages that came in it and
// were rejected (a NaN, a zero stamp: received, not lost). A message that
// arrives late, behind the sample that closed the gap, fills one slot back.
// An interval longer than `max_gap_s` is a silence: the publisher paused, and
// nothing is counted missing.
//
// The median is over the last kWindow intervals, updated every kUpdateEvery,
// so a publisher that changes its rate is followed within a window; no gap is
// judged before the first update. No allocation.

#include <array>
#include <cstdint>

namespace rcm {

class StreamGaps {
 public:
  static constexpr int kWindow = 63;
  static constexpr int kUpdateEvery = 16;
  static constexpr double kGapRatio = 1.5;

  explicit StreamGaps(double max_gap_s = 1.0);

  // The interval (ns) from the last accepted sample to this one and the
  // messages received and rejected between them; returns the messages missing
  // in that interval (0 for none, a silence, or before the median is known).
  std::uint64_t compute_interval(std::int64_t interval_ns, std::uint64_t rejected_between);
  // A message rejected as out of order whose stamp lies in the last interval:
  // returns 1 when it fills a slot that interval counted missing.
  std::uint64_t compute_late_arrival();
  // The stream's timeline moved (a retimed publisher): the interval across the
  // move says nothing, and the next one is judged afresh.
  void restart_interval() { last_missing_ = 0; }

  // 0 until the first update.
  std::int64_t get_median_interval_ns() const { return median_ns_; }
  // The missing messages the last interval still counts (after late arrivals).
  std::uint64_t get_last_missing() const { return last_missing_; }
  // Since the start: messages missing, and the intervals that still count some.
  std::uint64_t get_missing() const { return missing_; }
  std::uint64_t get_gaps() const { return gaps_; }

 private:
  std::int64_t max_gap_ns_;
  std::array<std::int64_t, kWindow> recent_{}, scratch_{};
  std::uint64_t intervals_ = 0;
  std::int64_t median_ns_ = 0;
  std::uint64_t last_missing_ = 0;
  std::uint64_t missing_ = 0, gaps_ = 0;
};

}  // namespace rcm
