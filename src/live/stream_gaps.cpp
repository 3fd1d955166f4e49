#include "rcm/live/stream_gaps.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace rcm {

StreamGaps::StreamGaps(double max_gap_s) : max_gap_ns_(std::llround(max_gap_s * 1e9)) {
  if (!(max_gap_s > 0.0)) throw std::invalid_argument("StreamGaps: max_gap_s must be > 0");
}

std::uint64_t StreamGaps::compute_interval(std::int64_t interval_ns, std::uint64_t rejected_between) {
  last_missing_ = 0;
  if (interval_ns <= 0 || interval_ns > max_gap_ns_) return 0;
  recent_[static_cast<std::size_t>(intervals_ % kWindow)] = interval_ns;
  ++intervals_;
  if (intervals_ % kUpdateEvery == 0) {
    const auto n = static_cast<std::ptrdiff_t>(std::min<std::uint64_t>(intervals_, kWindow));
    std::copy(recent_.begin(), recent_.begin() + n, scratch_.begin());
    std::nth_element(scratch_.begin(), scratch_.begin() + n / 2, scratch_.begin() + n);
    median_ns_ = scratch_[static_cast<std::size_t>(n / 2)];
  }
  if (median_ns_ <= 0 || static_cast<double>(interval_ns) <= kGapRatio * static_cast<double>(median_ns_)) return 0;
  const auto slots = static_cast<std::uint64_t>(
      std::llround(static_cast<double>(interval_ns) / static_cast<double>(median_ns_)));
  const std::uint64_t skipped = slots > 1 ? slots - 1 : 0;
  last_missing_ = skipped > rejected_between ? skipped - rejected_between : 0;
  missing_ += last_missing_;
  gaps_ += last_missing_ > 0 ? 1 : 0;
  return last_missing_;
}

std::uint64_t StreamGaps::compute_late_arrival() {
  if (last_missing_ == 0) return 0;
  --last_missing_;
  --missing_;
  if (last_missing_ == 0) --gaps_;  // the gap is filled
  return 1;
}

}  // namespace rcm
