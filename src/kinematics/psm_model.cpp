#include "rcm/kinematics/psm_model.hpp"

#include <cmath>
#include <nlohmann/json.hpp>

#include "rcm/common/error.hpp"
#include "rcm/common/text_file.hpp"

namespace rcm {
namespace detail {
const std::vector<std::pair<std::string, std::string>>& builtin_robot_json();  // generated
}

namespace {

using nlohmann::json;

InputLocation at(const std::string& source, const std::string& field) {
  InputLocation where;
  where.file = source;
  where.field = field;
  where.kind = InputLocation::Kind::json_field;
  return where;
}

double get_number(const json& obj, const std::string& key, const std::string& source,
                  const std::string& path) {
  const std::string field = path + "." + key;
  if (!obj.contains(key)) throw InputError(at(source, field), "missing (expected a number)");
  const json& v = obj.at(key);
  if (!v.is_number()) throw InputError(at(source, field), "expected a number, got " + v.dump());
  const double x = v.get<double>();
  if (!std::isfinite(x)) throw InputError(at(source, field), "expected a finite number");
  return x;
}

std::string get_string(const json& obj, const std::string& key, const std::string& source,
                       const std::string& path) {
  const std::string field = path.empty() ? key : path + "." + key;
  if (!obj.contains(key)) throw InputError(at(source, field), "missing (expected a string)");
  const json& v = obj.at(key);
  if (!v.is_string()) throw InputError(at(source, field), "expected a string, got " + v.dump());
  return v.get<std::string>();
}

}  // namespace

PsmModel PsmModel::from_json_text(const std::string& text, const std::string& source) {
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {
    // parse_error, and out_of_range for a number beyond double (1e999).
    throw InputError(at(source, ""), std::string("not valid JSON: ") + e.what());
  }
  if (!doc.is_object()) throw InputError(at(source, ""), "expected a JSON object");
  const std::string format = get_string(doc, "format", source, "");
  if (format != "rcm-robot/1")
    throw InputError(at(source, "format"), "expected \"rcm-robot/1\", got \"" + format + "\"");
  const std::string convention = get_string(doc, "convention", source, "");
  if (convention != "modified-dh")
    throw InputError(at(source, "convention"),
                     "only \"modified-dh\" (Craig) is supported, got \"" + convention + "\"");

  PsmModel model;
  model.name_ = get_string(doc, "name", source, "");
  if (!doc.contains("joints") || !doc["joints"].is_array())
    throw InputError(at(source, "joints"), "expected an array of joints");
  const json& joints = doc["joints"];
  if (joints.size() < 3)
    throw InputError(at(source, "joints"),
                     "expected at least 3 joints (yaw, pitch, insertion), got " +
                         std::to_string(joints.size()));
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const std::string path = "joints[" + std::to_string(i) + "]";
    const json& j = joints[i];
    if (!j.is_object()) throw InputError(at(source, path), "expected an object");
    DhJoint joint;
    joint.name = get_string(j, "name", source, path);
    const std::string type = get_string(j, "type", source, path);
    if (type == "revolute") {
      joint.type = JointType::revolute;
    } else if (type == "prismatic") {
      joint.type = JointType::prismatic;
    } else {
      throw InputError(at(source, path + ".type"),
                       "expected \"revolute\" or \"prismatic\", got \"" + type + "\"");
    }
    joint.a = get_number(j, "a", source, path);
    joint.alpha = get_number(j, "alpha", source, path);
    joint.d = get_number(j, "d", source, path);
    joint.theta = get_number(j, "theta", source, path);
    joint.q_min = get_number(j, "qmin", source, path);
    joint.q_max = get_number(j, "qmax", source, path);
    if (!(joint.q_min < joint.q_max))
      throw InputError(at(source, path + ".qmin"), "qmin must be below qmax");
    model.joints_.push_back(joint);
  }

  // The estimator relies on the RCM structure: two revolute axes through the
  // base origin, then insertion along the shaft.
  const JointType expected[3] = {JointType::revolute, JointType::revolute, JointType::prismatic};
  for (int i = 0; i < 3; ++i) {
    const std::string path = "joints[" + std::to_string(i) + "]";
    if (model.joints_[i].type != expected[i])
      throw InputError(at(source, path + ".type"),
                       "the first three joints must be revolute, revolute, prismatic");
    if (i < 2 && (std::abs(model.joints_[i].a) > 1e-12 || std::abs(model.joints_[i].d) > 1e-12))
      throw InputError(at(source, path),
                       "joints 1 and 2 must pivot about the RCM (a = 0 and d = 0)");
  }
  if (std::abs(model.joints_[2].a) > 1e-12)
    throw InputError(at(source, "joints[2].a"), "the insertion axis must pass through the RCM (a = 0)");

