// The CDR decoders of ROS 2 messages (sensor_msgs/msg/JointState and
// geometry_msgs/msg/WrenchStamped, big- and little-endian), whose documented
// error is cdr::DecodeError. A decoded message is encoded again in the same
// byte order and must decode to the same values; a decoded JointState is put
// through the joint map as the rosbag2 reader does.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "fuzz_support.hpp"
#include "io/rosbag2/cdr.hpp"
#include "rcm/io/message_recording.hpp"

namespace {

template <class Message>
bool decodes(const std::uint8_t* data, std::size_t size, Message& out) {
  try {
    rcm::cdr::decode(data, size, out);
    return true;
  } catch (const rcm::cdr::DecodeError&) {
    return false;
  }
}

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  const bool big_endian = size >= 2 && data[1] == 0;
  cdr::JointState js;
  if (decodes(data, size, js)) {
    const std::vector<std::uint8_t> again = cdr::encode(js, big_endian);
    cdr::JointState back;
    RCM_FUZZ_CHECK(decodes(again.data(), again.size(), back));
    RCM_FUZZ_CHECK(back.header.sec == js.header.sec && back.header.nanosec == js.header.nanosec);
    RCM_FUZZ_CHECK(back.header.frame_id == js.header.frame_id && back.name == js.name);
    RCM_FUZZ_CHECK(same_bits(back.position, js.position) && same_bits(back.velocity, js.velocity) &&
                   same_bits(back.effort, js.effort));
    // As the rosbag2 reader does with the first message of a topic.
    TopicReadOptions options;
    options.read.min_joints = 1;
    JointStateSampler sampler("fuzz.cdr", "/joints", options, "header.stamp");
    bool kept = false;
    if (fuzz::accepts([&] { kept = sampler.add(0, js.header.get_stamp_ns(), view_joint_state(js)); })) {
      RCM_FUZZ_CHECK(kept && sampler.messages() == 1);
      const std::vector<double>& v = sampler.get_values();
      RCM_FUZZ_CHECK(v.size() == 3 * static_cast<std::size_t>(sampler.num_joints()));
      RCM_FUZZ_CHECK(std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); }));
    }
  }
  cdr::WrenchStamped w;
  if (decodes(data, size, w)) {
    const std::vector<std::uint8_t> again = cdr::encode(w, big_endian);
    cdr::WrenchStamped back;
    RCM_FUZZ_CHECK(decodes(again.data(), again.size(), back));
    RCM_FUZZ_CHECK(std::memcmp(back.force, w.force, sizeof w.force) == 0 &&
                   std::memcmp(back.torque, w.torque, sizeof w.torque) == 0);
    RCM_FUZZ_CHECK(back.header.frame_id == w.header.frame_id);
  }
  return 0;
}
