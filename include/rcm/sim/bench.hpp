#pragma once
// The simulated phantom bench: a closed-loop PSM (PD + rigid-body feedforward,
// integrated at the physics rate) tracking a reference, with LuGre friction, the
// tissue pad, and the sensors of a real bench (quantized encoders, differentiated
// velocities, noisy efforts, an ATI force sensor), logged at 200 Hz.
//
// Every recording comes with its ground truth in memory (SimTruth), including
// the free-space torque a perfect model would predict, friction state included:
//   effort (noise-free) = tau_fs + J_D^T f.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"
#include "rcm/io/plot.hpp"
#include "rcm/sim/sim_config.hpp"
#include "rcm/sim/tissue.hpp"
#include "rcm/sim/trajectory.hpp"

namespace rcm::sim {

// Per logged sample (T rows, aligned with Recording::time).
struct SimTruth {
  Eigen::MatrixXd q, qd, qdd;   // true joint state, T x 3
  Eigen::MatrixXd tau;          // actuator effort without sensor noise, T x 3
  Eigen::MatrixXd tau_fs;       // M qdd + C qd + g + friction (with its state), T x 3
  Eigen::MatrixXd friction;     // friction part of tau_fs, T x 3
  Eigen::MatrixXd force;        // tissue force on the tissue, base frame, T x 3 (0 in free space)
  Eigen::VectorXd theta;        // pivot angle from z3(q0), rad
  Eigen::VectorXd shaft_distance;  // D sec(theta), m (0 in free space)
};

struct SimulatedRecording {
  std::string name;
  Recording recording;
  SimTruth truth;
  bool tissue_engaged = false;
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();
};

// A logged slice [t_begin, t_end) of one continuous run, written as one recording.
struct RunSegment {
  std::string name;
  double t_begin = 0.0, t_end = 0.0;
};

// What a closed loop adds to a run (sim/closed_loop.hpp): an incision that
// moves, and an RCM that is a setpoint (a software-RCM arm with the same
// joint-space dynamics: the joints pivot about wherever the setpoint is).
struct RunHooks {
  // The incision relative to the RCM as it is at time t (incision frame),
  // called every physics step: the tissue's anchor follows it.
  std::function<Eigen::Vector3d(double t)> get_misalignment;
  // Its rate (m/s; optional: none means zero), for the tissue's damping and
  // axial friction: a smooth motion's derivative, not a step's jump.
  std::function<Eigen::Vector3d(double t)> get_misalignment_rate;
  // Every logged sample as the sensors give it, and the true incision force
  // (base frame), in time order; here the loop reads the arm and moves the RCM.
  std::function<void(double t, const Eigen::Vector3d& q, const Eigen::Vector3d& qd, const Eigen::Vector3d& effort,
                     const Eigen::Vector3d& f_true_base)>
      on_sample;
};

// Simulates one continuous run from t = -settle_s to the last segment's end;
// the robot starts at rest at the reference's initial pose. `tissue` null means
// free space. Deterministic in (config, reference, tissue, noise_seed, and
// what the hooks do).
std::vector<SimulatedRecording> simulate_run(const SimConfig& config,
                                             const ReferenceTrajectory& reference,
                                             const TissueModel* tissue,
                                             const std::vector<RunSegment>& segments,
                                             std::uint64_t noise_seed, const RunHooks* hooks = nullptr);

// A stream seed from the master seed and a name (splitmix64 of both).
std::uint64_t derive_seed(std::uint64_t seed, const std::string& stream);

// The session's protocol, one recording (or trial) at a time.
SimulatedRecording simulate_free_space(const SimConfig& config, int index = 0);
SimulatedRecording simulate_baseline(const SimConfig& config);
SimulatedRecording simulate_calibration(const SimConfig& config);
struct SimulatedTrial {
  std::string name;
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();
  SimulatedRecording recording;          // teleoperation along the shared path
  SimulatedRecording static_recording;   // return to q0 and hold; time continues
};
SimulatedTrial simulate_trial(const SimConfig& config, const Eigen::Vector3d& misalignment_m);
// "D30_r10_15" for [0.010, 0.015, 0.030] m.
std::string get_trial_name(const Eigen::Vector3d& misalignment_m);
// The teleoperation reference shared by calibration and trials (starts at q0).
ReferenceTrajectory make_teleop_reference(const SimConfig& config, const std::string& stream,
                                          double duration_s);

struct RecordingFileInfo {
  std::string name;
  std::filesystem::path file;
  std::filesystem::path truth_file;  // empty when not written
  std::size_t samples = 0;
  double duration_s = 0.0;
  Eigen::Vector3d effort_min = Eigen::Vector3d::Zero(), effort_max = Eigen::Vector3d::Zero();
  Eigen::Vector3d effort_noise_hf = Eigen::Vector3d::Zero();  // RMS of the effort noise above 5 Hz
  double force_max_n = 0.0;        // max |f| of the truth
  double theta_max_rad = 0.0;
};

struct SessionWriteSummary {
  std::filesystem::path manifest;
  std::vector<RecordingFileInfo> recordings;
  double elapsed_s = 0.0;
};

// Writes the whole session (rcm-session/1) under out_dir: recordings, *_truth.csv
// (when protocol.write_truth), sim_config.json (the resolved configuration) and
// session.json with the truth of every trial. Recordings are simulated on
// config.threads threads; the files do not depend on the thread count. An
// interrupt (rcm/common/interrupt.hpp) stops it with Interrupted, whose message
// lists the recordings written; session.json is then not written.
SessionWriteSummary simulate_session(const SimConfig& config, const std::filesystem::path& out_dir,
                                     const std::function<void(const std::string&)>& progress = {});

// Truth CSV, itself a valid recording of the noise-free signals: time,
// position_i, velocity_i (true q, qd), effort_i (actuator effort without noise),
// force_x..z (true tissue force), then qdd_i, tau_fs_i, friction_i, theta,
// shaft_distance.
void save_truth_csv(const std::filesystem::path& path, const SimulatedRecording& rec);
RecordingFileInfo summarize_simulated_recording(const SimulatedRecording& rec);

// The speed experiment: one periodic excitation path (SpeedExperimentParams)
// at full speed, logged at sensors.log_rate_hz for speed.duration_s after its
// fade-in ("fast"), and the same path slowed down by speed.slowdown, logged at
// log_rate_hz / slowdown for slowdown times as long ("slow"): row k of both is
// the same point of the path. A model fitted on one speed and scored on the
// other, as on a dVRK's identification runs.
struct SpeedExperimentResult {
  SimulatedRecording fast, slow;
};
SpeedExperimentResult run_speed_experiment(const SimConfig& config);

// Fig. 3: static force at the incision vs pivot angle for several coaxial offsets.
struct ForceAnglePoint {
  double offset_m = 0.0;
  double theta_rad = 0.0;          // commanded (signed)
  double theta_true_rad = 0.0;     // reached pivot angle (unsigned)
  double force_n = 0.0;            // mean |f| of the ATI during the hold
  double force_std_n = 0.0;
  double force_true_n = 0.0;       // mean |f| of the truth
  double force_law_n = 0.0;        // g(D tan(theta_true)) of the elastic law alone
};
struct ForceAngleResult {
  std::vector<ForceAnglePoint> points;
};
ForceAngleResult run_force_angle_experiment(const SimConfig& config);
// offset_m,theta_rad,force_n,theta_deg,force_std_n,force_true_n,force_law_n,theta_true_rad
void save_force_angle_csv(const std::filesystem::path& path, const ForceAngleResult& result);
PlotFiles save_force_angle_plot(const std::filesystem::path& stem, const ForceAngleResult& result);

}  // namespace rcm::sim
