// Speed of the simulated bench. Target: the default session
// (15 min free space + 10 trials, with truth files) written in under 60 s.

#include <benchmark/benchmark.h>

#include <filesystem>
#include <unistd.h>

#include "rcm/sim/bench.hpp"
#include "rcm/sim/simulated_psm.hpp"

using namespace rcm::sim;

// Simulated seconds per wall-clock second of one free-space recording (1 thread).
static void BM_SimulateFreeSpace60s(benchmark::State& state) {
  SimConfig config = make_default_config();
  config.protocol.free_space_s = 60.0;
  for (auto _ : state) {
    SimulatedRecording rec = simulate_free_space(config);
    benchmark::DoNotOptimize(rec.recording.effort.data());
  }
  state.counters["sim_s_per_s"] =
      benchmark::Counter(60.0, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_SimulateFreeSpace60s)->Unit(benchmark::kMillisecond);

static void BM_ForceAngleSweep(benchmark::State& state) {
  SimConfig config = make_default_config();
  for (auto _ : state) benchmark::DoNotOptimize(run_force_angle_experiment(config).points.size());
}
BENCHMARK(BM_ForceAngleSweep)->Unit(benchmark::kMillisecond)->Iterations(1);

// The whole default session written to disk (recordings, truth files, manifest).
static void BM_DefaultSessionToDisk(benchmark::State& state) {
  const SimConfig config = make_default_config();
  const auto dir = std::filesystem::temp_directory_path() / ("rcm_bench_sim_" + std::to_string(::getpid()));
  for (auto _ : state) {
    const SessionWriteSummary s = simulate_session(config, dir);
    benchmark::DoNotOptimize(s.recordings.size());
  }
  std::filesystem::remove_all(dir);
}
BENCHMARK(BM_DefaultSessionToDisk)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// One publishing period of the simulated PSM behind CRTK (rcm_sim_psm_dds's
// arm, without the middleware): a servo_jp taken, the physics steps of the
// period (the tissue engaged), the sample published. Target: real time at
// 1.5 kHz with a core to spare, i.e. well under the period of 667 us.
static void BM_SimulatedPsmStep(benchmark::State& state) {
  SimulatedPsmOptions o;
  o.rate_hz = static_cast<double>(state.range(0));
  const SimulatedPsm psm(make_default_config(), o);
  SimulatedPsmState s = psm.create_state(1);
  psm.apply_state_command(s, "home");
  while (!s.homed) psm.compute_step(s);
  psm.apply_incision_command(s, "place 0.005 0.01 0.03");
  PsmVector q = s.setpoint;
  long k = 0;
  for (auto _ : state) {
    q[0] = 0.3 * std::sin(++k * (2.0 * M_PI * 0.2 / o.rate_hz));
    psm.apply_servo_jp(s, q.data(), 6, nullptr, 0);
    psm.compute_step(s);
    benchmark::DoNotOptimize(s.sample.effort.data());
  }
  state.counters["physics_steps"] = psm.substeps();
}
BENCHMARK(BM_SimulatedPsmStep)->Arg(200)->Arg(1000)->Arg(1500)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