  // The contract fixes the frames; a table that does not reproduce them would
  // make every force and offset silently wrong.
  KinematicsData data;
  const Eigen::Vector3d probes[] = {{0.0, 0.0, 0.1}, {0.3, -0.2, 0.12}, {-0.7, 0.5, 0.05}};
  for (const auto& q : probes) {
    compute_forward_kinematics(model, data, q);
    const Eigen::Matrix3d R = data.X_base_frame[3].linear();
    const double err = (R - compute_R_base_3(q)).cwiseAbs().maxCoeff();
    const double origin_off = data.X_base_frame[3].translation().cross(R.col(2)).norm();
    if (err > 1e-9 || origin_off > 1e-9)
      throw InputError(at(source, "joints"),
                       "the DH table does not reproduce the rcm-session/1 frame 3 "
                       "(z3 = [sin q1 cos q2, -sin q2, -cos q1 cos q2], shaft through the RCM)");
  }
  return model;
}

PsmModel PsmModel::load(const std::filesystem::path& path) {
  return from_json_text(read_text_file(path), path.string());
}

void PsmModel::check_within_limits(const Eigen::Vector3d& q, const InputLocation& where,
                                   double tolerance) const {
  for (int i = 0; i < 3; ++i) {
    const DhJoint& j = joints_[static_cast<std::size_t>(i)];
    if (!std::isfinite(q[i]) || q[i] < j.q_min - tolerance || q[i] > j.q_max + tolerance) {
      InputLocation at_joint = where;
      if (where.kind == InputLocation::Kind::json_field) at_joint.field += "[" + std::to_string(i) + "]";
      throw InputError(at_joint, "joint " + std::to_string(i + 1) + " (" + j.name + ") value " +
                                     std::to_string(q[i]) + " is outside its limits [" +
                                     std::to_string(j.q_min) + ", " + std::to_string(j.q_max) + "]");
    }
  }
}

std::vector<std::string> get_builtin_robot_names() {
  std::vector<std::string> names;
  for (const auto& entry : detail::builtin_robot_json()) names.push_back(entry.first);
  return names;
}

PsmModel load_robot_model(const std::string& name_or_path, const std::string& context) {
  for (const auto& entry : detail::builtin_robot_json())
    if (entry.first == name_or_path)
      return PsmModel::from_json_text(entry.second, "builtin:" + entry.first + ".json");
  if (name_or_path.size() > 5 && name_or_path.substr(name_or_path.size() - 5) == ".json" &&
      std::filesystem::exists(name_or_path))
    return PsmModel::load(name_or_path);
  std::string known;
  for (const auto& n : get_builtin_robot_names()) known += (known.empty() ? "" : ", ") + n;
  InputLocation where;
  where.file = context;
  throw InputError(where, "unknown robot \"" + name_or_path + "\" (known: " + known +
                              "; or give the path of an rcm-robot/1 .json file)");
}

Eigen::Isometry3d compute_dh_transform(double a, double alpha, double d, double theta) {
  const double ca = std::cos(alpha), sa = std::sin(alpha);
  const double ct = std::cos(theta), st = std::sin(theta);
  // RotX(alpha) * TransX(a) * RotZ(theta) * TransZ(d), written out.
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() << ct, -st, 0.0,
                st * ca, ct * ca, -sa,
                st * sa, ct * sa, ca;
  X.translation() << a, -sa * d, ca * d;
  return X;
}

void compute_forward_kinematics(const PsmModel& model, KinematicsData& data,
                                const Eigen::Vector3d& q) {
  data.X_base_frame[0].setIdentity();
  for (int i = 0; i < 3; ++i) {
    const DhJoint& j = model.joints()[static_cast<std::size_t>(i)];
    const bool revolute = j.type == JointType::revolute;
    const double theta = j.theta + (revolute ? q[i] : 0.0);
    const double d = j.d + (revolute ? 0.0 : q[i]);
    data.X_base_frame[i + 1] = data.X_base_frame[i] * compute_dh_transform(j.a, j.alpha, d, theta);
  }
}

ShaftDirections compute_shaft_directions(const Eigen::Vector3d& q) {
  const double s1 = std::sin(q[0]), c1 = std::cos(q[0]), s2 = std::sin(q[1]), c2 = std::cos(q[1]);
  ShaftDirections d;
  d.x3 = Eigen::Vector3d(-s1 * s2, -c2, c1 * s2);
  d.y3 = Eigen::Vector3d(-c1, 0.0, -s1);
  d.z3 = Eigen::Vector3d(s1 * c2, -s2, -c1 * c2);
  d.dz3_dq1 = Eigen::Vector3d(c1 * c2, 0.0, s1 * c2);
  d.cos_q2 = c2;
  return d;
}

Eigen::Vector3d compute_z3_base(const Eigen::Vector3d& q) { return compute_shaft_directions(q).z3; }

Eigen::Vector3d compute_x3_base(const Eigen::Vector3d& q) { return compute_shaft_directions(q).x3; }

Eigen::Vector3d compute_y3_base(const Eigen::Vector3d& q) { return compute_shaft_directions(q).y3; }

Eigen::Matrix3d compute_R_base_3(const Eigen::Vector3d& q) {
  const ShaftDirections d = compute_shaft_directions(q);
  Eigen::Matrix3d R;
  R << d.x3, d.y3, d.z3;
  return R;
}

}  // namespace rcm
