// rcm_monitor_dds: the online misalignment estimator of `rcm monitor` on a
// live dVRK over ROS 2, without ROS 2: a plain Cyclone DDS participant that
// does on the wire what a ROS 2 node does (DDS topic rt/<arm>/measured_js, type
// sensor_msgs::msg::dds_::JointState_, XCDR1, domain ROS_DOMAIN_ID), so that
// it talks to the dVRK's ROS 2 node whatever DDS that one uses. What to
// publish and log is rcm::MonitorNode (live/, shared with the ROS 1 node);
// this file is Cyclone's side of it. Topics, QoS, parameters: docs/ros2.md.
//
//   rcm_monitor_dds --session session.json --model-file free_space_model.json [--arm PSM1] [--params-file P.yaml]

#include <CLI/CLI.hpp>
#include <dds/dds.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <pthread.h>
#include <sched.h>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <condition_variable>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/live/monitor_node.hpp"
#include "ros2_msgs.h"

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop = true; }

rcm::InputLocation param_location(const std::string& file, const std::string& name) {
  return rcm::InputLocation::plain(file, name);
}

// A ROS 2 parameters file: `<node>:` or `/**:`, then `ros__parameters:`.
void read_params_file(const std::string& file, const std::string& node_name, rcm::MonitorNodeParameters& p) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(file);
  } catch (const YAML::Exception& e) {
    rcm::InputLocation where = param_location(file, "");
    if (e.mark.line >= 0) where.line = static_cast<std::size_t>(e.mark.line) + 1;
    throw rcm::InputError(where, "not a readable YAML parameters file: " + e.msg);
  }
  YAML::Node params;
  for (const std::string& key : {node_name, "/" + node_name, std::string("/**")})
    if (root[key] && root[key]["ros__parameters"]) params = root[key]["ros__parameters"];
  if (!params || !params.IsMap())
    throw rcm::InputError(param_location(file, node_name + ".ros__parameters"),
                          "missing: a ROS 2 parameters file has '" + node_name + ":' (or '/**:') then "
                          "'ros__parameters:'");
  for (const auto& kv : params) {
    const std::string name = kv.first.as<std::string>();
    const YAML::Node& v = kv.second;
    const rcm::InputLocation where = param_location(file, node_name + ".ros__parameters." + name);
    try {
      if (name == "session") p.session = v.as<std::string>();
      else if (name == "model_file") p.model_file = v.as<std::string>();
      else if (name == "arm") p.arm = v.as<std::string>();
      else if (name == "joint_names")
        p.joint_names = v.IsSequence() ? v.as<std::vector<std::string>>()
                                       : rcm::parse_joint_names(v.as<std::string>(), where);
      else if (name == "alarm_force_n") p.alarm_force_n = v.as<double>();
      else if (name == "onset_threshold") p.onset_threshold = v.as<double>();
      else if (name == "publish_every") p.publish_every = v.as<int>();
      else if (name == "queue_size") p.queue_size = v.as<int>();
      else if (name == "base_frame") p.base_frame = v.as<std::string>();
      else if (name == "incision_frame") p.incision_frame = v.as<std::string>();
      else if (name == "dedupe") p.dedupe = v.as<bool>();
      else if (name == "seed") p.seed = v.as<int>();
      else if (name == "status_period_s") p.status_period_s = v.as<double>();
      else if (name == "tolerance_m") p.correction.tolerance_m = v.as<double>();
      else if (name == "compensate_limit_m") p.correction.compensate_limit_m = v.as<double>();
      else if (name == "max_shift_rate_m_per_s") p.correction.max_rate_m_per_s = v.as<double>();
      else throw rcm::InputError(where, "unknown parameter");
    } catch (const YAML::Exception& e) {
      throw rcm::InputError(where, "wrong type: " + e.msg);
    }
  }
}

// The value of `--params-file` before CLI11 parses, so that the file's values
// become the flags' defaults and every flag given overrides them.
std::string find_params_file(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--params-file" && i + 1 < argc) return argv[i + 1];
    if (a.rfind("--params-file=", 0) == 0) return a.substr(14);
  }
  return {};
}

dds_qos_t* make_qos(dds_reliability_kind_t reliability, int depth, dds_durability_kind_t durability) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, reliability, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
  dds_qset_durability(q, durability);
  return q;
}

[[noreturn]] void dds_fail(const char* what, dds_return_t rc) {
  throw std::runtime_error(std::string("DDS: ") + what + ": " + dds_strretcode(rc));
}

