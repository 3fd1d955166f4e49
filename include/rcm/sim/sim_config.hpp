#pragma once
// Configuration of the simulated phantom bench (docs/simulator.md).
//
// Every number the simulator uses lives here, with its default, so that a JSON
// config file can override any of them and `rcm simulate --help` can list them.
// The same field table drives load, save and the help text (visit_config_fields),
// so the three cannot drift apart.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <variant>
#include <vector>

namespace rcm::sim {

// A rigid body of the arm. `com` and `inertia_diag` are expressed in the body's
// own frame (see ArmDynamics for which frame each body is attached to); the
// inertia is about the centre of mass, along the frame's axes.
struct RigidBodyParams {
  double mass_kg = 0.0;
  Eigen::Vector3d com_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d inertia_diag_kg_m2 = Eigen::Vector3d::Zero();
};

// How one motor drives its joint. The dVRK reads the motor's encoder and its
// current, not the link: a cable of finite stiffness lets the link lag the
// motor above a few hertz, and the effort is the rotor's inertia times the
// motor's acceleration plus what the cable transmits. Units: kg m^2, N m/rad,
// N m s/rad for the revolute joints; kg, N/m, N s/m for the insertion.
struct JointTransmissionParams {
  double rotor_inertia = 0.0;  // motor and gearhead, reflected to the joint
  double stiffness = 0.0;      // cable between motor and link; 0: rigid (motor and link one body)
  double damping = 0.0;        // cable damping
  // Share of the joint's friction (every term of JointFrictionParams) that acts
  // on the link, behind the cable; the rest acts on the motor and gearhead.
  // With a rigid transmission both sides move together and only the sum matters.
  double friction_link_share = 0.0;
};

struct ArmParams {
  // "rigid" (default: the links driven directly, no rotor inertia) or "cable"
  // (compliant transmissions, friction on both sides of the cable); the preset
  // the transmissions started from.
  std::string preset = "rigid";
  // Rotates with joint 1 only (yaw about the RCM). Frame: the base frame rotated
  // by q1 about the yaw axis.
  RigidBodyParams yaw_link;
  // Rotates with joints 1 and 2 (the pitch parallelogram, lumped). Frame: DH frame 3
  // orientation [x3 y3 z3], origin at the RCM.
  RigidBodyParams pitch_link;
  // The insertion carriage and instrument: rotates with joints 1-2 and slides
  // with q3 along z3. Its centre of mass is at com + q3 * e_z in frame-3 axes.
  RigidBodyParams insertion_stage;
  Eigen::Vector3d gravity_base_m_s2 = Eigen::Vector3d(0.0, 0.0, -9.81);
  // Constant force of the insertion stage's counterbalance spring along -z3 (N).
  double insertion_counterbalance_n = 0.0;
  // Stiffness of an elastic element along the insertion (cables, harness),
  // N/m: the stage's force grows by this much per metre of q3 (0 at q3 = 0).
  double insertion_stiffness_n_per_m = 0.0;
  std::array<JointTransmissionParams, 3> transmission{};  // yaw, pitch, insertion
};

// Most Maxwell-slip elements a joint's friction may have (a fixed bound, so
// that the plant's state has a fixed size and a step never allocates).
inline constexpr int kMaxSlipElements = 8;

// Friction of one joint: a LuGre element (Canudas de Wit et al. 1995) with
// direction-dependent Coulomb and stiction levels, plus Maxwell-slip elements
// (the rate-independent generalized Maxwell-slip model, Al-Bender et al. 2005),
// plus viscous friction and a constant offset; every part may be zero. Units:
// N m and rad for revolute joints, N and m for the prismatic one.
struct JointFrictionParams {
  double coulomb_pos = 0.0;   // Coulomb level when moving in +q
  double coulomb_neg = 0.0;   // Coulomb level when moving in -q (magnitude)
  double stiction_ratio = 1.3;  // F_s / F_c (Stribeck peak)
  double stribeck_velocity = 0.01;
  double viscous = 0.0;       // sigma_2
  double bristle_stiffness = 0.0;  // sigma_0
  double bristle_damping = 0.0;    // sigma_1
  double offset = 0.0;        // direction-independent bias (cable preload), added always
  // Maxwell-slip elements, each [breakaway displacement, force]: a spring that
  // carries force / displacement per unit deflection until it carries `force`,
  // then slips. Elements of different breakaway displacements make the
  // hysteresis loop's shape: after a reversal the friction changes by the sum of
  // min(force, stiffness x travel) over the elements, twice over, whatever the speed.
  std::vector<Eigen::Vector2d> slip_elements;
  // Damping of the elements while they stick (sigma_1 of the sticking part):
  // each element's share is its stiffness's share of their total.
  double slip_damping = 0.0;
};

struct ControllerParams {
  double physics_rate_hz = 2000.0;  // fixed integration step = control period
  Eigen::Vector3d kp = Eigen::Vector3d(400.0, 400.0, 4000.0);
  Eigen::Vector3d kd = Eigen::Vector3d(6.0, 7.0, 40.0);
  // Feed the rigid-body inverse dynamics of the reference forward (no friction
  // model, as a perfectly identified dynamic model would).
  bool feedforward = true;
  double velocity_filter_hz = 40.0;  // first-order filter on differentiated encoders
  double settle_s = 0.5;             // simulated before the first logged sample
};

struct SensorParams {
  double log_rate_hz = 200.0;
  Eigen::Vector3d effort_noise = Eigen::Vector3d(0.007, 0.007, 0.195);  // std, N m / N
  Eigen::Vector3d position_quantum = Eigen::Vector3d(2.0e-5, 2.0e-5, 2.0e-6);  // rad / m
  // White noise on the logged velocity, std per sample (rad/s, rad/s, m/s),
  // fading linearly to zero below velocity_noise_fade of motor speed: the
  // dVRK's estimate comes from encoder edges, and a motor at rest makes none.
  // The controller differentiates its encoders through its own filter.
  Eigen::Vector3d velocity_noise = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_noise_fade = Eigen::Vector3d(0.03, 0.03, 0.005);
  double force_noise_n = 0.08;       // ATI std per axis, N
  double repeat_row_probability = 0.0;  // a logged row repeats the previous one
  bool noise = true;                 // false: every sensor exact (tests)
};

struct TrajectoryParams {
  // Amplitudes of the excursion around q0 (rad, rad, m); the motion never leaves
  // q0 +- amplitude (smooth saturation).
  Eigen::Vector3d amplitude = Eigen::Vector3d(0.60, 0.50, 0.035);
  double min_frequency_hz = 0.04;
  double max_frequency_hz = 0.45;
  int harmonics = 5;
  // A long recording is a sequence of independent motions, like a surgeon's
  // teleoperation over minutes: every segment_s a new draw of the harmonics,
  // cross-faded over blend_s. Without it 15 min of free space would be one draw
  // and could miss the speeds that a trial's draw reaches.
  double segment_s = 60.0;
  double blend_s = 4.0;
  double pause_fraction = 0.15;       // share of time spent in pauses
  double pause_min_s = 0.4;
  double pause_max_s = 2.5;
  double max_theta_rad = 0.95;        // refuse a path whose pivot angle exceeds this
  // The free-space recording's path: "teleoperation" (the path above),
  // "file" (below) or "excitation", a periodic finite Fourier series per joint as the dVRK's
  // dynamics-identification runs play it: the same period over and over, never
  // at rest after its start. Trials and calibration are always teleoperation.
  std::string free_space_path = "teleoperation";
  // "file": the free-space recording plays this joint trajectory (time,
  // position_1..N, velocity_1..N; rcm excite writes one) from its first
  // sample, interpolated (SampledPath); a recording longer than the file
  // holds its last sample.
  std::string free_space_file;
  // Bounded by q0 +- amplitude, as the teleoperation.
  double excitation_period_s = 10.0;  // fundamental period
  int excitation_harmonics = 5;       // frequencies k / period, k = 1..harmonics
  double excitation_ramp_s = 2.0;     // C2 fade-in from rest at q0
  // Random coefficients of harmonic k drawn with a standard deviation k^-falloff:
  // 1 puts the motion in the low harmonics, 0 spreads it evenly.
  double excitation_falloff = 1.0;
};

struct TissueParams {
  std::string preset = "linear";      // linear | stiffening | viscoelastic | sliding
  double stiffness_n_per_m = 875.0;   // k1 of g(x) = k1 x + k3 x^3
  double cubic_n_per_m3 = 0.0;        // k3
  double damping_n_s_per_m = 0.0;     // Kelvin-Voigt damping of the stretch rate
  double axial_friction_n = 0.0;      // Coulomb level of the shaft sliding through the incision
  double axial_bristle_n_per_m = 2.0e4;
  double axial_bristle_damping_n_s_per_m = 20.0;
  double min_pad_cosine = 0.25;       // cos(theta) below which the shaft is too flat
};

struct ProtocolParams {
  Eigen::Vector3d q0 = Eigen::Vector3d(0.0, 0.0, 0.12);
  double free_space_s = 900.0;
  int free_space_files = 1;
  double baseline_approach_s = 2.5;
  double baseline_hold_s = 10.0;
  Eigen::Vector3d baseline_start_offset = Eigen::Vector3d(0.15, -0.10, 0.01);
  double calibration_offset_m = 0.030;
  double calibration_s = 60.0;
  double trial_s = 60.0;
  // Which teleoperation each trial moves through: "own" (a draw of its own per
  // trial, as a surgeon's motions differ from one trial to the next, so that the
  // free-space model errs differently in each) or "shared" (the calibration's
  // path in every trial: the trials then differ only by the misalignment).
  std::string trial_paths = "own";
  double static_return_s = 3.0;
  double static_hold_s = 10.0;  // in all, shared by the holds
  // Holds at q0 in each static file, each approached from the side opposite to
  // the previous one (1: the paper's single return and hold). A joint at rest
  // keeps the friction its last motion left, anywhere in its hysteresis band;
  // with holds approached from both sides that friction changes sign between
  // them and cancels in their mean (rcm::compute_static_hold). Between holds
  // the arm moves out to q0 +- static_approach_offset and back, in
  // static_return_s.
  int static_approaches = 2;
  Eigen::Vector3d static_approach_offset = Eigen::Vector3d(0.05, 0.05, 0.005);
  std::vector<double> coaxial_offsets_m{0.010, 0.020, 0.030, 0.040, 0.050};
  std::vector<Eigen::Vector2d> radial_offsets_m{Eigen::Vector2d(0.0, 0.0),
                                                Eigen::Vector2d(0.010, 0.015)};
  bool write_truth = true;  // *_truth.csv next to every recording
};

struct ForceAngleParams {
  std::vector<double> offsets_m{0.0, 0.010, 0.020, 0.030, 0.040};
  std::vector<double> angles_deg{-45, -30, -15, 0, 15, 30, 45};
  int pivot_joint = 1;       // 1: yaw, 2: pitch
  double move_s = 1.5;
  double hold_s = 1.5;
  double average_s = 1.0;    // averaged at the end of each hold
  bool plot = true;
};

// The speed experiment (`rcm simulate --experiment speed`): one periodic
// excitation path (as TrajectoryParams::excitation_*, with its own shape below)
// recorded at full speed and slowed down, the same path points at a fraction of
// the logging rate, as the dVRK's identification runs are logged. The shape's
// defaults are those of a dVRK identification path: a fundamental of 0.155 Hz
// and six harmonics of comparable amplitude, as far as the joints allow from q0.
struct SpeedExperimentParams {
  double duration_s = 30.0;  // of the full-speed recording, after the fade-in
  int slowdown = 2;          // the slow run: period, fade-in and duration x slowdown, log rate / slowdown
  double period_s = 6.45;    // the full-speed path's fundamental period
  int harmonics = 6;
  double ramp_s = 2.0;       // fade-in from rest at q0, at full speed
  // Bound around q0 (rad, rad, m): free space has no pad, so only the joint
  // limits bound it.
  Eigen::Vector3d amplitude = Eigen::Vector3d(1.4, 0.9, 0.11);
  double falloff = 0.0;      // as TrajectoryParams::excitation_falloff
};

struct SimConfig {
  std::uint64_t seed = 1;
  std::string robot = "dvrk-psm-classic";
  int threads = 2;  // recordings are independent; results do not depend on this
  ArmParams arm;
  std::string friction_preset = "real";  // the preset `friction` started from
  std::array<JointFrictionParams, 3> friction;
  ControllerParams controller;
  SensorParams sensors;
  TrajectoryParams trajectory;
  TissueParams tissue;
  ProtocolParams protocol;
  ForceAngleParams force_angle;
  SpeedExperimentParams speed;
};

// The defaults documented in docs/simulator.md (a Classic PSM on the phantom bench).
SimConfig make_default_config();

// Names accepted by --tissue / tissue.preset.
std::vector<std::string> get_tissue_preset_names();
// Sets every tissue field to the named preset; throws InputError for an unknown name.
void apply_tissue_preset(TissueParams& tissue, const std::string& name);

// Names accepted by --friction / friction.preset.
std::vector<std::string> get_friction_preset_names();
// Sets every joint's friction to the named preset; throws InputError for an unknown name.
void apply_friction_preset(SimConfig& config, const std::string& name);

// Names accepted by --arm / arm.preset.
std::vector<std::string> get_arm_preset_names();
// Sets the transmissions (and the effort noise that goes with them, SensorParams)
// to the named preset; throws InputError for an unknown name.
void apply_arm_preset(SimConfig& config, const std::string& name);

// Throws InputError naming `source` and the field for every inconsistent value.
void validate_config(const SimConfig& config, const std::string& source = "config");
// validate_config and what only the speed experiment needs: its path
// (speed.amplitude around protocol.q0) within the joint limits.
void validate_speed_experiment(const SimConfig& config, const std::string& source = "config");

// Overrides fields of `config` from JSON. Unknown keys and wrong types throw
// InputError naming `source` and the JSON path. `tissue.preset`, `arm.preset`
// and `friction.preset`, when present, are applied first (in that order) so
// that explicit fields override the presets.
void apply_config_json(SimConfig& config, const nlohmann::json& json, const std::string& source);
SimConfig load_config(const std::filesystem::path& path);  // defaults + file, validated
nlohmann::json config_to_json(const SimConfig& config);
void save_config(const std::filesystem::path& path, const SimConfig& config);

// One row per configurable field: JSON path, current value as text, help.
struct ConfigFieldDoc {
  std::string path;
  std::string value;
  std::string help;
};
std::vector<ConfigFieldDoc> describe_config(const SimConfig& config);

}  // namespace rcm::sim
