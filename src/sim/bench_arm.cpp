#include "rcm/sim/bench_arm.hpp"

#include <algorithm>
#include <cmath>

#include "rcm/sim/arm_dynamics.hpp"

namespace rcm::sim {

namespace {

double quantize(double x, double quantum) { return quantum > 0.0 ? quantum * std::round(x / quantum) : x; }

}  // namespace

BenchArm::BenchArm(const SimConfig& config)
    : plant(config.arm, config.friction),
      controller(config.controller),
      sensors(config.sensors),
      dt(1.0 / config.controller.physics_rate_hz),
      velocity_filter_alpha(1.0 - std::exp(-2.0 * M_PI * config.controller.velocity_filter_hz * dt)) {}

int get_physics_steps_per_period(const SimConfig& config, double rate_hz) {
  return std::max(1, static_cast<int>(std::ceil(config.controller.physics_rate_hz / rate_hz - 1e-9)));
}

Eigen::Vector3d compute_measured_position(const SensorParams& sensors, const Eigen::Vector3d& qm) {
  if (!sensors.noise) return qm;
  Eigen::Vector3d m;
  for (int j = 0; j < 3; ++j) m[j] = quantize(qm[j], sensors.position_quantum[j]);
  return m;
}

BenchArmState make_bench_arm_state(const BenchArm& arm, const Eigen::Vector3d& q) {
  BenchArmState s;
  s.plant = make_plant_state_at_rest(arm.plant, q);
  // The encoders sit on the motors.
  s.q_meas_prev = compute_measured_position(arm.sensors, s.plant.qm);
  return s;
}

void compute_bench_arm_step(const BenchArm& arm, BenchArmState& state, const ReferenceSample& ref,
                            const TissueModel* tissue, BenchArmStep& step) {
  const ControllerParams& C = arm.controller;
  step.q_meas = compute_measured_position(arm.sensors, state.plant.qm);
  if (arm.sensors.noise) {
    state.velocity_filtered += arm.velocity_filter_alpha * ((step.q_meas - state.q_meas_prev) / arm.dt -
                                                            state.velocity_filtered);
    step.v_meas = state.velocity_filtered;
  } else {
    step.v_meas = state.plant.qmd;
  }
  state.q_meas_prev = step.q_meas;

  step.tau = C.kp.cwiseProduct(ref.q - step.q_meas) + C.kd.cwiseProduct(ref.qd - step.v_meas);
  if (C.feedforward)
    step.tau += compute_inverse_dynamics(arm.plant.arm, ref.q, ref.qd, ref.qdd, true) +
                arm.plant.rotor_inertia.cwiseProduct(ref.qdd);

  step.tissue = tissue ? compute_tissue_force(*tissue, state.plant.q, state.plant.qd, state.axial_z) : TissueOutput{};
  step.acceleration = compute_plant_acceleration(arm.plant, state.plant, step.tau, step.tissue.tau);
}

void advance_bench_arm_state(const BenchArm& arm, BenchArmState& state, const BenchArmStep& step,
                             const TissueModel* tissue) {
  advance_plant_state(arm.plant, state.plant, step.acceleration, arm.dt);
  if (tissue) state.axial_z = advance_tissue_state(*tissue, state.axial_z, step.tissue.axial_velocity, arm.dt);
}

Eigen::Vector3d compute_published_velocity(const SensorParams& S, const Eigen::Vector3d& v_meas,
                                           const Eigen::Vector3d& qmd, std::mt19937_64& rng,
                                           std::normal_distribution<double>& normal) {
  Eigen::Vector3d v = v_meas;
  if (S.noise && S.velocity_noise.maxCoeff() > 0.0)
    for (int j = 0; j < 3; ++j) {
      const double fade = std::min(1.0, std::abs(qmd[j]) / S.velocity_noise_fade[j]);
      v[j] += fade * S.velocity_noise[j] * normal(rng);
    }
  return v;
}

Eigen::Vector3d compute_sensed_effort(const SensorParams& S, const Eigen::Vector3d& tau, std::mt19937_64& rng,
                                      std::normal_distribution<double>& normal) {
  Eigen::Vector3d e;
  for (int j = 0; j < 3; ++j) e[j] = tau[j] + (S.noise ? S.effort_noise[j] * normal(rng) : 0.0);
  return e;
}

void set_tissue_misalignment(TissueModel& tissue, const Eigen::Vector3d& misalignment_m,
                             const Eigen::Vector3d& rate_m_per_s) {
  tissue.misalignment_m = misalignment_m;
  tissue.p_anchor_base = tissue.R_base_inc * misalignment_m;
  tissue.misalignment_rate_m_per_s = rate_m_per_s;
}

}  // namespace rcm::sim
