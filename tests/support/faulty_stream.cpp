#include "support/faulty_stream.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <unistd.h>

namespace rcm::test {

const char* to_string(StreamFault fault) {
  switch (fault) {
    case StreamFault::nan_value: return "NaN value";
    case StreamFault::inf_value: return "infinite value";
    case StreamFault::nan_unread_joint: return "NaN in an unread joint";
    case StreamFault::truncated_array: return "truncated array";
    case StreamFault::duplicate: return "duplicated messages";
    case StreamFault::reorder: return "reordered messages";
    case StreamFault::drop: return "dropped messages";
    case StreamFault::stamp_ahead: return "stamp 3 h ahead";
    case StreamFault::stamp_behind: return "stamp 3 h behind";
    case StreamFault::clock_back: return "clock stepped back 2 h";
    case StreamFault::clock_forward: return "clock stepped forward 2 h";
    case StreamFault::zero_stamp: return "zero stamps";
    case StreamFault::names_reordered: return "joints reordered";
    case StreamFault::name_missing: return "joint missing";
    case StreamFault::burst: return "burst of 10000";
    case StreamFault::silence: return "10-minute silence";
  }
  return "unknown";
}

namespace {

using Verdict = LiveMonitor::Verdict;
constexpr std::int64_t kSecondNs = 1000000000LL;
constexpr std::int64_t kHourNs = 3600LL * kSecondNs;
constexpr std::int64_t kBaseNs = 1700000000LL * kSecondNs;
const std::array<const char*, 4> kNames = {"outer_yaw", "outer_pitch", "outer_insertion", "outer_roll"};

// A JointState as a middleware delivers it, with room for four joints so that
// faults reshape it without allocating.
struct Message {
  std::int64_t stamp_ns = 0, receive_ns = 0;
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
  Message() {
    name.reserve(4);
    position.reserve(4);
    velocity.reserve(4);
    effort.reserve(4);
  }
  std::vector<double>& array(int a) { return a == 0 ? position : a == 1 ? velocity : effort; }
};

class CountingSink : public MonitorSink {
 public:
  std::uint64_t estimates = 0, lines = 0, retime_lines = 0;
  void publish_estimate(std::int64_t, const OnlineOutput&) override { ++estimates; }
  void publish_flag(MonitorFlag, bool) override {}
  void publish_rejected(std::uint64_t) override {}
  void publish_correction(std::int64_t, const CorrectionOutput&) override {}
  void publish_advice(const std::string&) override {}
  void log(LogLevel, const std::string& text, double) override {
    ++lines;
    if (text.find("clock moved") != std::string::npos) ++retime_lines;
  }
};

long read_rss_kb() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  long pages = 0, resident = 0;
  const int n = std::fscanf(f, "%ld %ld", &pages, &resident);
  std::fclose(f);
  return n == 2 ? resident * (sysconf(_SC_PAGESIZE) / 1024) : 0;
}

// Which counter moved between two snapshots.
Verdict get_verdict(const LiveMonitor::Counters& before, const LiveMonitor::Counters& after) {
  if (after.accepted != before.accepted) return Verdict::accepted;
  if (after.duplicate_stamp != before.duplicate_stamp) return Verdict::duplicate_stamp;
  if (after.out_of_order != before.out_of_order) return Verdict::out_of_order;
  if (after.bad_stamp != before.bad_stamp) return Verdict::bad_stamp;
  if (after.time_jump != before.time_jump) return Verdict::time_jump;
  if (after.too_few_joints != before.too_few_joints) return Verdict::too_few_joints;
  return Verdict::malformed;
}

void add(LiveMonitor::Counters& c, Verdict v) {
  switch (v) {
    case Verdict::accepted: ++c.accepted; break;
    case Verdict::duplicate_stamp: ++c.duplicate_stamp; break;
    case Verdict::out_of_order: ++c.out_of_order; break;
    case Verdict::bad_stamp: ++c.bad_stamp; break;
    case Verdict::malformed: ++c.malformed; break;
    case Verdict::too_few_joints: ++c.too_few_joints; break;
    case Verdict::time_jump: ++c.time_jump; break;
  }
}

std::uint64_t get_window(StreamFault kind, int retime_after) {
  switch (kind) {
    case StreamFault::stamp_ahead:
    case StreamFault::stamp_behind:
    case StreamFault::silence: return 1;
    case StreamFault::clock_back:
    case StreamFault::clock_forward: return static_cast<std::uint64_t>(retime_after);
    case StreamFault::names_reordered: return 200;
    case StreamFault::burst: return 10000;
    default: return 20;
  }
}

// The looped recording, the two nodes and the injector's state.
class Soak {
 public:
  Soak(const Recording& clean, const MonitorNodeParameters& parameters, const SoakOptions& options)
      : clean_(clean),
        options_(options),
        rng_(options.seed),
        pipeline_(make_monitor_pipeline(parameters)),
        reference_(parameters, std::make_unique<OnlinePipeline>(*pipeline_), options.zero_stamp, reference_sink_),
        faulty_(parameters, std::make_unique<OnlinePipeline>(*pipeline_), options.zero_stamp, faulty_sink_) {
    if (clean_.num_samples() < 2 || clean_.position.cols() < 3)
      throw std::invalid_argument("run_soak: the recording needs 2 samples and 3 joints");
    dt_ = clean_.time[1] - clean_.time[0];
    loop_s_ = clean_.time[clean_.num_samples() - 1] - clean_.time[0] + dt_;
    retime_after_ = LiveStampRules{}.retime_after;
    for (int k = 0; k < kNumStreamFaults; ++k) order_[static_cast<std::size_t>(k)] = static_cast<StreamFault>(k);
    report_.faults.reserve(static_cast<std::size_t>(
        static_cast<double>(options.messages) * dt_ / std::max(options.fault_period_s, 1.0) + 16));
  }