dds_entity_t check(dds_entity_t e, const char* what) {
  if (e < 0) dds_fail(what, e);
  return e;
}

// One output of the node: queued by the estimator's thread, written by the
// publisher thread. Plain data, so that queueing it costs no allocation.
struct Output {
  enum class Kind { estimate, flag, rejected, advice } kind = Kind::estimate;
  std::int64_t stamp_ns = 0;
  double misalignment[3] = {0, 0, 0}, sd[3] = {0, 0, 0}, force[3] = {0, 0, 0}, correction[3] = {0, 0, 0};
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
  DdsSink(dds_entity_t participant, const rcm::MonitorNodeParameters& p)
      : incision_(p.get_incision_frame()), base_(p.get_base_frame()),
        queue_(static_cast<std::size_t>(std::max(p.queue_size, 64))) {
    const std::string prefix = "rt/" + p.get_output_prefix();
    dds_qos_t* stream = make_qos(DDS_RELIABILITY_RELIABLE, p.queue_size, DDS_DURABILITY_VOLATILE);
    dds_qos_t* latched = make_qos(DDS_RELIABILITY_RELIABLE, 1, DDS_DURABILITY_TRANSIENT_LOCAL);
    auto writer = [&](const dds_topic_descriptor_t* type, const std::string& name, const dds_qos_t* qos) {
      const dds_entity_t topic = check(dds_create_topic(participant, type, name.c_str(), nullptr, nullptr), name.c_str());
      return check(dds_create_writer(participant, topic, qos, nullptr), name.c_str());
    };
    misalignment_ = writer(&geometry_msgs_msg_dds__Vector3Stamped__desc, prefix + "misalignment", stream);
    sd_ = writer(&geometry_msgs_msg_dds__Vector3Stamped__desc, prefix + "misalignment_sd", stream);
    force_ = writer(&geometry_msgs_msg_dds__WrenchStamped__desc, prefix + "incision_force", stream);
    onset_ = writer(&std_msgs_msg_dds__Bool__desc, prefix + "onset", latched);
    alarm_ = writer(&std_msgs_msg_dds__Bool__desc, prefix + "alarm", latched);
    out_of_regime_ = writer(&std_msgs_msg_dds__Bool__desc, prefix + "out_of_regime", latched);
    rejected_ = writer(&std_msgs_msg_dds__UInt64__desc, prefix + "rejected_samples", latched);
    correction_ = writer(&geometry_msgs_msg_dds__Vector3Stamped__desc, prefix + "correction", stream);
    advice_ = writer(&std_msgs_msg_dds__String__desc, prefix + "advice", latched);
    dds_delete_qos(stream);
    dds_delete_qos(latched);
    std::memset(&vector_msg_, 0, sizeof vector_msg_);
    std::memset(&wrench_msg_, 0, sizeof wrench_msg_);
    wrench_msg_.header.frame_id = const_cast<char*>(base_.c_str());
    publisher_ = std::thread([this] { publish_queued(); });
  }
  ~DdsSink() override { finish(); }

