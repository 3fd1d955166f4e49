#pragma once
// One physics step of the bench's arm: the encoders and the controller's
// velocity filter, the position controller (PD plus rigid-body feedforward) on
// a reference sample, the tissue's force, the plant's acceleration; then the
// plant and the tissue's axial bristle advanced. The one home of that step for
// every simulation of the arm: the bench's runs (simulate_run, bench.hpp) and
// the simulated PSM behind the robot's interfaces (simulated_psm.hpp).
//
// The published sensors (the logged velocity's noise, the effort's noise) are
// drawn by the caller with the helpers below, from its own random streams, so
// that each caller keeps the order of its draws.

#include <Eigen/Core>
#include <random>

#include "rcm/sim/plant.hpp"
#include "rcm/sim/sim_config.hpp"
#include "rcm/sim/tissue.hpp"
#include "rcm/sim/trajectory.hpp"

namespace rcm::sim {

// Immutable: the plant, the controller and the sensors of one configuration,
// stepped at controller.physics_rate_hz.
struct BenchArm {
  explicit BenchArm(const SimConfig& config);
  Plant plant;
  ControllerParams controller;
  SensorParams sensors;
  double dt = 0.0;                     // physics step, s
  double velocity_filter_alpha = 0.0;  // of the controller's first-order filter at dt
};

struct BenchArmState {
  PlantState plant;
  double axial_z = 0.0;  // the tissue's axial bristle (m)
  Eigen::Vector3d q_meas_prev = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_filtered = Eigen::Vector3d::Zero();
};

// Physics steps per period of a stream at `rate_hz`: the smallest whole number
// that steps at least as fast as the configuration's physics rate (a physics
// rate that the stream's period divides).
int get_physics_steps_per_period(const SimConfig& config, double rate_hz);

// At rest at link position q (make_plant_state_at_rest), the encoders read.
BenchArmState make_bench_arm_state(const BenchArm& arm, const Eigen::Vector3d& q);

// What one step sensed, commanded and felt.
struct BenchArmStep {
  Eigen::Vector3d q_meas = Eigen::Vector3d::Zero();  // quantized motor encoders
  Eigen::Vector3d v_meas = Eigen::Vector3d::Zero();  // the controller's filtered velocity
  Eigen::Vector3d tau = Eigen::Vector3d::Zero();     // motor torque (the effort, before its noise)
  TissueOutput tissue;                               // zero in free space
  PlantAcceleration acceleration;
};

// The encoders as the sensors quantize them.
Eigen::Vector3d compute_measured_position(const SensorParams& sensors, const Eigen::Vector3d& qm);

// Reads the sensors (the velocity filter advances), runs the controller on
// `reference` and computes the tissue force (`tissue` null: free space) and the
// acceleration. Throws std::domain_error where the tissue does (the shaft too
// flat to the pad). No allocation.
void compute_bench_arm_step(const BenchArm& arm, BenchArmState& state, const ReferenceSample& reference,
                            const TissueModel* tissue, BenchArmStep& step);
// The plant by one step, and the tissue's axial bristle (when `tissue`).
void advance_bench_arm_state(const BenchArm& arm, BenchArmState& state, const BenchArmStep& step,
                             const TissueModel* tissue);

// The published velocity: the controller's, plus the dVRK's encoder-timing
// noise fading out as the motor stops (SensorParams::velocity_noise).
Eigen::Vector3d compute_published_velocity(const SensorParams& sensors, const Eigen::Vector3d& v_meas,
                                           const Eigen::Vector3d& qmd, std::mt19937_64& rng,
                                           std::normal_distribution<double>& normal);
// The logged effort: tau plus the current sensor's noise.
Eigen::Vector3d compute_sensed_effort(const SensorParams& sensors, const Eigen::Vector3d& tau, std::mt19937_64& rng,
                                      std::normal_distribution<double>& normal);

// Moves a tissue model's incision (a moving patient, or a software RCM that
// moved): its misalignment relative to the RCM and that misalignment's rate.
void set_tissue_misalignment(TissueModel& tissue, const Eigen::Vector3d& misalignment_m,
                             const Eigen::Vector3d& rate_m_per_s);

}  // namespace rcm::sim