  SoakReport run() {
    reference_.start("soak");
    faulty_.start("soak");
    const auto wall0 = std::chrono::steady_clock::now();
    const double total_s = static_cast<double>(options_.messages) * dt_;
    next_fault_s_ = options_.first_fault_s;
    for (std::uint64_t i = 0; i < options_.messages; ++i) {
      const double t = get_time(i);
      const StreamFault next = order_[next_kind_ % kNumStreamFaults];
      if (left_ == 0 && t >= next_fault_s_ && t + window_time(next) + get_recovery_window(next) + 2.0 < total_s)
        start_fault(i, t);
      fill(clean_message_, i, t, false);
      feed(reference_, clean_message_, nullptr);
      stream_faulty(i, t);
      track(i);
      if (t >= options_.rss_baseline_s) {
        if (report_.rss_baseline_kb == 0) report_.rss_baseline_kb = read_rss_kb();
        if (i % 20000 == 0) report_.rss_peak_after_kb = std::max(report_.rss_peak_after_kb, read_rss_kb());
      }
    }
    finish_fault();
    report_.clean_samples = options_.messages;
    report_.sample_time_s = total_s;
    report_.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    report_.rss_end_kb = read_rss_kb();
    report_.rss_peak_after_kb = std::max(report_.rss_peak_after_kb, report_.rss_end_kb);
    report_.counters = faulty_.get_monitor().get_counters();
    report_.retime_log_lines = faulty_sink_.retime_lines;
    report_.final_deviation_m = get_deviation();
    return std::move(report_);
  }

 private:
  double get_time(std::uint64_t i) const {
    const std::uint64_t n = static_cast<std::uint64_t>(clean_.num_samples());
    return clean_.time[static_cast<Eigen::Index>(i % n)] - clean_.time[0] + static_cast<double>(i / n) * loop_s_;
  }
  double window_time(StreamFault kind) const { return static_cast<double>(get_window(kind, retime_after_)) * dt_; }

  // Sample i as the clean stream (`faulty` false) or as the faulty stream's
  // clocks have it (shifted, silences, bursts).
  void fill(Message& m, std::uint64_t i, double t, bool faulty) const {
    const Eigen::Index j = static_cast<Eigen::Index>(i % static_cast<std::uint64_t>(clean_.num_samples()));
    const std::int64_t t_ns = kBaseNs + std::llround(t * 1e9);
    m.stamp_ns = faulty ? t_ns + shift_ns_ + silence_ns_ : t_ns;
    m.receive_ns = !faulty ? t_ns : burst_left_ > 0 ? burst_receive_ns_ : t_ns + silence_ns_;
    m.name.assign(kNames.begin(), kNames.end());
    m.position.assign(4, 0.0);
    m.velocity.assign(4, 0.0);
    m.effort.assign(4, 0.0);
    for (int k = 0; k < 3; ++k) {
      m.position[static_cast<std::size_t>(k)] = clean_.position(j, k);
      m.velocity[static_cast<std::size_t>(k)] = clean_.velocity(j, k);
      m.effort[static_cast<std::size_t>(k)] = clean_.effort(j, k);
    }
    m.position[3] = 0.2 * std::sin(0.5 * t);  // a roll the model does not read
    m.velocity[3] = 0.1 * std::cos(0.5 * t);
    m.effort[3] = 0.01;
  }

