// The speed experiment (docs/simulator.md, "--experiment speed"): one periodic
// excitation path at full speed and slowed down, each logged as the dVRK logs
// its identification runs.

#include <fmt/format.h>

#include "parallel.hpp"
#include "rcm/sim/bench.hpp"

namespace rcm::sim {

using detail::run_parallel;

namespace {

// The experiment's path (SpeedExperimentParams) slowed down by `slowdown`: the
// same points, each reached `slowdown` times later, and logged that many times
// less often.
SimConfig slow_down(const SimConfig& config, int slowdown) {
  SimConfig c = config;
  const SpeedExperimentParams& V = config.speed;
  c.trajectory.excitation_period_s = V.period_s * slowdown;
  c.trajectory.excitation_harmonics = V.harmonics;
  c.trajectory.excitation_ramp_s = V.ramp_s * slowdown;
  c.trajectory.excitation_falloff = V.falloff;
  c.trajectory.amplitude = V.amplitude;  // the excitation's bound; this run has no teleoperation
  c.sensors.log_rate_hz /= slowdown;
  return c;
}

SimulatedRecording record(const SimConfig& config, const std::string& name, int slowdown) {
  const SimConfig c = slow_down(config, slowdown);
  ReferenceTrajectory ref;
  ref.add_path(0.0, std::make_shared<const ExcitationPath>(c.trajectory, c.protocol.q0,
                                                           derive_seed(config.seed, "path:speed")));
  // Logged from the end of the fade-in: the real runs start on the path, in motion.
  const double t0 = c.trajectory.excitation_ramp_s;
  auto recs = simulate_run(c, ref, nullptr, {{name, t0, t0 + config.speed.duration_s * slowdown}},
                           derive_seed(config.seed, "noise:speed:" + name));
  return std::move(recs.front());
}

}  // namespace

SpeedExperimentResult run_speed_experiment(const SimConfig& config) {
  validate_speed_experiment(config);
  SpeedExperimentResult r;
  std::vector<std::function<void()>> jobs;
  jobs.emplace_back([&] { r.slow = record(config, "slow", config.speed.slowdown); });
  jobs.emplace_back([&] { r.fast = record(config, "fast", 1); });
  run_parallel(jobs, config.threads);
  return r;
}

}  // namespace rcm::sim
