// Per-sample cost of the online misalignment estimator (target: a
// streaming update <= 20 us per sample; the dVRK runs at 1.5 kHz, 667 us per
// sample). The estimator alone (bank of 3 EKFs with Jet derivatives, onset test,
// alarm), and the whole live path: free-space model step + residual + estimator,
// with the linear model and with the hybrid (linear + 1 x 128 LSTM residual).

#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/networks.hpp"
#include "rcm/estimation/online.hpp"

namespace {

const Eigen::Vector3d kQ0(0.0, 0.0, 0.12);

rcm::OnlineEstimator make_estimator() {
  rcm::JointTissueModel tissue;
  tissue.parameters = Eigen::Vector4d(875.0, 1e5, 2.0, 0.3);
  rcm::OnlineEstimatorOptions o;
  o.torque_sigma = Eigen::Vector3d(0.03, 0.04, 0.2);
  return rcm::OnlineEstimator(rcm::make_incision_frame(kQ0), tissue, o);
}

// A pivoting path sampled at 1.5 kHz, precomputed so that only the update is timed.
struct Stream {
  std::vector<Eigen::Vector3d> q, qd, dtau;
  std::vector<double> t;
};
const Stream& stream() {
  static const Stream s = [] {
    Stream out;
    const int n = 15000;
    for (int k = 0; k < n; ++k) {
      const double t = k / 1500.0;
      out.t.push_back(t);
      out.q.push_back(kQ0 + Eigen::Vector3d(0.5 * std::sin(0.9 * t), 0.45 * std::sin(1.2 * t + 0.4), 0.02 * std::sin(0.7 * t)));
      out.qd.push_back(Eigen::Vector3d(0.45 * std::cos(0.9 * t), 0.54 * std::cos(1.2 * t + 0.4), 0.014 * std::cos(0.7 * t)));
      out.dtau.push_back(Eigen::Vector3d(0.3 * std::sin(0.9 * t), -0.2 * std::cos(1.2 * t), 1.0));
    }
    return out;
  }();
  return s;
}

rcm::dynamics::TorqueModelInfo info(int joints) {
  rcm::dynamics::TorqueModelInfo i;
  i.num_joints = joints;
  i.num_outputs = joints;
  i.sample_period_s = 1.0 / 1500.0;
  return i;
}

std::shared_ptr<const rcm::dynamics::LinearTorqueModel> linear_model(int joints) {
  const auto J = static_cast<Eigen::Index>(joints);
  rcm::dynamics::LinearTorqueParameters lp{Eigen::VectorXd::Constant(17, 0.01), Eigen::VectorXd::Constant(J, 0.01),
                                           Eigen::VectorXd::Constant(J, 0.05),  Eigen::VectorXd::Constant(J, 0.05),
                                           Eigen::VectorXd::Zero(J),            Eigen::VectorXd::Constant(J, 3e-4)};
  return std::make_shared<const rcm::dynamics::LinearTorqueModel>(info(joints), lp);
}

void run_pipeline(benchmark::State& state, const rcm::OnlinePipeline& pipeline) {
  const Stream& s = stream();
  auto ws = pipeline.create_workspace();
  std::size_t k = 0;
  double q[6] = {0, 0, 0, 0, 0, 0}, qd[6] = {0, 0, 0, 0, 0, 0}, effort[6] = {0, 0, 0, 0, 0, 0};
  for (auto _ : state) {
    if (k == s.t.size()) {
      k = 0;
      pipeline.reset(ws);
    }
    for (int j = 0; j < 3; ++j) {
      q[j] = s.q[k][j];
      qd[j] = s.qd[k][j];
      effort[j] = s.dtau[k][j];
    }
    benchmark::DoNotOptimize(pipeline.compute_sample(ws, s.t[k], q, qd, effort).misalignment_m.data());
    ++k;
  }
}

}  // namespace

static void BM_OnlineEstimatorUpdate(benchmark::State& state) {
  const rcm::OnlineEstimator estimator = make_estimator();
  const Stream& s = stream();
  auto ws = estimator.create_workspace();
  std::size_t k = 0;
  for (auto _ : state) {
    if (k == s.t.size()) {
      k = 0;
      estimator.reset(ws);
    }
    benchmark::DoNotOptimize(estimator.compute_update(ws, s.t[k], s.q[k], s.qd[k], s.dtau[k]).misalignment_m.data());
    ++k;
  }
}
BENCHMARK(BM_OnlineEstimatorUpdate);

static void BM_OnlinePipelineLinear(benchmark::State& state) {
  run_pipeline(state, rcm::OnlinePipeline(linear_model(6), make_estimator()));
}
BENCHMARK(BM_OnlinePipelineLinear);

// The same with the zero-phase qddot live, as `rcm dynamics fit` gives it by
// default (a 0.2 s window): the model's ring and the pipeline's delay line, at
// 1.5 kHz.
static void BM_OnlinePipelineLinearLiveZeroPhase(benchmark::State& state) {
  rcm::dynamics::LinearTorqueParameters p = linear_model(6)->parameters();
  p.batch_acceleration_window_s = Eigen::VectorXd::Constant(6, 0.2);
  p.live_zero_phase = true;
  run_pipeline(state, rcm::OnlinePipeline(std::make_shared<const rcm::dynamics::LinearTorqueModel>(info(6), p),
                                          make_estimator()));
}
BENCHMARK(BM_OnlinePipelineLinearLiveZeroPhase);

static void BM_OnlinePipelineHybrid(benchmark::State& state) {
  const rcm::dynamics::Normalization norm{Eigen::VectorXf::Zero(12), Eigen::VectorXf::Ones(12), Eigen::VectorXf::Zero(6),
                                          Eigen::VectorXf::Ones(6)};
  auto model = std::make_shared<const rcm::dynamics::HybridTorqueModel>(
      info(6), linear_model(6), rcm::dynamics::make_random_lstm_network(12, 128, 1, 64, 6, 1, 0.2f), norm);
  run_pipeline(state, rcm::OnlinePipeline(model, make_estimator()));
}
BENCHMARK(BM_OnlinePipelineHybrid);

// The pure LSTM, causal (0) and with its default 40 ms output delay at 1.5 kHz
// (60 samples), for which the pipeline also keeps the last 61 samples.
static void BM_OnlinePipelineLstm(benchmark::State& state) {
  const rcm::dynamics::Normalization norm{Eigen::VectorXf::Zero(12), Eigen::VectorXf::Ones(12), Eigen::VectorXf::Zero(6),
                                          Eigen::VectorXf::Ones(6)};
  auto model = std::make_shared<const rcm::dynamics::LstmTorqueModel>(
      info(6), rcm::dynamics::make_random_lstm_network(12, 128, 1, 64, 6, 1, 0.2f), norm,
      static_cast<int>(state.range(0)));
  run_pipeline(state, rcm::OnlinePipeline(model, make_estimator()));
}
BENCHMARK(BM_OnlinePipelineLstm)->ArgName("delay")->Arg(0)->Arg(60);
BENCHMARK_MAIN();