  void feed(MonitorNode& node, const Message& m, const Verdict* expected) {
    const LiveMonitor::Counters before = node.get_monitor().get_counters();
    try {
      node.compute_message(JointStateView{m.name, m.position, m.velocity, m.effort}, m.stamp_ns, m.receive_ns);
    } catch (const std::exception& e) {
      if (report_.exceptions++ == 0) report_.first_exception = e.what();
    }
    if (expected) {
      ++report_.messages_sent;
      add(report_.expected, *expected);
      if (get_verdict(before, node.get_monitor().get_counters()) != *expected && report_.verdict_mismatches++ == 0)
        report_.first_mismatch = std::string(to_string(kind_)) + ": expected '" + rcm::to_string(*expected) +
                                 "' at stamp " + std::to_string(m.stamp_ns);
    }
  }

  void start_fault(std::uint64_t i, double t) {
    finish_fault();
    if (next_kind_ % kNumStreamFaults == 0) std::shuffle(order_.begin(), order_.end(), rng_);
    kind_ = order_[next_kind_++ % kNumStreamFaults];
    left_ = get_window(kind_, retime_after_);
    ++report_.injected[static_cast<std::size_t>(kind_)];
    SoakFault f;
    f.kind = kind_;
    f.start_s = t;
    f.messages = left_;
    f.end_s = t + static_cast<double>(left_ - 1) * dt_;
    f.window_s = get_recovery_window(kind_);
    report_.faults.push_back(f);
    fault_end_index_ = i + left_ - 1;
    last_bad_index_ = 0;
    any_bad_ = false;
    next_fault_s_ = std::max(t + options_.fault_period_s, f.end_s + f.window_s + 2.0);
    if (kind_ == StreamFault::clock_back) shift_ns_ -= 2 * kHourNs;
    if (kind_ == StreamFault::clock_forward) shift_ns_ += 2 * kHourNs;
    if (kind_ == StreamFault::clock_back || kind_ == StreamFault::clock_forward) ++report_.expected.retimed;
    if (kind_ == StreamFault::silence) silence_ns_ += 600 * kSecondNs;
    if (kind_ == StreamFault::burst) {
      burst_left_ = left_;
      burst_receive_ns_ = kBaseNs + std::llround(t * 1e9) + silence_ns_;
    }
  }

  double get_recovery_window(StreamFault kind) const {
    if (kind != StreamFault::silence) return options_.recovery_window_s;
    return std::max(options_.recovery_window_s, pipeline_->estimator().options().max_drift_gap_s);
  }

  void finish_fault() {
    if (report_.faults.empty()) return;
    SoakFault& f = report_.faults.back();
    if (any_bad_ && last_bad_index_ >= fault_end_index_)
      f.recovery_s = static_cast<double>(last_bad_index_ - fault_end_index_ + 1) * dt_;
  }

