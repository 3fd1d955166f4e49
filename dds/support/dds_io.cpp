// What rcm's DDS programs share (dds_io.hpp).

#include "dds_io.hpp"

#include <time.h>

#include <cstdlib>
#include <stdexcept>

#include "rcm/common/error.hpp"

namespace rcm::dds_node {

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

int get_domain(int flag, const std::string& source) {
  int domain = flag;
  if (domain < 0) {
    const char* env = std::getenv("ROS_DOMAIN_ID");
    domain = env && *env ? std::atoi(env) : 0;
  }
  if (domain < 0 || domain > 232)
    throw InputError(InputLocation::plain(source, "--domain"), "must be a DDS domain id, 0..232");
  return domain;
}

namespace {

dds_entity_t make_topic(dds_entity_t participant, const dds_topic_descriptor_t* type, const std::string& ros_name) {
  const std::string name = "rt" + ros_name;
  return check(dds_create_topic(participant, type, name.c_str(), nullptr, nullptr), name.c_str());
}

}  // namespace

dds_entity_t make_reader(dds_entity_t participant, const dds_topic_descriptor_t* type, const std::string& ros_name,
                         int depth) {
  dds_qos_t* q = make_qos(DDS_RELIABILITY_RELIABLE, depth, DDS_DURABILITY_VOLATILE);
  const dds_entity_t r = dds_create_reader(participant, make_topic(participant, type, ros_name), q, nullptr);
  dds_delete_qos(q);
  return check(r, ros_name.c_str());
}

dds_entity_t make_writer(dds_entity_t participant, const dds_topic_descriptor_t* type, const std::string& ros_name,
                         int depth) {
  dds_qos_t* q = make_qos(DDS_RELIABILITY_RELIABLE, depth, DDS_DURABILITY_VOLATILE);
  const dds_entity_t w = dds_create_writer(participant, make_topic(participant, type, ros_name), q, nullptr);
  dds_delete_qos(q);
  return check(w, ros_name.c_str());
}

bool is_matched_writer(dds_entity_t writer) {
  dds_publication_matched_status_t s;
  return dds_get_publication_matched_status(writer, &s) == DDS_RETCODE_OK && s.current_count > 0;
}

bool is_matched_reader(dds_entity_t reader) {
  dds_subscription_matched_status_t s;
  return dds_get_subscription_matched_status(reader, &s) == DDS_RETCODE_OK && s.current_count > 0;
}

void take_all(dds_entity_t reader, const std::function<void(const void*)>& on_sample) {
  take_all(reader, [&](const void* sample, std::int64_t) { on_sample(sample); });
}

void take_all(dds_entity_t reader, const std::function<void(const void*, std::int64_t)>& on_sample) {
  constexpr std::size_t kBatch = 64;
  void* samples[kBatch];
  dds_sample_info_t infos[kBatch];
  while (true) {
    for (void*& s : samples) s = nullptr;  // null buffers: Cyclone lends its samples
    const dds_return_t n = dds_take(reader, samples, infos, kBatch, kBatch);
    if (n < 0) dds_fail("take", n);
    for (dds_return_t i = 0; i < n; ++i)
      if (infos[i].valid_data) on_sample(samples[i], infos[i].source_timestamp);
    if (n > 0) dds_return_loan(reader, samples, n);
    if (n < static_cast<dds_return_t>(kBatch)) return;
  }
}

std::int64_t get_stamp_ns(const std_msgs_msg_dds__Header_& h) {
  return static_cast<std::int64_t>(h.stamp.sec) * 1000000000 + static_cast<std::int64_t>(h.stamp.nanosec);
}

void set_stamp(std_msgs_msg_dds__Header_& h, std::int64_t ns) {
  h.stamp.sec = static_cast<std::int32_t>(ns / 1000000000);
  h.stamp.nanosec = static_cast<std::uint32_t>(ns % 1000000000);
}

std::int64_t get_wall_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

std::int64_t get_steady_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

void JointStateBuffer::assign(const sensor_msgs_msg_dds__JointState_& m) {
  name.resize(m.name._length);
  for (std::uint32_t i = 0; i < m.name._length; ++i) name[i].assign(m.name._buffer[i] ? m.name._buffer[i] : "");
  position.assign(m.position._buffer, m.position._buffer + m.position._length);
  velocity.assign(m.velocity._buffer, m.velocity._buffer + m.velocity._length);
  effort.assign(m.effort._buffer, m.effort._buffer + m.effort._length);
}

JointStateMessage::JointStateMessage(std::vector<std::string> names) : names_(std::move(names)) {
  for (auto& n : names_) name_ptrs_.push_back(n.data());
  msg_.header.frame_id = empty_;
  msg_.name = {static_cast<std::uint32_t>(names_.size()), static_cast<std::uint32_t>(names_.size()),
               name_ptrs_.data(), false};
}

const sensor_msgs_msg_dds__JointState_* JointStateMessage::fill(std::int64_t stamp_ns, const double* p,
                                                                std::size_t np, const double* v, std::size_t nv,
                                                                const double* e, std::size_t ne) {
  set_stamp(msg_.header, stamp_ns);
  auto seq = [](std::vector<double>& store, const double* x, std::size_t n, dds_sequence_double& out) {
    store.assign(x, x + n);
    out = {static_cast<std::uint32_t>(n), static_cast<std::uint32_t>(n), store.data(), false};
  };
  seq(position_, p, np, msg_.position);
  seq(velocity_, v, nv, msg_.velocity);
  seq(effort_, e, ne, msg_.effort);
  return &msg_;
}

std_msgs_msg_dds__Header_ make_header(std::int64_t stamp_ns, const char* frame_id) {
  std_msgs_msg_dds__Header_ h{};
  set_stamp(h, stamp_ns);
  h.frame_id = const_cast<char*>(frame_id);
  return h;
}

}  // namespace rcm::dds_node
