// Cyclone's side of the node (dds_sink.hpp).

#include "dds_sink.hpp"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace rcm::dds_node {

DdsSink::DdsSink(dds_entity_t participant, const rcm::MonitorNodeParameters& p)
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
  if (p.software_rcm) shift_ = writer(&geometry_msgs_msg_dds__Vector3Stamped__desc, prefix + "shift", stream);
  dds_delete_qos(stream);
  dds_delete_qos(latched);
  std::memset(&vector_msg_, 0, sizeof vector_msg_);
  std::memset(&wrench_msg_, 0, sizeof wrench_msg_);
  wrench_msg_.header.frame_id = const_cast<char*>(base_.c_str());
  publisher_ = std::thread([this] { publish_queued(); });
}

void DdsSink::finish() {
  queue_.close();
  if (publisher_.joinable()) publisher_.join();
}

std::string DdsSink::get_summary() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "rcm: publishing (own thread): %.2f us mean, %.1f us max per estimate (%d writes); queue depth max "
                "%zu of %zu, %llu outputs dropped\n",
                writes_.count ? 1e6 * writes_.sum_s / static_cast<double>(writes_.count) : 0.0, 1e6 * writes_.max_s,
                shift_ ? 5 : 4,
                queue_.get_max_depth(), queue_.capacity(), static_cast<unsigned long long>(queue_.get_dropped()));
  return buf;
}

void DdsSink::publish_estimate(std::int64_t stamp_ns, const rcm::OnlineOutput& out) {
  Output o;
  o.kind = Output::Kind::estimate;
  o.stamp_ns = stamp_ns;
  for (int i = 0; i < 3; ++i) {
    o.misalignment[i] = out.misalignment_m[i];
    o.sd[i] = out.sd_m[i];
    o.force[i] = out.f_inc_base[i];
    o.correction[i] = pending_correction_[i];
    o.shift[i] = pending_shift_[i];
  }
  queue_.push(o);
}

void DdsSink::publish_correction(std::int64_t, const rcm::CorrectionOutput& c) {
  for (int i = 0; i < 3; ++i) pending_correction_[i] = c.move_base[i];
}

void DdsSink::publish_shift(std::int64_t, const Eigen::Vector3d& shift_base) {
  for (int i = 0; i < 3; ++i) pending_shift_[i] = shift_base[i];
}

void DdsSink::publish_advice(const std::string& text) {
  Output o;
  o.kind = Output::Kind::advice;
  std::snprintf(o.advice, sizeof o.advice, "%s", text.c_str());
  queue_.push(o);
}

void DdsSink::publish_flag(rcm::MonitorFlag flag, bool value) {
  Output o;
  o.kind = Output::Kind::flag;
  o.flag = flag;
  o.value = value;
  queue_.push(o);
}

void DdsSink::publish_rejected(std::uint64_t total) {
  Output o;
  o.kind = Output::Kind::rejected;
  o.total = total;
  queue_.push(o);
}

void DdsSink::log(rcm::LogLevel level, const std::string& text, double throttle_s) {
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

void DdsSink::set_stamp(std_msgs_msg_dds__Header_& h, std::int64_t ns) {
  h.stamp.sec = static_cast<std::int32_t>(ns / 1000000000);
  h.stamp.nanosec = static_cast<std::uint32_t>(ns % 1000000000);
}

void DdsSink::write(dds_entity_t writer, const void* sample) {
  const dds_return_t rc = dds_write(writer, sample);
  if (rc < 0 && ++write_errors_ <= 10)
    std::fprintf(stderr, "[WARN] [rcm_monitor_dds]: write failed: %s\n", dds_strretcode(rc));
}

void DdsSink::publish_queued() {
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
        if (shift_) {
          vector_msg_.vector = {o.shift[0], o.shift[1], o.shift[2]};
          write(shift_, &vector_msg_);
        }
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

}  // namespace rcm::dds_node