  // Writes what is still queued and stops the publisher thread.
  void finish() {
    queue_.close();
    if (publisher_.joinable()) publisher_.join();
  }
  // For the exit summary, after finish().
  std::string get_summary() const {
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "rcm: publishing (own thread): %.2f us mean, %.1f us max per estimate (4 writes); queue depth max "
                  "%zu of %zu, %llu outputs dropped\n",
                  writes_.count ? 1e6 * writes_.sum_s / static_cast<double>(writes_.count) : 0.0, 1e6 * writes_.max_s,
                  queue_.get_max_depth(), queue_.capacity(), static_cast<unsigned long long>(queue_.get_dropped()));
    return buf;
  }

  void publish_estimate(std::int64_t stamp_ns, const rcm::OnlineOutput& out) override {
    Output o;
    o.kind = Output::Kind::estimate;
    o.stamp_ns = stamp_ns;
    for (int i = 0; i < 3; ++i) {
      o.misalignment[i] = out.misalignment_m[i];
      o.sd[i] = out.sd_m[i];
      o.force[i] = out.f_inc_base[i];
      o.correction[i] = pending_correction_[i];
    }
    queue_.push(o);
  }
  // The node core calls publish_correction just before publish_estimate, with
  // the same stamp, on the estimator's thread: one queued output carries both.
  void publish_correction(std::int64_t, const rcm::CorrectionOutput& c) override {
    for (int i = 0; i < 3; ++i) pending_correction_[i] = c.move_base[i];
  }
  void publish_advice(const std::string& text) override {
    Output o;
    o.kind = Output::Kind::advice;
    std::snprintf(o.advice, sizeof o.advice, "%s", text.c_str());
    queue_.push(o);
  }
  void publish_flag(rcm::MonitorFlag flag, bool value) override {
    Output o;
    o.kind = Output::Kind::flag;
    o.flag = flag;
    o.value = value;
    queue_.push(o);
  }
  void publish_rejected(std::uint64_t total) override {
    Output o;
    o.kind = Output::Kind::rejected;
    o.total = total;
    queue_.push(o);
  }
  void log(rcm::LogLevel level, const std::string& text, double throttle_s = 0.0) override {
    const auto now = std::chrono::steady_clock::now();
    if (throttle_s > 0) {  // the core throttles one kind of line per period
      auto it = last_logged_.find(throttle_s);
      if (it != last_logged_.end() && std::chrono::duration<double>(now - it->second).count() < throttle_s) return;
      last_logged_[throttle_s] = now;
    }
    const double t = static_cast<double>(dds_time()) * 1e-9;
    std::fprintf(level == rcm::LogLevel::info ? stdout : stderr, "[%s] [%.6f] [rcm_monitor_dds]: %s\n",
                 level == rcm::LogLevel::info ? "INFO" : level == rcm::LogLevel::warn ? "WARN" : "ERROR", t,
                 text.c_str());
  }

 private:
  struct Timing {
    std::uint64_t count = 0;
    double sum_s = 0, max_s = 0;
  };

  static void set_stamp(std_msgs_msg_dds__Header_& h, std::int64_t ns) {
    h.stamp.sec = static_cast<std::int32_t>(ns / 1000000000);
    h.stamp.nanosec = static_cast<std::uint32_t>(ns % 1000000000);
  }
  void write(dds_entity_t writer, const void* sample) {
    const dds_return_t rc = dds_write(writer, sample);
    if (rc < 0 && ++write_errors_ <= 10)
      std::fprintf(stderr, "[WARN] [rcm_monitor_dds]: write failed: %s\n", dds_strretcode(rc));
  }
  void publish_queued() {
    // SCHED_BATCH: woken by a queued output, this thread does not preempt the
    // estimator's thread on the same core; it runs when that one is done.
    sched_param param{};
    pthread_setschedparam(pthread_self(), SCHED_BATCH, &param);
    std::vector<Output> batch;
    batch.reserve(queue_.capacity());
    while (queue_.pop_all(batch)) {
      for (const Output& o : batch) {
        if (o.kind == Output::Kind::estimate) {
          const auto start = std::chrono::steady_clock::now();
          set_stamp(vector_msg_.header, o.stamp_ns);
          vector_msg_.header.frame_id = const_cast<char*>(incision_.c_str());
          vector_msg_.vector = {o.misalignment[0], o.misalignment[1], o.misalignment[2]};
          write(misalignment_, &vector_msg_);
          vector_msg_.vector = {o.sd[0], o.sd[1], o.sd[2]};
          write(sd_, &vector_msg_);
          set_stamp(wrench_msg_.header, o.stamp_ns);
          wrench_msg_.wrench.force = {o.force[0], o.force[1], o.force[2]};
          write(force_, &wrench_msg_);
          vector_msg_.header.frame_id = const_cast<char*>(base_.c_str());
          vector_msg_.vector = {o.correction[0], o.correction[1], o.correction[2]};
          write(correction_, &vector_msg_);
          const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
          ++writes_.count;
          writes_.sum_s += s;
          writes_.max_s = std::max(writes_.max_s, s);
        } else if (o.kind == Output::Kind::flag) {
          std_msgs_msg_dds__Bool_ m{o.value};
          write(o.flag == rcm::MonitorFlag::onset ? onset_ : o.flag == rcm::MonitorFlag::alarm ? alarm_ : out_of_regime_,
                &m);
        } else if (o.kind == Output::Kind::advice) {
          std_msgs_msg_dds__String_ m{const_cast<char*>(o.advice)};
          write(advice_, &m);
        } else {
          std_msgs_msg_dds__UInt64_ m{o.total};
          write(rejected_, &m);
        }
      }
    }
  }

  std::string incision_, base_;
  dds_entity_t misalignment_ = 0, sd_ = 0, force_ = 0, onset_ = 0, alarm_ = 0, out_of_regime_ = 0, rejected_ = 0,
               correction_ = 0, advice_ = 0;
  double pending_correction_[3] = {0, 0, 0};  // the estimator's thread only
  geometry_msgs_msg_dds__Vector3Stamped_ vector_msg_;
  geometry_msgs_msg_dds__WrenchStamped_ wrench_msg_;
  std::map<double, std::chrono::steady_clock::time_point> last_logged_;
  std::uint64_t write_errors_ = 0;
  Timing writes_;
  OutputQueue queue_;
  std::thread publisher_;  // last: starts once everything it uses exists
};

