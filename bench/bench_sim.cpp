// Speed of the simulated bench. Target: the default session
// (15 min free space + 10 trials, with truth files) written in under 60 s.

#include <benchmark/benchmark.h>

#include <filesystem>
#include <unistd.h>

#include "rcm/sim/bench.hpp"

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

BENCHMARK_MAIN();
