#pragma once
// The rcm-session/1 manifest (docs/formats.md): which recordings
// form a bench or clinical session, with paths relative to the manifest.

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace rcm {

struct CalibrationSpec {
  std::filesystem::path recording;  // absolute or relative to the working directory
  double coaxial_offset_m = 0.0;    // the known pure coaxial offset D*
};

struct TrialSpec {
  std::string name;
  std::filesystem::path recording;                     // step 3a, teleoperation
  std::optional<std::filesystem::path> static_recording;  // step 3b, hold at q0
  std::optional<Eigen::Vector3d> truth_misalignment_m;   // [dr_x, dr_y, D], evaluation only
};

struct Session {
  std::filesystem::path manifest;   // the JSON file this came from
  std::string robot;                // e.g. "dvrk-psm-classic"
  Eigen::Vector3d q0 = Eigen::Vector3d::Zero();
  std::vector<std::filesystem::path> free_space;
  std::optional<std::filesystem::path> baseline;
  std::optional<CalibrationSpec> calibration;
  std::vector<TrialSpec> trials;
  // "topics": {"joints": "/PSM1/measured_js", "force": "/PSM1/body/measured_cf"}:
  // the topics of the session's bags, so that the session describes itself.
  std::string joint_topic, force_topic;  // empty: not given
  nlohmann::json extra = nlohmann::json::object();  // unknown top-level fields, kept
};

// Reads and validates a manifest: format tag, known robot, q0 within the
// robot's joint limits, every referenced file present. Paths in the result are
// resolved against the manifest's directory. Throws InputError naming the
// manifest and the JSON field.
Session load_session(const std::filesystem::path& manifest);

// `base` with the session's topics: what every reader of its recordings is given.
struct RecordingReadOptions;
RecordingReadOptions get_read_options(const Session& session, RecordingReadOptions base);

// Writes a manifest (atomically) with paths made relative to its directory.
void save_session(const std::filesystem::path& manifest, const Session& session);

}  // namespace rcm
