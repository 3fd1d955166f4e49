// LibTorch side of the LSTM comparison: one streaming step of torch::nn::LSTM
// (+ head) with its state, against the Eigen kernel on the same weights, and
// one truncated-BPTT training update as fit_lstm_torque_model runs it.
// bench/torch_compare.py runs this program next to PyTorch and writes the ratios.

#include <benchmark/benchmark.h>

#include <random>

#include "rcm/dynamics/training.hpp"

using namespace rcm::dynamics;

namespace {
void torch_threads_for_benchmark() { set_libtorch_threads(2); }
}  // namespace

namespace {
LstmNetwork lstm(int in, int H, int L, int out) { return make_random_lstm_network(in, H, L, 64, out, 1, 0.2f); }
}  // namespace

// Sizes: 6 joints -> 12 inputs, H hidden x L layers (args), head 64, 6 outputs.
static void BM_LibTorchLstmStep(benchmark::State& state) {
  set_libtorch_threads(1);  // one core, as the Eigen kernel
  auto step = make_libtorch_lstm_stepper(lstm(12, static_cast<int>(state.range(0)), static_cast<int>(state.range(1)), 6));
  float x[12] = {0.1f}, y[6];
  for (auto _ : state) {
    x[0] += 1e-4f;
    step(x, y);
    benchmark::DoNotOptimize(y);
  }
}
BENCHMARK(BM_LibTorchLstmStep)->Args({128, 1})->Args({128, 2});

static void BM_EigenLstmStep(benchmark::State& state) {
  LstmKernel k(lstm(12, static_cast<int>(state.range(0)), static_cast<int>(state.range(1)), 6));
  auto s = k.create_state();
  float x[12] = {0.1f}, y[6];
  for (auto _ : state) {
    x[0] += 1e-4f;
    k.step(s, x, y);
    benchmark::DoNotOptimize(y);
  }
}
BENCHMARK(BM_EigenLstmStep)->Args({128, 1})->Args({128, 2});

// One Adam update of the default 1 x 128 network on a streams x window batch,
// 2 threads, as fit_lstm_torque_model runs it; samples/s is the training throughput.
static void BM_LibTorchTrainingStep(benchmark::State& state) {
  torch_threads_for_benchmark();
  const auto streams = static_cast<int>(state.range(0)), window = static_cast<int>(state.range(1));
  auto step = make_libtorch_training_step(12, 128, 1, 64, 6, streams, window);
  for (auto _ : state) step();
  state.counters["samples/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * streams * window, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_LibTorchTrainingStep)
    ->ArgNames({"streams", "window"})
    ->Args({32, 100})
    ->Args({128, 25})
    ->Args({128, 50})
    ->Args({256, 50})
    ->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
