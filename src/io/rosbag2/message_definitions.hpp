#pragma once
// Internal to io: what the bag writer's two storage files share, the message
// types and their definitions as rosbag2 stores them.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace rcm::rosbag2::detail {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

constexpr const char* kJointStateType = "sensor_msgs/msg/JointState";
constexpr const char* kWrenchType = "geometry_msgs/msg/WrenchStamped";
constexpr const char* kForceFrame = "PSM1_base";

// A topic as a storage file declares it.
struct BagTopic {
  std::string name, type, format = "cdr";
};

// The definitions rosbag2 stores with a topic (MCAP Schema data, SQLite
// message_definitions): the type's .msg text followed by its dependencies.
constexpr const char* kJointStateMsg = R"(std_msgs/Header header

string[] name
float64[] position
float64[] velocity
float64[] effort

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
)";

constexpr const char* kWrenchStampedMsg = R"(std_msgs/Header header
Wrench wrench

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec

================================================================================
MSG: geometry_msgs/Wrench
Vector3  force
Vector3  torque

================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
)";

inline std::string message_definition(const std::string& type) {
  if (type == kJointStateType) return kJointStateMsg;
  if (type == kWrenchType) return kWrenchStampedMsg;
  return "";
}

}  // namespace rcm::rosbag2::detail
