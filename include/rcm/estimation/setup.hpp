#pragma once
// Is the arm ready to estimate? What the operating room needs checked between
// docking and the first estimate, on the session's own recordings:
//
// - the free-space recording: how long, which part of each joint's range and
//   speeds it covers, how many velocity reversals it holds (friction is
//   identified at reversals);
// - the free-space model fitted on it: its held-out error stated as the force
//   it causes at the incision, and whether more data would still lower it (the
//   model refitted on the first part of the data and scored on the same
//   held-out end: a learning curve of this arm's own recording);
// - the calibration: how long, how far it pivots about the incision, how much of
//   it the free-space model's regime covers, and the offset the identified
//   models find on it where the offset is known.
//
// Every shortfall is a finding that says what to do ("move the instrument
// further toward outer_pitch -0.35 rad"); the arm is ready when none is
// `missing`. The thresholds are SetupOptions, declared once with their table.
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "rcm/dynamics/regime.hpp"
#include "rcm/estimation/study.hpp"

namespace rcm {

struct SetupOptions {
  // Free space.
  double min_free_space_s = 120.0;
  // The range around q0 the free space must reach on each joint, besides what
  // the calibration reaches (0 on a joint: only the calibration's).
  Eigen::Vector3d workspace_half_range = Eigen::Vector3d(0.3, 0.3, 0.03);
  int min_reversals = 10;
  // A reversal counts once the velocity has passed this fraction of the
  // joint's peak speed in the recording on both sides: encoder noise at rest
  // is no reversal.
  double reversal_speed_fraction = 0.1;
  // Calibration.
  double min_calibration_s = 20.0;
  double min_calibration_pivot_rad = 0.17;
  // Calibration samples outside the free-space model's regime (the live flag's
  // test, dynamics::RegimeCheckOptions) beyond which it is not covered.
  double max_outside_regime_fraction = 0.10;
  // The model's held-out torque error is stated as a force at the incision at
  // this coaxial offset and pivot (a yaw pivot from q0).
  double check_offset_m = 0.03;
  double check_pivot_rad = 0.349;
  double max_force_error_n = 2.0;
  // A note when a joint's held-out RMSE exceeds this many times the spread of
  // its bulk (dynamics::JointTorqueError::robust_sd): rare spikes hold most
  // of it. Normal errors give 1.
  double max_spike_ratio = 1.5;
  // The offset the identified models find on the calibration, against its
  // known [0, 0, D*].
  double max_calibration_error_m = 0.001;
  // Learning curve: the model refitted on these shares of the fitted data (in
  // time order, the last one 1); more data would still help when the error at
  // the whole is below (1 - curve_improvement) x that at the share before it.
  std::vector<double> curve_fractions = {0.25, 0.5, 1.0};
  double curve_improvement = 0.1;
  void check() const;  // throws std::invalid_argument
};
const OptionTable<SetupOptions>& get_option_table(OptionTag<SetupOptions>);

enum class SetupSeverity { ok, note, missing };
const char* to_string(SetupSeverity severity);

struct SetupFinding {
  std::string check;  // "free_space.duration", "free_space.position.outer_pitch", ...
  SetupSeverity severity = SetupSeverity::ok;
  std::string message;
};

// One joint of the free space against what is wanted of it.
struct SetupJointCoverage {
  std::string name;
  double position_min = 0.0, position_max = 0.0;  // free space, rad or m
  double wanted_min = 0.0, wanted_max = 0.0;      // calibration and workspace
  double speed_max = 0.0;                         // free space, peak |qdot|
  double calibration_speed_max = 0.0;
  int reversals = 0;
};

// The model refitted on the first `fraction` of the fitted data (linear kinds).
struct SetupCurvePoint {
  double fraction = 1.0;
  double seconds_of_data = 0.0;
  std::vector<dynamics::JointTorqueError> errors;  // on the whole fit's held-out split
};

struct SetupReport {
  bool ready = false;
  std::vector<SetupFinding> findings;
  std::string robot;
  // Robot time: the recordings' own durations, s.
  double free_space_s = 0.0, baseline_s = 0.0, calibration_s = 0.0;
  double compute_s = 0.0;  // wall time of run_setup
  std::vector<SetupJointCoverage> joints;
  FreeSpaceModelStep free_space;
  std::vector<SetupCurvePoint> curve;  // empty for the network kinds
  double force_error_n = 0.0;          // at options.check_offset_m, check_pivot_rad
  double check_offset_m = 0.0, check_pivot_rad = 0.0;
  bool has_calibration = false;
  double calibration_pivot_max_rad = 0.0;
  dynamics::RegimeSummary calibration_regime;
  std::optional<JointTissueModel> tissue;
  std::optional<double> calibration_error_m;  // |JointTissueModel::calibration_bias_m|

  double get_robot_seconds() const { return free_space_s + baseline_s + calibration_s; }
  nlohmann::json to_json() const;
  std::string to_text() const;
};

// RMS incision force of independent joint torque errors `sigma` (N m, N m, N)
// at configuration q and coaxial offset D: Eq. 6 applied to each joint's error.
double compute_force_error_rms(const IncisionFrame& incision, const Eigen::Vector3d& q, double D,
                               const Eigen::Vector3d& sigma);

// Fits the free-space model (or loads options.model_file) and the tissue model
// as prepare_monitor does, and checks everything above. Bad input (a missing
// file, too few samples to fit) is an InputError as everywhere; a recording
// that is valid but falls short is a finding.
SetupReport run_setup(const Session& session, const StudyOptions& study, const SetupOptions& options,
                      const TorqueModelFitter& fitter);

}  // namespace rcm
