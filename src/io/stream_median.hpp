#pragma once
// Internal to io: the exact median of a stream of numbers in bounded memory,
// for the median sampling interval of a recording read in chunks (`rcm
// inspect`) and the median period of a force topic (the tolerance at its
// ends). "Median" is the element n / 2 of the sorted values (0-based), as
// std::nth_element picks it over the whole vector, so that a streamed summary
// equals a whole one bit for bit.
//
// One pass is enough when the stream holds at most kMaxDistinct distinct
// values: sampling intervals are stamped in ns or us and repeat, so a
// recording of any length has a few thousand. Otherwise the caller replays
// the same values (any order) once or a few times: each pass narrows the
// median to the values that share 16 more leading bits of their ordered
// 64-bit pattern, and once at most kMaxCollected of them remain they are kept
// and sorted. At most four passes; memory is bounded by the constants below
// (about 12 MB), whatever the length.

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <unordered_map>
#include <utility>
#include <vector>

namespace rcm::detail {

class StreamMedian {
 public:
  static constexpr std::size_t kMaxDistinct = std::size_t{1} << 16;
  static constexpr std::size_t kMaxCollected = std::size_t{1} << 20;

  void add(double value) {
    const std::uint64_t key = to_key(value);
    if (pass_ == 0) {
      ++count_;
      if (!overflowed_) {
        ++distinct_[key];
        if (distinct_.size() > kMaxDistinct) {
          overflowed_ = true;
          distinct_ = {};
        }
      }
      ++histogram_[key >> 48];
      return;
    }
    if (prefix_bits_ > 0 && (key >> (64 - prefix_bits_)) != prefix_) return;
    if (collecting_)
      collected_.push_back(key);
    else
      ++histogram_[(key >> (48 - prefix_bits_)) & 0xFFFF];
  }

  std::size_t size() const { return count_; }
  // True when get() needs the same values again: call start_pass(), add them
  // all, and ask again.
  bool needs_pass() {
    if (done_ || count_ == 0) return false;
    if (pass_ == 0 && !ranked_) {
      rank_ = count_ / 2;
      ranked_ = true;
    }
    if (pass_ == 0 && !overflowed_) {
      std::vector<std::pair<std::uint64_t, std::uint64_t>> v(distinct_.begin(), distinct_.end());
      std::sort(v.begin(), v.end());
      std::uint64_t seen = 0;
      for (const auto& [key, n] : v) {
        seen += n;
        if (seen > rank_) {
          result_ = key;
          break;
        }
      }
      return !(done_ = true);
    }
    if (collecting_) {
      std::nth_element(collected_.begin(), collected_.begin() + static_cast<std::ptrdiff_t>(rank_), collected_.end());
      result_ = collected_[rank_];
      collected_ = {};
      return !(done_ = true);
    }
    // The histogram of this level: the bucket that holds the median, and its rank there.
    std::uint64_t below = 0, bucket = 0;
    for (; bucket < histogram_.size(); ++bucket) {
      if (below + histogram_[bucket] > rank_) break;
      below += histogram_[bucket];
    }
    const std::uint64_t in_bucket = histogram_[bucket];
    rank_ -= below;
    prefix_ = (prefix_ << 16) | bucket;
    prefix_bits_ += 16;
    if (prefix_bits_ == 64) {
      result_ = prefix_;
      return !(done_ = true);
    }
    collecting_ = in_bucket <= kMaxCollected;
    return true;
  }
  void start_pass() {
    ++pass_;
    std::fill(histogram_.begin(), histogram_.end(), 0);
    collected_.clear();
  }
  // The median; call when needs_pass() is false (0 for an empty stream).
  double get() const { return count_ == 0 ? 0.0 : from_key(result_); }

 private:
  // Doubles ordered as unsigned integers: flip every bit of negatives, the
  // sign bit of the others.
  static std::uint64_t to_key(double v) {
    std::uint64_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    return (bits >> 63) ? ~bits : bits | (std::uint64_t{1} << 63);
  }
  static double from_key(std::uint64_t key) {
    const std::uint64_t bits = (key >> 63) ? key & ~(std::uint64_t{1} << 63) : ~key;
    double v;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }

  std::size_t count_ = 0;
  int pass_ = 0;
  bool overflowed_ = false, collecting_ = false, done_ = false;
  std::unordered_map<std::uint64_t, std::uint64_t> distinct_;
  std::vector<std::uint64_t> histogram_ = std::vector<std::uint64_t>(std::size_t{1} << 16, 0);
  std::vector<std::uint64_t> collected_;
  std::uint64_t prefix_ = 0, result_ = 0;
  int prefix_bits_ = 0;
  std::uint64_t rank_ = 0;  // of the median among the values still in question
  bool ranked_ = false;
};

}  // namespace rcm::detail
