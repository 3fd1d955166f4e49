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
LstmNetwork lstm(int in, int H, int L, int out) {
  std::mt19937 rng(1);
  std::normal_distribution<float> g(0.0f, 0.2f);
  auto rnd = [&](int r, int c) {
    Eigen::MatrixXf m(r, c);
    for (int i = 0; i < m.size(); ++i) m.data()[i] = g(rng);
    return m;
  };
  LstmNetwork n;
  for (int k = 0; k < L; ++k)
    n.layers.push_back({rnd(4 * H, k ? H : in), rnd(4 * H, H), rnd(4 * H, 1).col(0), rnd(4 * H, 1).col(0)});
  n.head.layers.push_back({rnd(64, H), rnd(64, 1).col(0), Activation::tanh});
  n.head.layers.push_back({rnd(out, 64), rnd(out, 1).col(0), Activation::identity});
  return n;
}
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

// One Adam update of the default 1 x 128 network on a 32-stream x 100-sample
// window, 2 threads, as fit_lstm_torque_model runs it.
static void BM_LibTorchTrainingStep(benchmark::State& state) {
  torch_threads_for_benchmark();
  auto step = make_libtorch_training_step(12, 128, 1, 64, 6, 32, 100);
  for (auto _ : state) step();
}
BENCHMARK(BM_LibTorchTrainingStep)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
