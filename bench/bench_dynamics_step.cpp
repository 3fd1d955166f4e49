// Per-sample cost of the torque models' streaming step (float kernels, no
// allocation): the default 1 x 128 LSTM on 6 joints (and other sizes), the per-joint MLP and
// the model-based linear model with its friction state.

#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/networks.hpp"

using namespace rcm::dynamics;

namespace {
LstmNetwork lstm(int in, int H, int L, int out) { return make_random_lstm_network(in, H, L, 64, out, 1, 0.2f); }
TorqueModelInfo info6() {
  TorqueModelInfo i;
  i.num_joints = 6;
  i.num_outputs = 6;
  i.sample_period_s = 0.005;
  return i;
}
Normalization norm6() {
  return {Eigen::VectorXf::Zero(12), Eigen::VectorXf::Ones(12), Eigen::VectorXf::Zero(6), Eigen::VectorXf::Ones(6)};
}
void run(benchmark::State& state, const TorqueModel& m) {
  auto ws = m.create_workspace();
  double q[6] = {0.1, 0.2, 0.12, 0, 0, 0}, qd[6] = {0.3, -0.2, 0.01, 0.1, 0, 0}, tau[6];
  double t = 0;
  for (auto _ : state) {
    // Every joint moves, as in use: a joint at rest would skip its Dahl updates.
    for (int k = 0; k < 6; ++k) q[k] += 1e-4 * (k + 1);
    t += 0.005;
    m.compute_step(*ws, t, q, qd, tau);
    benchmark::DoNotOptimize(tau);
  }
}
}  // namespace

static void BM_LstmKernelStep(benchmark::State& state) {
  const int H = static_cast<int>(state.range(0)), L = static_cast<int>(state.range(1));
  LstmKernel k(lstm(12, H, L, 6));  // AVX2/FMA kernels when the CPU has them
  state.SetLabel(to_string(k.isa()));
  auto s = k.create_state();
  Eigen::VectorXf x = Eigen::VectorXf::Constant(12, 0.1f), y(6);
  for (auto _ : state) {
    x[0] += 1e-4f;
    k.step(s, x.data(), y.data());
    benchmark::DoNotOptimize(y.data());
  }
}
BENCHMARK(BM_LstmKernelStep)->Args({128, 1})->Args({128, 2})->Args({256, 1})->Args({32, 1});

// The same step on the portable kernels (what a CPU without AVX2/FMA runs).
static void BM_LstmKernelStepPortable(benchmark::State& state) {
  const int H = static_cast<int>(state.range(0)), L = static_cast<int>(state.range(1));
  LstmKernel k(lstm(12, H, L, 6), KernelIsa::portable);
  auto s = k.create_state();
  Eigen::VectorXf x = Eigen::VectorXf::Constant(12, 0.1f), y(6);
  for (auto _ : state) {
    x[0] += 1e-4f;
    k.step(s, x.data(), y.data());
    benchmark::DoNotOptimize(y.data());
  }
}
BENCHMARK(BM_LstmKernelStepPortable)->Args({128, 1});

// The default architecture as fitted: [q, qdot], `direction` tanh(qdot / s)
// features per joint (3 by default, FitOptions::velocity_tanh_scales),
// `acceleration` filtered qddot features per joint (1 by default,
// FitOptions::acceleration_filters_s) and `dahl` Dahl states per joint (3 by
// default, FitOptions::dahl_fractions).
static void BM_LstmModelStep(benchmark::State& state) {
  const int features = static_cast<int>(state.range(0)), filters = static_cast<int>(state.range(1)),
            dahl = static_cast<int>(state.range(2));
  Normalization norm = norm6();
  norm.velocity_tanh_scale = Eigen::VectorXf::LinSpaced(6 * features, 0.003f, 0.03f);
  norm.acceleration_filter_s = Eigen::VectorXf::LinSpaced(filters, 0.03f, 0.05f);
  norm.acceleration_scale = Eigen::VectorXf::Constant(6 * filters, 2.0f);
  norm.dahl_displacement = Eigen::VectorXf::LinSpaced(6 * dahl, 1e-5f, 3e-3f);
  LstmTorqueModel m(info6(), lstm(12 + 6 * (features + filters + dahl), 128, 1, 6), norm);
  run(state, m);
}
BENCHMARK(BM_LstmModelStep)
    ->ArgNames({"direction", "acceleration", "dahl"})
    ->Args({3, 1, 3})
    ->Args({3, 1, 0})
    ->Args({3, 0, 0})
    ->Args({0, 0, 0});