  // The faulty stream's messages for clean sample i (none, one or two).
  void stream_faulty(std::uint64_t i, double t) {
    Message& m = faulty_message_;
    fill(m, i, t, true);
    if (burst_left_ > 0) --burst_left_;
    if (left_ == 0) {
      const Verdict v = Verdict::accepted;
      feed(faulty_, m, &v);
      return;
    }
    const std::uint64_t step = get_window(kind_, retime_after_) - left_;  // 0-based within the fault
    --left_;
    std::uniform_int_distribution<int> joint(0, 2), array(0, 2);
    Verdict v = Verdict::accepted;
    switch (kind_) {
      case StreamFault::nan_value:
        m.array(array(rng_))[static_cast<std::size_t>(joint(rng_))] = std::numeric_limits<double>::quiet_NaN();
        v = Verdict::malformed;
        break;
      case StreamFault::inf_value:
        m.array(array(rng_))[static_cast<std::size_t>(joint(rng_))] =
            (step % 2 ? -1.0 : 1.0) * std::numeric_limits<double>::infinity();
        v = Verdict::malformed;
        break;
      case StreamFault::nan_unread_joint:
        m.array(array(rng_))[3] = std::numeric_limits<double>::quiet_NaN();
        break;
      case StreamFault::truncated_array: {
        const int a = std::uniform_int_distribution<int>(0, 3)(rng_);
        if (a == 3) m.name.pop_back();
        else m.array(a).pop_back();
        v = Verdict::malformed;
        break;
      }
      case StreamFault::duplicate:
        feed(faulty_, m, &v);
        v = Verdict::duplicate_stamp;
        break;
      case StreamFault::reorder:
        if (step % 2 == 0) {  // held back, sent after the next one
          std::swap(held_message_, m);
          return;
        }
        feed(faulty_, m, &v);
        std::swap(held_message_, m);
        v = Verdict::out_of_order;
        break;
      case StreamFault::drop:  // one gap of the stamps, every message of it missing
        if (step == 0) ++report_.expected.gaps;
        ++report_.expected.missing;
        return;
      case StreamFault::stamp_ahead:
        m.stamp_ns += 3 * kHourNs;
        v = Verdict::time_jump;
        break;
      case StreamFault::stamp_behind:
        m.stamp_ns -= 3 * kHourNs;
        v = Verdict::out_of_order;
        break;
      case StreamFault::clock_back:
      case StreamFault::clock_forward:
        if (left_ > 0) v = kind_ == StreamFault::clock_back ? Verdict::out_of_order : Verdict::time_jump;
        break;
      case StreamFault::zero_stamp:
        m.stamp_ns = 0;
        v = Verdict::bad_stamp;
        break;
      case StreamFault::names_reordered: {
        std::array<int, 4> p = {0, 1, 2, 3};
        std::shuffle(p.begin(), p.end(), rng_);
        reordered_ = m;
        for (std::size_t k = 0; k < 4; ++k) {
          const auto s = static_cast<std::size_t>(p[k]);
          m.name[k] = reordered_.name[s];
          m.position[k] = reordered_.position[s];
          m.velocity[k] = reordered_.velocity[s];
          m.effort[k] = reordered_.effort[s];
        }
        break;
      }
      case StreamFault::name_missing: {
        const auto k = static_cast<std::ptrdiff_t>(joint(rng_));
        m.name.erase(m.name.begin() + k);
        m.position.erase(m.position.begin() + k);
        m.velocity.erase(m.velocity.begin() + k);
        m.effort.erase(m.effort.begin() + k);
        v = Verdict::malformed;
        break;
      }
      case StreamFault::burst:
      case StreamFault::silence:
        break;
    }
    feed(faulty_, m, &v);
  }

  double get_deviation() const {
    if (!reference_.get_monitor().started() || !faulty_.get_monitor().started()) return 0.0;
    return (faulty_.get_monitor().get_output().misalignment_m - reference_.get_monitor().get_output().misalignment_m)
        .norm();
  }

  void track(std::uint64_t i) {
    if (report_.faults.empty()) return;
    const double d = get_deviation();
    SoakFault& f = report_.faults.back();
    f.max_deviation_m = std::max(f.max_deviation_m, d);
    if (i >= fault_end_index_ && d > options_.recovery_tolerance_m) {
      last_bad_index_ = i;
      any_bad_ = true;
    }
  }

  const Recording& clean_;
  SoakOptions options_;
  std::mt19937_64 rng_;
  CountingSink reference_sink_, faulty_sink_;
  std::unique_ptr<OnlinePipeline> pipeline_;  // built once (it fits the tissue model), copied into each node
  MonitorNode reference_, faulty_;
  SoakReport report_;
  double dt_ = 0.0, loop_s_ = 0.0;
  int retime_after_ = 10;
  std::array<StreamFault, kNumStreamFaults> order_{};
  std::uint64_t next_kind_ = 0;
  StreamFault kind_ = StreamFault::drop;
  std::uint64_t left_ = 0, fault_end_index_ = 0, last_bad_index_ = 0, burst_left_ = 0;
  bool any_bad_ = false;
  double next_fault_s_ = 0.0;
  std::int64_t shift_ns_ = 0, silence_ns_ = 0, burst_receive_ns_ = 0;
  Message clean_message_, faulty_message_, held_message_, reordered_;
};

}  // namespace

