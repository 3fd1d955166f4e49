#pragma once
// rcm_monitor_dds's side of rcm::MonitorSink: Cyclone DDS writers for the
// node's topics (ROS 2 types and QoS, docs/ros2.md) fed from a queue by a
// publisher thread, and a stderr logger in ROS 2's format.

#include <dds/dds.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "support/dds_io.hpp"
#include "rcm/live/monitor_node.hpp"
#include "ros2_msgs.h"

namespace rcm::dds_node {

// One output of the node: queued by the estimator's thread, written by the
// publisher thread. Plain data, so that queueing it costs no allocation.
struct Output {
  enum class Kind { estimate, flag, rejected, advice } kind = Kind::estimate;
  std::int64_t stamp_ns = 0;
  double misalignment[3] = {0, 0, 0}, sd[3] = {0, 0, 0}, force[3] = {0, 0, 0}, correction[3] = {0, 0, 0},
         shift[3] = {0, 0, 0};
  // The advice travels by value: the queue holds no pointer into the estimator's thread.
  char advice[320] = {};
  rcm::MonitorFlag flag = rcm::MonitorFlag::onset;
  bool value = false;
  std::uint64_t total = 0;
};

// A bounded queue between the two threads. Full (the writes stalled for
// `capacity` samples): the newest output is dropped and counted, never the
// estimator blocked.
class OutputQueue {
 public:
  explicit OutputQueue(std::size_t capacity) : ring_(capacity) {}
  void push(const Output& o) {
    bool wake = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (size_ == ring_.size()) {
        ++dropped_;
        return;
      }
      ring_[(head_ + size_) % ring_.size()] = o;
      ++size_;
      max_depth_ = std::max(max_depth_, size_);
      wake = waiting_;  // a busy publisher takes it with the rest: no wake-up call
    }
    if (wake) ready_.notify_one();
  }
  // Moves every queued output into `out` (cleared first); waits for one. False once closed and empty.
  bool pop_all(std::vector<Output>& out) {
    out.clear();
    std::unique_lock<std::mutex> lock(mutex_);
    waiting_ = true;
    ready_.wait(lock, [&] { return size_ > 0 || closed_; });
    waiting_ = false;
    for (; size_ > 0; --size_, head_ = (head_ + 1) % ring_.size()) out.push_back(ring_[head_]);
    return !out.empty() || !closed_;
  }
  void close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    ready_.notify_one();
  }
  std::size_t capacity() const { return ring_.size(); }
  std::size_t get_max_depth() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return max_depth_;
  }
  std::uint64_t get_dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::vector<Output> ring_;
  std::size_t head_ = 0, size_ = 0, max_depth_ = 0;
  std::uint64_t dropped_ = 0;
  bool closed_ = false, waiting_ = false;
};

// Cyclone's writers and a stderr logger behind the node core's sink. The
// estimator's thread only queues; a publisher thread writes, so that a write
// (serialization and a send per reliable reader) never delays the next
// sample. Messages are filled in place: frame ids point at strings the sink owns.
class DdsSink : public rcm::MonitorSink {
 public:
  DdsSink(dds_entity_t participant, const rcm::MonitorNodeParameters& p);
  ~DdsSink() override { finish(); }

  // Writes what is still queued and stops the publisher thread.
  void finish();
  // For the exit summary, after finish().
  std::string get_summary() const;

  void publish_estimate(std::int64_t stamp_ns, const rcm::OnlineOutput& out) override;
  // The node core calls publish_correction just before publish_estimate, with
  // the same stamp, on the estimator's thread: one queued output carries both.
  void publish_correction(std::int64_t, const rcm::CorrectionOutput& c) override;
  // Likewise the software shift (software_rcm only).
  void publish_shift(std::int64_t, const Eigen::Vector3d& shift_base) override;
  void publish_advice(const std::string& text) override;
  void publish_flag(rcm::MonitorFlag flag, bool value) override;
  void publish_rejected(std::uint64_t total) override;
  void log(rcm::LogLevel level, const std::string& text, double throttle_s = 0.0) override;

 private:
  struct Timing {
    std::uint64_t count = 0;
    double sum_s = 0, max_s = 0;
  };

  static void set_stamp(std_msgs_msg_dds__Header_& h, std::int64_t ns);
  void write(dds_entity_t writer, const void* sample);
  void publish_queued();

  std::string incision_, base_;
  dds_entity_t misalignment_ = 0, sd_ = 0, force_ = 0, onset_ = 0, alarm_ = 0, out_of_regime_ = 0, rejected_ = 0,
               correction_ = 0, advice_ = 0, shift_ = 0;
  double pending_correction_[3] = {0, 0, 0}, pending_shift_[3] = {0, 0, 0};  // the estimator's thread only
  geometry_msgs_msg_dds__Vector3Stamped_ vector_msg_;
  geometry_msgs_msg_dds__WrenchStamped_ wrench_msg_;
  std::map<double, std::chrono::steady_clock::time_point> last_logged_;
  std::uint64_t write_errors_ = 0;
  Timing writes_;
  OutputQueue queue_;
  std::thread publisher_;  // last: starts once everything it uses exists
};

}  // namespace rcm::dds_node