// A DDS JointState sample in the vectors JointStateView borrows; capacity is
// kept from message to message, so after the first no allocation happens here.
struct JointStateBuffer {
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
  void assign(const sensor_msgs_msg_dds__JointState_& m) {
    name.resize(m.name._length);
    for (std::uint32_t i = 0; i < m.name._length; ++i) name[i].assign(m.name._buffer[i] ? m.name._buffer[i] : "");
    position.assign(m.position._buffer, m.position._buffer + m.position._length);
    velocity.assign(m.velocity._buffer, m.velocity._buffer + m.velocity._length);
    effort.assign(m.effort._buffer, m.effort._buffer + m.effort._length);
  }
};

int run(int argc, char** argv) {
  rcm::MonitorNodeParameters p;
  std::string node_name = "rcm_monitor_dds";
  const std::string params_file = find_params_file(argc, argv);
  for (int i = 1; i < argc; ++i)  // the node name decides which key of the file is read
    if (std::string(argv[i]) == "--node-name" && i + 1 < argc) node_name = argv[i + 1];
  if (!params_file.empty()) read_params_file(params_file, node_name, p);

  CLI::App app{"rcm_monitor_dds: the online RCM misalignment estimator on a live dVRK over ROS 2 (DDS)"};
  std::string joint_names, params_file_flag;
  int domain = -1;
  bool best_effort = false;
  app.add_option("--params-file", params_file_flag, "ROS 2 parameters file (YAML); flags override its values");
  app.add_option("--node-name", node_name, "the node's name: the key read in the parameters file")->capture_default_str();
  app.add_option("--session", p.session, "rcm-session/1 manifest (calibration, q0)");
  app.add_option("--model-file", p.model_file, "saved free-space model (free_space_model.json of rcm run)");
  app.add_option("--arm", p.arm, "arm namespace: subscribes <arm>/measured_js, publishes <arm>/rcm/...")->capture_default_str();
  app.add_option("--joint-names", joint_names, "joint order of the model, comma separated (default: the first message's)");
  app.add_option("--alarm-force-n", p.alarm_force_n, "force alarm threshold (N)")->capture_default_str();
  app.add_option("--onset-threshold", p.onset_threshold, "onset detector threshold")->capture_default_str();
  app.add_option("--publish-every", p.publish_every, "publish every n-th estimate")->capture_default_str();
  app.add_option("--queue-size", p.queue_size, "history depth of the estimate topics")->capture_default_str();
  app.add_option("--base-frame", p.base_frame, "frame_id of incision_force (default <arm>_base)");
  app.add_option("--incision-frame", p.incision_frame, "frame_id of misalignment (default <arm>_incision)");
  app.add_flag("--dedupe", p.dedupe, "drop repeated samples in the session's recordings");
  app.add_option("--seed", p.seed, "seed of the joint method's setup")->capture_default_str();
  app.add_option("--status-period-s", p.status_period_s, "seconds between status lines (0: none)")->capture_default_str();
  app.add_option("--tolerance-m", p.correction.tolerance_m, "correction: aligned within this distance (m)")
      ->capture_default_str();
  app.add_option("--compensate-limit-m", p.correction.compensate_limit_m,
                 "correction: software RCM shifts up to this, beyond it re-docking advice (m)")
      ->capture_default_str();
  app.add_option("--max-shift-rate-m-per-s", p.correction.max_rate_m_per_s,
                 "correction: speed of the software RCM shift (m/s)")
      ->capture_default_str();
  app.add_option("--domain", domain, "DDS domain (default: ROS_DOMAIN_ID, else 0)");
  app.add_flag("--best-effort", best_effort,
               "subscribe best-effort (matches best-effort publishers; the dVRK's are reliable)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  const std::string source = params_file.empty() ? "command line" : "command line / " + params_file;
  if (!joint_names.empty()) p.joint_names = rcm::parse_joint_names(joint_names, param_location(source, "--joint-names"));
  p.check([&](const std::string& name) { return param_location(source, name); });
  if (domain < 0) {
    const char* env = std::getenv("ROS_DOMAIN_ID");
    domain = env && *env ? std::atoi(env) : 0;
  }
  if (domain < 0 || domain > 232)
    throw rcm::InputError(param_location(source, "--domain"), "must be a DDS domain id, 0..232");

  std::string models;
  std::unique_ptr<rcm::OnlinePipeline> pipeline = rcm::make_monitor_pipeline(p, &models);

  const dds_entity_t participant = check(dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr),
                                         "create participant");
  DdsSink sink(participant, p);
  sink.log(rcm::LogLevel::info, "rcm: " + models);
  rcm::MonitorNode node(p, std::move(pipeline), rcm::LiveMonitor::ZeroStamp::invalid, sink);

  const std::string input = "rt/" + p.get_input_topic();
  const dds_entity_t topic = check(
      dds_create_topic(participant, &sensor_msgs_msg_dds__JointState__desc, input.c_str(), nullptr, nullptr), "topic");
  dds_qos_t* qos = make_qos(best_effort ? DDS_RELIABILITY_BEST_EFFORT : DDS_RELIABILITY_RELIABLE, 100,
                            DDS_DURABILITY_VOLATILE);
  const dds_entity_t reader = check(dds_create_reader(participant, topic, qos, nullptr), "reader");
  dds_delete_qos(qos);
  check(dds_set_status_mask(reader, DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS | DDS_SUBSCRIPTION_MATCHED_STATUS |
                                        DDS_DATA_AVAILABLE_STATUS),
        "status");
  const dds_entity_t waitset = check(dds_create_waitset(participant), "waitset");
  check(dds_waitset_attach(waitset, reader, reader), "attach");
  node.start(input + " (domain " + std::to_string(domain) + (best_effort ? ", best effort)" : ", reliable)"));

  constexpr std::size_t kBatch = 64;
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  JointStateBuffer buffer;
  const rcm::JointStateView view{buffer.name, buffer.position, buffer.velocity, buffer.effort};
  while (!g_stop) {
    const dds_return_t woke = dds_waitset_wait(waitset, nullptr, 0, DDS_MSECS(100));
    if (woke < 0) dds_fail("wait", woke);
    std::uint32_t status = 0;
    if (dds_take_status(reader, &status, DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS) == DDS_RETCODE_OK && status)
      sink.log(rcm::LogLevel::warn, "rcm: a publisher on " + input + " does not match this subscription's QoS" +
                                        (best_effort ? "" : " (a best-effort publisher? restart with --best-effort)"));
    // Samples sent before the subscription matches their writer are not
    // delivered (VOLATILE): say when the robot's publisher comes and goes.
    dds_subscription_matched_status_t matched;
    if (dds_get_subscription_matched_status(reader, &matched) == DDS_RETCODE_OK && matched.current_count_change != 0)
      sink.log(rcm::LogLevel::info,
               "rcm: " + std::to_string(matched.current_count) + " publisher(s) matched on " + input);
    while (true) {
      for (void*& s : samples) s = nullptr;  // null buffers: Cyclone lends its samples
      const dds_return_t n = dds_take(reader, samples, infos, kBatch, kBatch);
      if (n < 0) dds_fail("take", n);
      for (dds_return_t i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(samples[i]);
        buffer.assign(m);
        const std::int64_t stamp =
            static_cast<std::int64_t>(m.header.stamp.sec) * 1000000000 + static_cast<std::int64_t>(m.header.stamp.nanosec);
        node.compute_message(view, stamp, dds_time());
      }
      if (n > 0) dds_return_loan(reader, samples, n);
      if (n < static_cast<dds_return_t>(kBatch)) break;
    }
  }
  sink.finish();
  std::fputs(node.get_summary().c_str(), stderr);
  std::fputs(sink.get_summary().c_str(), stderr);
  dds_delete(participant);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // log lines appear as they come when redirected to a file
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try {
    return run(argc, argv);
  } catch (const rcm::InputError& e) {
    std::fprintf(stderr, "rcm_monitor_dds: error: %s\n", e.what());
    return 2;
  } catch (const std::invalid_argument& e) {  // e.g. fewer joint names than the model reads
    std::fprintf(stderr, "rcm_monitor_dds: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rcm_monitor_dds: error: %s\n", e.what());
    return 1;
  }
}