static void BM_MlpModelStep(benchmark::State& state) {
  const std::vector<DenseStack> stacks = make_random_mlp_stacks(12, 100, 6, 2, 0.2f);
  MlpTorqueModel m(info6(), stacks, norm6());
  run(state, m);
}
BENCHMARK(BM_MlpModelStep);

static void BM_LinearModelStep(benchmark::State& state) {
  LinearTorqueParameters p{Eigen::VectorXd::Ones(17), Eigen::VectorXd::Ones(6), Eigen::VectorXd::Ones(6),
                           Eigen::VectorXd::Ones(6), Eigen::VectorXd::Ones(6), Eigen::VectorXd::Constant(6, 1e-3)};
  LinearTorqueModel m(info6(), p);
  run(state, m);
}
BENCHMARK(BM_LinearModelStep);

// The structure the default fit gives a yaw / pitch / insertion arm: the
// rigid-body inertia, the slow Dahl state and sqrt-velocity friction held
// beyond a speed limit, a Coulomb level along each joint's travel and a
// stiffness.
static void BM_LinearModelStepFittedStructure(benchmark::State& state) {
  LinearTorqueParameters p{Eigen::VectorXd::Ones(17), Eigen::VectorXd::Ones(6), Eigen::VectorXd::Ones(6),
                           Eigen::VectorXd::Ones(6), Eigen::VectorXd::Ones(6), Eigen::VectorXd::Constant(6, 1e-3)};
  p.inertia = Eigen::VectorXd::Constant(19, 0.1);
  p.coulomb_slow = p.sqrt_viscous = Eigen::VectorXd::Constant(6, 0.1);
  p.coulomb_profile = Eigen::MatrixXd::Constant(6, kCoulombProfileKnots, 0.05);
  p.coulomb_profile_range = Eigen::MatrixXd(6, 2);
  p.coulomb_profile_range.col(0).setConstant(-1.0);
  p.coulomb_profile_range.col(1).setConstant(1.0);
  p.stiffness = Eigen::VectorXd::Constant(6, 0.2);
  p.dahl_displacement_slow = Eigen::VectorXd::Constant(6, 0.02);
  p.friction_speed_limit = Eigen::VectorXd::Constant(6, 0.5);
  LinearTorqueModel m(info6(), p);
  run(state, m);
}
BENCHMARK(BM_LinearModelStepFittedStructure);

// The same structure with the zero-phase qddot live (live_zero_phase): per
// sample, each joint's cubic fit over the window of the sample the delay points
// at, as the default fit of a 3-joint arm gives it. Arguments: the stream's
// rate (Hz) and the zero-phase window (ms); the cost grows with the samples in
// the window.
static void BM_LinearModelStepLiveZeroPhase(benchmark::State& state) {
  const double rate = static_cast<double>(state.range(0)), window = 1e-3 * static_cast<double>(state.range(1));
  TorqueModelInfo info;
  info.num_joints = info.num_outputs = 3;
  info.sample_period_s = 0.005;
  LinearTorqueParameters p{Eigen::VectorXd::Ones(17), Eigen::VectorXd::Ones(3), Eigen::VectorXd::Ones(3),
                           Eigen::VectorXd::Ones(3), Eigen::VectorXd::Ones(3), Eigen::VectorXd::Constant(3, 1e-3)};
  p.inertia = Eigen::VectorXd::Constant(19, 0.1);
  p.coulomb_slow = p.sqrt_viscous = Eigen::VectorXd::Constant(3, 0.1);
  p.stiffness = Eigen::VectorXd::Constant(3, 0.2);
  p.dahl_displacement_slow = Eigen::VectorXd::Constant(3, 0.02);
  p.friction_speed_limit = Eigen::VectorXd::Constant(3, 0.5);
  p.batch_acceleration_window_s = Eigen::VectorXd::Constant(3, window);
  p.live_zero_phase = true;
  LinearTorqueModel m(info, p);
  auto ws = m.create_workspace();
  double q[3] = {0.1, 0.2, 0.12}, qd[3] = {0.3, -0.2, 0.01}, tau[3];
  double t = 0;
  for (auto _ : state) {
    for (int k = 0; k < 3; ++k) q[k] += 1e-4 * (k + 1);
    qd[0] = std::sin(t);
    t += 1.0 / rate;
    m.compute_step(*ws, t, q, qd, tau);
    benchmark::DoNotOptimize(tau);
  }
}
BENCHMARK(BM_LinearModelStepLiveZeroPhase)
    ->ArgNames({"rate_hz", "window_ms"})
    ->Args({100, 200})
    ->Args({200, 200})
    ->Args({200, 400})
    ->Args({1500, 200})
    ->Args({1500, 400});

BENCHMARK_MAIN();