double SoakReport::get_max_recovery_s() const {
  double r = 0.0;
  for (const SoakFault& f : faults) r = std::max(r, f.recovery_s);
  return r;
}

std::uint64_t SoakReport::get_unrecovered() const {
  std::uint64_t n = 0;
  for (const SoakFault& f : faults) n += f.recovery_s > f.window_s ? 1 : 0;
  return n;
}

bool SoakReport::counts_match() const {
  const auto& c = counters;
  const auto& e = expected;
  return exceptions == 0 && c.accepted == e.accepted && c.duplicate_stamp == e.duplicate_stamp &&
         c.out_of_order == e.out_of_order && c.bad_stamp == e.bad_stamp && c.malformed == e.malformed &&
         c.too_few_joints == e.too_few_joints && c.time_jump == e.time_jump &&
         c.retimed == e.retimed && c.missing == e.missing && c.gaps == e.gaps && verdict_mismatches == 0 &&
         retime_log_lines == c.retimed;
}

std::string SoakReport::to_text() const {
  std::string s;
  char line[256];
  std::snprintf(line, sizeof line,
                "%llu clean samples (%.0f s of sample time), %llu faulty messages in %.1f s (%.0f messages/s per node)\n",
                static_cast<unsigned long long>(clean_samples), sample_time_s,
                static_cast<unsigned long long>(messages_sent), wall_s,
                wall_s > 0 ? static_cast<double>(messages_sent) / wall_s : 0.0);
  s += line;
  const auto row = [&](const char* name, std::uint64_t got, std::uint64_t want) {
    std::snprintf(line, sizeof line, "  %-16s %12llu  (predicted %llu)\n", name, static_cast<unsigned long long>(got),
                  static_cast<unsigned long long>(want));
    s += line;
  };
  row("accepted", counters.accepted, expected.accepted);
  row("duplicate stamp", counters.duplicate_stamp, expected.duplicate_stamp);
  row("out of order", counters.out_of_order, expected.out_of_order);
  row("time jump", counters.time_jump, expected.time_jump);
  row("zero stamp", counters.bad_stamp, expected.bad_stamp);
  row("malformed", counters.malformed, expected.malformed);
  row("too few joints", counters.too_few_joints, expected.too_few_joints);
  row("retimed", counters.retimed, expected.retimed);
  row("missing", counters.missing, expected.missing);
  row("gaps", counters.gaps, expected.gaps);
  std::snprintf(line, sizeof line, "  exceptions %llu%s%s; verdicts unlike the prediction %llu%s%s; clock-moved log lines %llu\n",
                static_cast<unsigned long long>(exceptions), first_exception.empty() ? "" : ": ",
                first_exception.c_str(), static_cast<unsigned long long>(verdict_mismatches),
                first_mismatch.empty() ? "" : ": ", first_mismatch.c_str(),
                static_cast<unsigned long long>(retime_log_lines));
  s += line;
  s += "  fault                        injected  samples  max recovery s  max deviation mm\n";
  for (int k = 0; k < kNumStreamFaults; ++k) {
    std::uint64_t samples = 0;
    double recovery = 0.0, deviation = 0.0;
    for (const SoakFault& f : faults) {
      if (static_cast<int>(f.kind) != k) continue;
      samples += f.messages;
      recovery = std::max(recovery, f.recovery_s);
      deviation = std::max(deviation, f.max_deviation_m);
    }
    std::snprintf(line, sizeof line, "  %-28s %8llu %8llu %15.3f %17.3f\n", to_string(static_cast<StreamFault>(k)),
                  static_cast<unsigned long long>(injected[static_cast<std::size_t>(k)]),
                  static_cast<unsigned long long>(samples), recovery, 1e3 * deviation);
    s += line;
  }
  std::snprintf(line, sizeof line, "  RSS %ld kB at the baseline, peak %ld kB after it, %ld kB at the end; final deviation %.3f mm\n",
                rss_baseline_kb, rss_peak_after_kb, rss_end_kb, 1e3 * final_deviation_m);
  s += line;
  return s;
}

SoakReport run_soak(const Recording& clean, const MonitorNodeParameters& parameters, const SoakOptions& options) {
  return Soak(clean, parameters, options).run();
}

}  // namespace rcm::test
