#pragma once
// One sensor_msgs/JointState put in a fixed joint order and checked, without
// allocating: what the ROS 1 and rosbag2 readers and the live nodes share, so
// that every recording and every live topic is held to the same rules. The
// message is seen through JointStateView, so that this layer knows no
// middleware: ROS 1's generated struct, a CDR-decoded ROS 2 message and a DDS
// sample all have the same four arrays.
//
// Rules (those of the CSV reader, in message terms):
// - position, velocity and effort must all be present (non-empty);
// - with names: every array has as many entries as `name`, and every joint of
//   the map is found by name exactly once (any order, extra joints ignored;
//   repeated names are caught when the order is resolved: on the first message
//   and on every message whose order differs from the previous one's);
// - without names (positional): the three arrays have the same length, equal to
//   the message size the map was made with; the map reads the first joints;
// - every value read is finite (joints the map does not read are not checked).
// Time is the caller's business (the bag reader and the node differ on what a
// bad stamp means: an error or a rejected sample).

#include <cstddef>
#include <string>
#include <vector>

namespace rcm {

// The four arrays of a sensor_msgs/JointState, borrowed from the message.
struct JointStateView {
  const std::vector<std::string>& name;
  const std::vector<double>& position;
  const std::vector<double>& velocity;
  const std::vector<double>& effort;
};

// Any message type with the four JointState arrays (ROS 1, decoded ROS 2).
template <class Message>
JointStateView view_joint_state(const Message& m) {
  return {m.name, m.position, m.velocity, m.effort};
}

// What is wrong with a message; `kind == none` when nothing is. Plain data so
// that a rejection costs no allocation; describe() makes the text (allocates).
struct JointStateDefect {
  enum class Kind {
    none,
    missing_array,   // `array` is empty
    lengths,         // `array` has `size` entries, `expected` wanted
    missing_names,   // the map orders by name, the message has no names
    missing_joint,   // joint `joint` of the map is not among the message's names
    duplicate_name,  // joint `joint` of the map appears twice in the message
    not_finite,      // array[index] (joint `joint` of the map) is NaN or infinite
  };
  Kind kind = Kind::none;
  const char* array = "";  // "name", "position", "velocity" or "effort"
  std::size_t index = 0;   // index in the message's array
  std::size_t size = 0, expected = 0;
  int joint = -1;          // joint of the map (0-based)

  explicit operator bool() const { return kind != Kind::none; }
};

// The joint order of a recording or of the live estimator: by name when the
// messages carry names, positional otherwise. Immutable; per-message buffers
// live in a Workspace.
class JointStateMap {
 public:
  struct Workspace {
    std::vector<double> position, velocity, effort;  // num_joints() each, the map's order
    std::vector<std::size_t> source;  // message index of each joint, cached from the last message
  };

  JointStateMap() = default;
  // By name: `names` in the order wanted (unique, non-empty).
  explicit JointStateMap(std::vector<std::string> names);
  // Positional: messages without names, exactly `message_size` entries each
  // (0: num_joints), of which the first `num_joints` are read.
  static JointStateMap make_positional(int num_joints, int message_size = 0);
  // The order of a first message: by its names when it has any, else positional
  // over its position array; only its first `max_joints` joints when > 0.
  static JointStateMap make_from_message(const JointStateView& message, int max_joints = 0);

  int num_joints() const { return num_joints_; }
  bool by_name() const { return !names_.empty(); }
  const std::vector<std::string>& names() const { return names_; }

  Workspace create_workspace() const;

  // Checks `message` and writes its values in this map's order into the
  // workspace. Returns the first defect found (the workspace is then partly
  // written). No allocation.
  JointStateDefect compute_sample(Workspace& workspace, const JointStateView& message) const;

  // "effort[2] ('outer_insertion'): expected a finite number, got nan" and the like.
  std::string describe(const JointStateDefect& defect, const JointStateView& message) const;

 private:
  std::vector<std::string> names_;
  int num_joints_ = 0;
  int message_size_ = 0;  // positional maps
};

}  // namespace rcm
