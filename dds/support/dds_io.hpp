#pragma once
// What every DDS program of rcm shares: QoS, return codes, the domain, stamps,
// and ROS 2 joint states to and from the generated C types.

#include <dds/dds.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "rcm/io/joint_state_map.hpp"
#include "ros2_msgs.h"

namespace rcm::dds_node {

dds_qos_t* make_qos(dds_reliability_kind_t reliability, int depth, dds_durability_kind_t durability);
// A DDS return code below zero as std::runtime_error naming `what`.
[[noreturn]] void dds_fail(const char* what, dds_return_t rc);
dds_entity_t check(dds_entity_t e, const char* what);

// The DDS domain: `flag` when >= 0, else ROS_DOMAIN_ID, else 0. Throws
// InputError naming `source` outside 0..232.
int get_domain(int flag, const std::string& source);

// A reader or a writer of one topic ("rt/" + ROS 2 name), RELIABLE, VOLATILE,
// KEEP_LAST `depth`: the dVRK's QoS.
dds_entity_t make_reader(dds_entity_t participant, const dds_topic_descriptor_t* type, const std::string& ros_name,
                         int depth);
dds_entity_t make_writer(dds_entity_t participant, const dds_topic_descriptor_t* type, const std::string& ros_name,
                         int depth);
bool is_matched_writer(dds_entity_t writer);
bool is_matched_reader(dds_entity_t reader);

// Takes every sample waiting on `reader`, calling `on_sample` with each valid
// one (and, in the second form, the writer's timestamp of it: ns, the writer's wall clock).
void take_all(dds_entity_t reader, const std::function<void(const void*)>& on_sample);
void take_all(dds_entity_t reader, const std::function<void(const void*, std::int64_t source_ns)>& on_sample);

std::int64_t get_stamp_ns(const std_msgs_msg_dds__Header_& header);
void set_stamp(std_msgs_msg_dds__Header_& header, std::int64_t ns);
// The wall clock (CLOCK_REALTIME) and a steady one, in ns.
std::int64_t get_wall_ns();
std::int64_t get_steady_ns();

// A received JointState in the vectors JointStateView borrows; capacity is kept
// from message to message, so after the first no allocation happens here.
struct JointStateBuffer {
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
  void assign(const sensor_msgs_msg_dds__JointState_& m);
  JointStateView view() const { return {name, position, velocity, effort}; }
};

// A JointState to send, its sequences pointing into vectors it owns.
class JointStateMessage {
 public:
  explicit JointStateMessage(std::vector<std::string> names = {});
  // Sets the stamp and the arrays (any may be empty) and returns the message to write.
  const sensor_msgs_msg_dds__JointState_* fill(std::int64_t stamp_ns, const double* position, std::size_t positions,
                                               const double* velocity, std::size_t velocities, const double* effort,
                                               std::size_t efforts);

 private:
  std::vector<std::string> names_;
  std::vector<char*> name_ptrs_;
  std::vector<double> position_, velocity_, effort_;
  char empty_[1] = {0};
  sensor_msgs_msg_dds__JointState_ msg_{};
};

// A header with this stamp and an empty frame id.
std_msgs_msg_dds__Header_ make_header(std::int64_t stamp_ns, const char* frame_id = "");

}  // namespace rcm::dds_node
