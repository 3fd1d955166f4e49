#pragma once
// The stream soak: a clean recording looped into a joint-state stream as long
// as wanted, fed to two MonitorNodes (the per-message path the ROS 1 and DDS
// nodes share): one the clean stream, the other the same stream with faults
// injected (bad values, bad arrays, bad names, duplicated, reordered and
// dropped messages, stamps off by hours, clocks stepped for good, zero stamps,
// bursts, silences). What a control-room process must do is checked on the
// way: nothing thrown, every rejection counted by reason and every lost
// message counted missing as the injector predicts, the estimate back within
// a tolerance of the clean run's within a window of sample time after each
// fault, and the resident memory flat.
//
// Used by tests/test_live_soak.cpp (a short stream, in `make test`) and by
// tests/soak_live.cpp (`make soak`, ten million messages).

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"
#include "rcm/live/live_monitor.hpp"
#include "rcm/live/monitor_node.hpp"

namespace rcm::test {

enum class StreamFault {
  nan_value,         // NaN in a joint the model reads: malformed
  inf_value,         // +-inf in a joint the model reads: malformed
  nan_unread_joint,  // NaN in a joint the model does not read: accepted
  truncated_array,   // one array a value short: malformed
  duplicate,         // every message sent twice: the copy is a duplicate stamp
  reorder,           // pairs swapped: the earlier of each pair is out of order
  drop,              // messages lost: counted missing, one gap
  stamp_ahead,       // one stamp hours ahead: time jump
  stamp_behind,      // one stamp hours behind: out of order
  clock_back,        // the publisher's clock steps back for good: followed after the rule's count
  clock_forward,     // ... and forward
  zero_stamp,        // invalid data (ROS 2 dVRK) or a lost stamp: zero stamp
  names_reordered,   // joints in another order, by name: accepted
  name_missing,      // a joint the model reads left out: malformed
  burst,             // ten thousand messages delivered at once: accepted
  silence,           // ten minutes without a message: accepted
};
constexpr int kNumStreamFaults = 16;
const char* to_string(StreamFault fault);

struct SoakOptions {
  std::uint64_t messages = 100000;  // clean samples streamed (the faulty stream has about as many)
  double first_fault_s = 60.0;      // sample time before the first fault (the estimate settles)
  double fault_period_s = 12.0;     // sample time from one fault's start to the next (at least)
  // The estimate must be back within this after a fault ends; after a silence
  // within the estimator's max_drift_gap_s, if longer: over a silence it lets
  // the incision move as much as in that time, by design.
  double recovery_window_s = 5.0;
  double recovery_tolerance_m = 1e-3;
  double rss_baseline_s = 60.0;     // memory is measured from this sample time on
  LiveMonitor::ZeroStamp zero_stamp = LiveMonitor::ZeroStamp::invalid;
  std::uint64_t seed = 1;
};

// One injected fault and what followed.
struct SoakFault {
  StreamFault kind;
  double start_s = 0.0, end_s = 0.0;  // clean sample time of the first and last affected sample
  std::uint64_t messages = 0;         // samples affected
  // From the end of the fault until the estimate stayed within tolerance of the
  // clean run's (until the next fault or the end); 0 when it never left it.
  double recovery_s = 0.0;
  double max_deviation_m = 0.0;  // largest deviation from the clean run, fault and recovery included
  double window_s = 0.0;         // the recovery this fault is allowed (SoakOptions::recovery_window_s)
};

struct SoakReport {
  std::uint64_t clean_samples = 0, messages_sent = 0;
  LiveMonitor::Counters counters, expected;  // the faulty node's, and the injector's prediction
  std::array<std::uint64_t, kNumStreamFaults> injected{};  // faults per kind
  std::vector<SoakFault> faults;
  std::uint64_t exceptions = 0;
  std::string first_exception;
  std::uint64_t verdict_mismatches = 0;  // messages whose verdict was not the predicted one
  std::string first_mismatch;
  std::uint64_t retime_log_lines = 0;  // the node's "clock moved" lines (one per retime)
  double sample_time_s = 0.0, wall_s = 0.0;
  long rss_baseline_kb = 0, rss_peak_after_kb = 0, rss_end_kb = 0;
  double final_deviation_m = 0.0;

  double get_max_recovery_s() const;
  std::uint64_t get_unrecovered() const;  // faults not back within their window
  // Counters equal to the prediction, nothing thrown, one log line per retime.
  bool counts_match() const;
  std::string to_text() const;  // a summary table, per fault kind
};

// Streams `clean` (a recording, looped with time going on) through a node made
// from `parameters` (as the live nodes make theirs) and through a second one with
// faults injected. The recording needs at least the model's joints; a fourth
// joint the model does not read is added to every message.
SoakReport run_soak(const Recording& clean, const MonitorNodeParameters& parameters, const SoakOptions& options);

}  // namespace rcm::test
