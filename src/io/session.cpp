#include "rcm/io/session.hpp"

#include "rcm/io/recording.hpp"

#include <cmath>
#include <set>

#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm {
namespace {

using nlohmann::json;

class Reader {
 public:
  explicit Reader(std::filesystem::path manifest) : manifest_(std::move(manifest)) {
    dir_ = manifest_.has_parent_path() ? manifest_.parent_path() : std::filesystem::path(".");
  }

  [[noreturn]] void fail(const std::string& field, const std::string& why) const {
    InputLocation where;
    where.file = manifest_.string();
    where.field = field.empty() ? "(top level)" : field;
    where.kind = InputLocation::Kind::json_field;
    throw InputError(where, why);
  }

  const json& require(const json& obj, const std::string& key, const std::string& path) const {
    if (!obj.contains(key)) fail(join(path, key), "missing");
    return obj.at(key);
  }

  std::string string_at(const json& v, const std::string& field) const {
    if (!v.is_string()) fail(field, "expected a string, got " + v.dump().substr(0, 60));
    return v.get<std::string>();
  }

  double number_at(const json& v, const std::string& field) const {
    if (!v.is_number()) fail(field, "expected a number, got " + v.dump().substr(0, 60));
    const double x = v.get<double>();
    if (!std::isfinite(x)) fail(field, "expected a finite number");
    return x;
  }

  Eigen::Vector3d vector3_at(const json& v, const std::string& field, bool allow_more) const {
    if (!v.is_array() || v.size() < 3 || (!allow_more && v.size() != 3))
      fail(field, std::string("expected an array of ") + (allow_more ? "at least " : "") + "3 numbers, got " +
                      v.dump().substr(0, 60));
    Eigen::Vector3d out;
    for (int i = 0; i < 3; ++i) out[i] = number_at(v[static_cast<std::size_t>(i)], field + "[" + std::to_string(i) + "]");
    for (std::size_t i = 3; i < v.size(); ++i) number_at(v[i], field + "[" + std::to_string(i) + "]");
    return out;
  }

  // A referenced recording (a file, or a rosbag2 directory): resolved against the
  // manifest's folder, checked to exist.
  std::filesystem::path file_at(const json& v, const std::string& field) const {
    const std::string rel = string_at(v, field);
    if (rel.empty()) fail(field, "empty path");
    const std::filesystem::path p = std::filesystem::path(rel).is_absolute() ? std::filesystem::path(rel) : dir_ / rel;
    std::error_code ec;
    if (!std::filesystem::exists(p, ec)) fail(field, "file not found: " + p.string());
    return p;
  }

  static std::string join(const std::string& path, const std::string& key) {
    return path.empty() ? key : path + "." + key;
  }

 private:
  std::filesystem::path manifest_;
  std::filesystem::path dir_;
};

}  // namespace

