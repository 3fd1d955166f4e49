// rcm::StreamGaps: the messages a stream skipped, from its stamps alone. Gaps
// are judged against the median interval once it is known, less the messages
// rejected in them; late arrivals fill their slot back; a silence is not a gap;
// a change of rate is followed; no allocation.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <cstdint>
#include <stdexcept>

#include "rcm/live/stream_gaps.hpp"

namespace {

using rcm::StreamGaps;
using rcm::test::get_allocation_count;

constexpr std::int64_t kPeriodNs = 666667;  // 1.5 kHz

// `n` regular intervals with a jitter of +-10 %; returns the missing counted.
std::uint64_t feed_regular(StreamGaps& gaps, int n, std::int64_t period_ns = kPeriodNs) {
  std::uint64_t missing = 0;
  for (int k = 0; k < n; ++k) missing += gaps.compute_interval(period_ns + (k % 3 - 1) * period_ns / 10, 0);
  return missing;
}

TEST(StreamGaps, CountsTheSlotsOfAGapOnceTheMedianIsKnown) {
  StreamGaps gaps;
  // Before the first median, nothing is judged.
  EXPECT_EQ(gaps.compute_interval(10 * kPeriodNs, 0), 0u);
  EXPECT_EQ(gaps.get_median_interval_ns(), 0);
  EXPECT_EQ(feed_regular(gaps, 2 * StreamGaps::kUpdateEvery), 0u);
  EXPECT_EQ(gaps.get_median_interval_ns(), kPeriodNs);
  // Five messages lost: six intervals without a sample.
  EXPECT_EQ(gaps.compute_interval(6 * kPeriodNs, 0), 5u);
  EXPECT_EQ(gaps.get_last_missing(), 5u);
  EXPECT_EQ(gaps.compute_interval(kPeriodNs, 0), 0u);
  EXPECT_EQ(gaps.get_last_missing(), 0u);
  // Up to 1.5 intervals is jitter; beyond it, rounded to the nearest slot.
  EXPECT_EQ(gaps.compute_interval(kPeriodNs * 3 / 2, 0), 0u);
  EXPECT_EQ(gaps.compute_interval(kPeriodNs * 16 / 10, 0), 1u);
  EXPECT_EQ(gaps.compute_interval(kPeriodNs * 34 / 10, 0), 2u);
}

TEST(StreamGaps, RejectedMessagesAndLateArrivalsAreNotMissing) {
  StreamGaps gaps;
  feed_regular(gaps, 64);
  // Four intervals, two messages received and rejected in them: one lost.
  EXPECT_EQ(gaps.compute_interval(4 * kPeriodNs, 2), 1u);
  // More rejections than slots (a duplicate among them): none lost.
  EXPECT_EQ(gaps.compute_interval(3 * kPeriodNs, 5), 0u);
  // Three lost, then two of them arrive late: one remains; a third late one
  // fills nothing.
  EXPECT_EQ(gaps.compute_interval(4 * kPeriodNs, 0), 3u);
  EXPECT_EQ(gaps.compute_late_arrival(), 1u);
  EXPECT_EQ(gaps.compute_late_arrival(), 1u);
  EXPECT_EQ(gaps.get_last_missing(), 1u);
  EXPECT_EQ(gaps.compute_late_arrival(), 1u);
  EXPECT_EQ(gaps.compute_late_arrival(), 0u);
  EXPECT_EQ(gaps.get_last_missing(), 0u);
}

TEST(StreamGaps, SilencesAndMovedTimelinesAreNotGaps) {
  StreamGaps gaps(1.0);
  feed_regular(gaps, 64);
  EXPECT_EQ(gaps.compute_interval(1000000001, 0), 0u);  // over a second: the publisher paused
  EXPECT_EQ(gaps.compute_interval(0, 0), 0u);
  EXPECT_EQ(gaps.compute_interval(-kPeriodNs, 0), 0u);
  EXPECT_EQ(gaps.get_median_interval_ns(), kPeriodNs);  // none of them entered the median
  EXPECT_EQ(gaps.compute_interval(3 * kPeriodNs, 0), 2u);
  gaps.restart_interval();
  EXPECT_EQ(gaps.get_last_missing(), 0u);
  EXPECT_THROW(StreamGaps(0.0), std::invalid_argument);
}

TEST(StreamGaps, FollowsAPublisherThatChangesItsRate) {
  StreamGaps gaps;
  feed_regular(gaps, 64, kPeriodNs);
  // From 1.5 kHz to 100 Hz: the first intervals look like gaps, then the
  // median follows within a window.
  EXPECT_GT(gaps.compute_interval(10000000, 0), 0u);
  feed_regular(gaps, StreamGaps::kWindow + StreamGaps::kUpdateEvery, 10000000);
  EXPECT_EQ(gaps.get_median_interval_ns(), 10000000);
  EXPECT_EQ(feed_regular(gaps, 200, 10000000), 0u);
  EXPECT_EQ(gaps.compute_interval(30000000, 0), 2u);
}

TEST(StreamGaps, NoAllocation) {
  StreamGaps gaps;
  const long before = get_allocation_count();
  feed_regular(gaps, 1000);
  gaps.compute_interval(5 * kPeriodNs, 1);
  gaps.compute_late_arrival();
  EXPECT_EQ(get_allocation_count(), before);
}

}  // namespace
