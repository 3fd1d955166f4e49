// What `rcm inspect` shows of a recording, from its chunks: running minima,
// maxima and sums, and the exact median sampling interval (stream_median.hpp),
// so that a recording of any length is summarized in bounded memory. A whole
// recording is summarized the same way, one chunk of it.

#include <algorithm>
#include <cmath>
#include <limits>

#include "io/stream_median.hpp"
#include "rcm/io/recording_reader.hpp"

namespace rcm {
namespace {

class SummaryBuilder {
 public:
  void add(const Recording& chunk) {
    const Eigen::Index T = chunk.time.size();
    if (T == 0) return;
    if (samples_ == 0) {
      first_time_ = chunk.time[0];
      position_.assign(static_cast<std::size_t>(chunk.num_joints()), {kInf, -kInf});
      velocity_ = effort_ = position_;
      if (chunk.force) force_.assign(3, {kInf, -kInf});
    }
    for (Eigen::Index t = 0; t < T; ++t) {
      if (samples_ > 0) {
        const double d = chunk.time[t] - last_time_;
        if (intervals_ == 0) shift_ = d;  // sums about the first interval keep the jitter's digits
        ++intervals_;
        dt_min_ = std::min(dt_min_, d);
        dt_max_ = std::max(dt_max_, d);
        sum_ += d - shift_;
        sum_squares_ += (d - shift_) * (d - shift_);
        median_.add(d);
      }
      last_time_ = chunk.time[t];
      ++samples_;
    }
    extend(position_, chunk.position);
    extend(velocity_, chunk.velocity);
    extend(effort_, chunk.effort);
    if (chunk.force) extend(force_, *chunk.force);
  }
  // The intervals again, for a median that needs another pass.
  void add_intervals(const Recording& chunk) {
    for (Eigen::Index t = 0; t < chunk.time.size(); ++t) {
      if (has_last_) median_.add(chunk.time[t] - last_again_);
      last_again_ = chunk.time[t];
      has_last_ = true;
    }
  }
  bool needs_pass() { return median_.needs_pass(); }
  void start_pass() {
    median_.start_pass();
    has_last_ = false;
  }

  RecordingSummary finish(int joints, bool has_force, std::size_t repeated, bool removed, bool from_rate) {
    RecordingSummary s;
    s.samples = samples_;
    s.joints = joints;
    s.repeated_rows = repeated;
    s.repeated_rows_removed = removed;
    s.has_force = has_force;
    s.time_from_rate = from_rate;
    if (intervals_ > 0) {
      const double n = static_cast<double>(intervals_);
      s.duration_s = last_time_ - first_time_;
      const double mean = sum_ / n;
      s.jitter_s = std::sqrt(std::max(0.0, sum_squares_ / n - mean * mean));
      s.dt_min_s = dt_min_;
      s.dt_max_s = dt_max_;
      s.dt_median_s = median_.get();
      s.rate_hz = s.dt_median_s > 0 ? 1.0 / s.dt_median_s : 0.0;
    }
    const auto zero = [&](std::vector<RecordingSummary::Range>& v, std::size_t n) {
      if (samples_ == 0) v.assign(n, {0.0, 0.0});
    };
    zero(position_, static_cast<std::size_t>(joints));
    zero(velocity_, static_cast<std::size_t>(joints));
    zero(effort_, static_cast<std::size_t>(joints));
    if (has_force) zero(force_, 3);
    s.position = position_;
    s.velocity = velocity_;
    s.effort = effort_;
    s.force = force_;
    return s;
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  static void extend(std::vector<RecordingSummary::Range>& ranges, const Eigen::MatrixXd& m) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      auto& r = ranges[static_cast<std::size_t>(j)];
      r.min = std::min(r.min, m.col(j).minCoeff());
      r.max = std::max(r.max, m.col(j).maxCoeff());
    }
  }

  std::size_t samples_ = 0, intervals_ = 0;
  double first_time_ = 0, last_time_ = 0;
  double dt_min_ = kInf, dt_max_ = -kInf, shift_ = 0, sum_ = 0, sum_squares_ = 0;
  detail::StreamMedian median_;
  bool has_last_ = false;
  double last_again_ = 0;
  std::vector<RecordingSummary::Range> position_, velocity_, effort_, force_;
};

}  // namespace

RecordingSummary summarize_recording(const Recording& r) {
  SummaryBuilder b;
  b.add(r);
  while (b.needs_pass()) {
    b.start_pass();
    b.add_intervals(r);
  }
  return b.finish(r.num_joints(), r.has_force(), r.repeated_rows, r.repeated_rows_removed, r.time_from_rate);
}

RecordingSummary summarize_recording(RecordingReader& reader,
                                     const std::function<std::unique_ptr<RecordingReader>()>& reopen) {
  SummaryBuilder b;
  Recording chunk;
  while (reader.read_chunk(chunk)) b.add(chunk);
  while (b.needs_pass()) {
    if (!reopen) throw std::logic_error("summarize_recording: the median sampling interval needs another pass");
    b.start_pass();
    const auto again = reopen();
    while (again->read_chunk(chunk)) b.add_intervals(chunk);
  }
  return b.finish(reader.num_joints(), reader.has_force(), reader.repeated_rows(), reader.repeated_rows_removed(),
                  reader.time_from_rate());
}

}  // namespace rcm
