#pragma once
// The robot description: a modified-DH chain read from a JSON data file
// (data/robots/*.json, format "rcm-robot/1"). Immutable once loaded; every
// computation takes it by const reference together with a workspace.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"

namespace rcm {

enum class JointType { revolute, prismatic };

struct DhJoint {
  std::string name;
  JointType type = JointType::revolute;
  double a = 0.0;      // a(i-1), m
  double alpha = 0.0;  // alpha(i-1), rad
  double d = 0.0;      // constant part of d(i), m (a prismatic joint adds q)
  double theta = 0.0;  // constant part of theta(i), rad (a revolute joint adds q)
  double q_min = 0.0, q_max = 0.0;  // limits, rad or m
};

class PsmModel {
 public:
  // Parses and validates "rcm-robot/1" JSON text. The first three joints must be
  // revolute, revolute, prismatic with the first two axes through the base
  // origin (the RCM), and the chain must reproduce the contract's insertion
  // axis z3(q); anything else is an InputError naming `source` and the field.
  static PsmModel from_json_text(const std::string& text, const std::string& source);
  static PsmModel load(const std::filesystem::path& path);

  const std::string& name() const { return name_; }
  const std::vector<DhJoint>& joints() const { return joints_; }
  int num_joints() const { return static_cast<int>(joints_.size()); }
  // l_tool: the insertion depth at which frame 3 passes through the RCM.
  double tool_offset() const { return -joints_[2].d; }

  // Throws InputError at `where` if q is outside the limits of the first three
  // joints by more than `tolerance` (a JSON field gets the index appended: q0[1]).
  void check_within_limits(const Eigen::Vector3d& q, const InputLocation& where,
                           double tolerance = 1e-9) const;

 private:
  std::string name_;
  std::vector<DhJoint> joints_;
};

// Robots shipped with rcm (their JSON is compiled into the library).
std::vector<std::string> get_builtin_robot_names();

// `name_or_path` is a built-in robot name or a path to an rcm-robot/1 file.
// Unknown names throw InputError listing the known ones.
PsmModel load_robot_model(const std::string& name_or_path,
                          const std::string& context_for_errors = "robot");

// Workspace of forward kinematics: frames 0..3 of the first three joints.
struct KinematicsData {
  std::array<Eigen::Isometry3d, 4> X_base_frame;  // X_base_frame[0] = identity
  KinematicsData() { X_base_frame.fill(Eigen::Isometry3d::Identity()); }
};

// Modified-DH link transform X_{i-1,i}.
Eigen::Isometry3d compute_dh_transform(double a, double alpha, double d, double theta);

// Fills data.X_base_frame[1..3] for joint values q (first three joints).
void compute_forward_kinematics(const PsmModel& model, KinematicsData& data,
                                const Eigen::Vector3d& q);

inline const Eigen::Isometry3d& get_frame_pose(const KinematicsData& data, int frame) {
  return data.X_base_frame[static_cast<std::size_t>(frame)];
}

// The shaft's directions at q in the base frame, from one evaluation of the
// trigonometry: the one home of the closed forms that J_D, the incision force,
// the three-step and joint estimators and the simulator use. x3, y3, z3 are the
// columns of the rotation of DH frame 3 (docs/formats.md); the insertion axis
// z3 turns with dz3/dq1 = yaw axis x z3 (norm |cos q2|) and dz3/dq2 = x3.
struct ShaftDirections {
  Eigen::Vector3d x3 = Eigen::Vector3d::Zero(), y3 = Eigen::Vector3d::Zero(), z3 = Eigen::Vector3d::Zero();
  Eigen::Vector3d dz3_dq1 = Eigen::Vector3d::Zero();
  double cos_q2 = 1.0;  // dz3_dq1's norm, with its sign
  const Eigen::Vector3d& get_dz3_dq2() const { return x3; }
};
ShaftDirections compute_shaft_directions(const Eigen::Vector3d& q);

// Columns of the rotation of DH frame 3 in the base frame, one at a time.
Eigen::Vector3d compute_z3_base(const Eigen::Vector3d& q);  // insertion axis
Eigen::Vector3d compute_x3_base(const Eigen::Vector3d& q);
Eigen::Vector3d compute_y3_base(const Eigen::Vector3d& q);
Eigen::Matrix3d compute_R_base_3(const Eigen::Vector3d& q);  // [x3 y3 z3]

}  // namespace rcm
