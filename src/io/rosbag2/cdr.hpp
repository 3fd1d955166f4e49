#pragma once
// ROS 2 messages in CDR (XCDR1, the rmw layers' wire and rosbag2 "cdr" format):
// the two types rcm reads, decoded by hand so that rcm needs no ROS 2.
//
// Layout: a 4-byte encapsulation header (00 00 big-endian, 00 01
// little-endian; the last two bytes are options, ignored), then the fields,
// each aligned to its size counted from the byte after the header; a string
// is a uint32 length that includes the terminating NUL, then its bytes; a
// sequence is a uint32 count, then its elements. Every length and count is
// checked against the bytes left before anything is allocated, so a corrupt
// message is an error, never a giant allocation or a read past the end.

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace rcm::cdr {

// A message that does not decode: `field` is the field being read, `offset` its
// byte offset in the message.
class DecodeError : public std::runtime_error {
 public:
  DecodeError(std::string field, std::size_t offset, const std::string& what);
  const std::string& field() const noexcept { return field_; }
  std::size_t offset() const noexcept { return offset_; }

 private:
  std::string field_;
  std::size_t offset_;
};

struct Header {
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
  std::string frame_id;
  bool is_zero() const { return sec == 0 && nanosec == 0; }
  std::int64_t get_stamp_ns() const { return static_cast<std::int64_t>(sec) * 1000000000 + nanosec; }
};

// sensor_msgs/msg/JointState.
struct JointState {
  Header header;
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
};

// geometry_msgs/msg/WrenchStamped.
struct WrenchStamped {
  Header header;
  double force[3] = {0, 0, 0};
  double torque[3] = {0, 0, 0};
};

// Decode into `out`, reusing its buffers. Throws DecodeError.
void decode(const std::uint8_t* data, std::size_t size, JointState& out);
void decode(const std::uint8_t* data, std::size_t size, WrenchStamped& out);

// The encoders, for tests and for writing recordings (little-endian unless `big_endian`).
std::vector<std::uint8_t> encode(const JointState& message, bool big_endian = false);
std::vector<std::uint8_t> encode(const WrenchStamped& message, bool big_endian = false);

}  // namespace rcm::cdr