Session load_session(const std::filesystem::path& manifest) {
  const json doc = load_json_file(manifest);
  Reader r(manifest);
  if (!doc.is_object()) r.fail("", "expected a JSON object (an rcm-session/1 manifest)");

  Session s;
  s.manifest = manifest;
  const std::string format = r.string_at(r.require(doc, "format", ""), "format");
  if (format != "rcm-session/1") r.fail("format", "expected \"rcm-session/1\", got \"" + format + "\"");

  s.robot = r.string_at(r.require(doc, "robot", ""), "robot");
  const PsmModel model = [&] {
    try {
      return load_robot_model(s.robot, manifest.string());
    } catch (const InputError& e) {
      r.fail("robot", e.reason());
    }
  }();

  s.q0 = r.vector3_at(r.require(doc, "q0", ""), "q0", true);
  InputLocation q0_where;
  q0_where.file = manifest.string();
  q0_where.field = "q0";
  q0_where.kind = InputLocation::Kind::json_field;
  model.check_within_limits(s.q0, q0_where);

  const json& fs = r.require(doc, "free_space", "");
  if (!fs.is_array() || fs.empty()) r.fail("free_space", "expected a non-empty array of recording paths");
  for (std::size_t i = 0; i < fs.size(); ++i)
    s.free_space.push_back(r.file_at(fs[i], "free_space[" + std::to_string(i) + "]"));

  if (doc.contains("baseline") && !doc["baseline"].is_null()) s.baseline = r.file_at(doc["baseline"], "baseline");

  if (doc.contains("calibration") && !doc["calibration"].is_null()) {
    const json& c = doc["calibration"];
    if (!c.is_object()) r.fail("calibration", "expected an object {recording, coaxial_offset_m}");
    CalibrationSpec cal;
    cal.recording = r.file_at(r.require(c, "recording", "calibration"), "calibration.recording");
    cal.coaxial_offset_m = r.number_at(r.require(c, "coaxial_offset_m", "calibration"), "calibration.coaxial_offset_m");
    if (std::abs(cal.coaxial_offset_m) > 0.5)
      r.fail("calibration.coaxial_offset_m", "expected metres (|D*| < 0.5 m), got " + std::to_string(cal.coaxial_offset_m));
    s.calibration = cal;
  }

  if (doc.contains("trials") && !doc["trials"].is_null()) {
    const json& trials = doc["trials"];
    if (!trials.is_array()) r.fail("trials", "expected an array");
    std::set<std::string> names;
    for (std::size_t i = 0; i < trials.size(); ++i) {
      const std::string path = "trials[" + std::to_string(i) + "]";
      const json& t = trials[i];
      if (!t.is_object()) r.fail(path, "expected an object {name, recording, static, truth}");
      TrialSpec trial;
      trial.name = r.string_at(r.require(t, "name", path), path + ".name");
      if (trial.name.empty()) r.fail(path + ".name", "empty name");
      if (!names.insert(trial.name).second) r.fail(path + ".name", "duplicate trial name \"" + trial.name + "\"");
      trial.recording = r.file_at(r.require(t, "recording", path), path + ".recording");
      if (t.contains("static") && !t["static"].is_null()) trial.static_recording = r.file_at(t["static"], path + ".static");
      if (t.contains("truth") && !t["truth"].is_null()) {
        const json& truth = t["truth"];
        if (!truth.is_object()) r.fail(path + ".truth", "expected an object {misalignment_m: [x, y, D]}");
        if (truth.contains("misalignment_m"))
          trial.truth_misalignment_m = r.vector3_at(truth["misalignment_m"], path + ".truth.misalignment_m", false);
      }
      s.trials.push_back(trial);
    }
  }

  if (doc.contains("topics") && !doc["topics"].is_null()) {
    const json& t = doc["topics"];
    if (!t.is_object()) r.fail("topics", "expected an object {joints, force} of topic names");
    for (auto it = t.begin(); it != t.end(); ++it) {
      if (it.key() != "joints" && it.key() != "force")
        r.fail("topics." + it.key(), "unknown: the topics are \"joints\" (sensor_msgs JointState) and \"force\" "
                                     "(geometry_msgs WrenchStamped)");
      const std::string name = r.string_at(it.value(), "topics." + it.key());
      if (name.empty()) r.fail("topics." + it.key(), "empty topic name");
      (it.key() == "joints" ? s.joint_topic : s.force_topic) = name;
    }
  }

  static const std::set<std::string> known = {"format", "robot", "q0", "free_space", "baseline", "calibration",
                                              "trials", "topics"};
  for (auto it = doc.begin(); it != doc.end(); ++it)
    if (!known.count(it.key())) s.extra[it.key()] = it.value();
  return s;
}

void save_session(const std::filesystem::path& manifest, const Session& s) {
  const std::filesystem::path dir =
      std::filesystem::absolute(manifest.has_parent_path() ? manifest.parent_path() : std::filesystem::path("."));
  auto rel = [&](const std::filesystem::path& p) {
    return std::filesystem::absolute(p).lexically_relative(dir).generic_string();
  };
  json doc = s.extra.is_object() ? s.extra : json::object();
  doc["format"] = "rcm-session/1";
  doc["robot"] = s.robot;
  doc["q0"] = {s.q0[0], s.q0[1], s.q0[2]};
  doc["free_space"] = json::array();
  for (const auto& p : s.free_space) doc["free_space"].push_back(rel(p));
  if (s.baseline) doc["baseline"] = rel(*s.baseline);
  if (s.calibration)
    doc["calibration"] = {{"recording", rel(s.calibration->recording)},
                          {"coaxial_offset_m", s.calibration->coaxial_offset_m}};
  doc["trials"] = json::array();
  for (const auto& t : s.trials) {
    json jt = {{"name", t.name}, {"recording", rel(t.recording)}};
    if (t.static_recording) jt["static"] = rel(*t.static_recording);
    if (t.truth_misalignment_m) {
      const Eigen::Vector3d& m = *t.truth_misalignment_m;
      jt["truth"] = {{"misalignment_m", {m[0], m[1], m[2]}}};
    }
    doc["trials"].push_back(jt);
  }
  if (!s.joint_topic.empty() || !s.force_topic.empty()) {
    doc["topics"] = json::object();
    if (!s.joint_topic.empty()) doc["topics"]["joints"] = s.joint_topic;
    if (!s.force_topic.empty()) doc["topics"]["force"] = s.force_topic;
  }
  save_json_file(manifest, doc);
}

RecordingReadOptions get_read_options(const Session& session, RecordingReadOptions base) {
  if (!session.joint_topic.empty()) base.joint_topic = session.joint_topic;
  if (!session.force_topic.empty()) base.force_topic = session.force_topic;
  return base;
}

}  // namespace rcm
