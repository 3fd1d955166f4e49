// Cost of the default free-space fit (the linear model, TorqueModelKind::linear)
// on the simulated bench's teleoperation: `rcm setup`, `rcm run` and every
// session of `rcm batch` pay it once unless handed a model file.

#include <benchmark/benchmark.h>

#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/sim/bench.hpp"

namespace {

// Argument: seconds of free space at the bench's 200 Hz (120: rcm setup's least).
void BM_FitLinearTorqueModel(benchmark::State& state) {
  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  config.protocol.free_space_s = static_cast<double>(state.range(0));
  const std::vector<rcm::Recording> free_space = {rcm::sim::simulate_free_space(config).recording};
  rcm::dynamics::FitOptions options;
  options.verbose = false;
  for (auto _ : state) {
    const rcm::dynamics::FitResult fit = rcm::dynamics::fit_linear_torque_model(free_space, options);
    benchmark::DoNotOptimize(fit.model.get());
  }
}

}  // namespace

BENCHMARK(BM_FitLinearTorqueModel)->ArgName("free_space_s")->Arg(120)->Unit(benchmark::kMillisecond)->Iterations(3);

BENCHMARK_MAIN();
