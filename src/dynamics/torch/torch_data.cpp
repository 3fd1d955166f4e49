// The training data of the networks: inputs [q, qdot, direction,
// acceleration and Dahl features] and targets of every recording, normalized
// with the statistics of the training split.

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <limits>

#include "torch_parts.hpp"

namespace rcm::dynamics::torch_detail {

SequenceData prepare_data(const std::vector<Recording>& recs, const std::vector<Eigen::MatrixXd>& targets,
                          const TimeSplit& split, int N, int M, const InputFeatures& features) {
  const std::vector<double>& velocity_tanh_scales = features.velocity_tanh_scales;
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(2 * N + M), sum2 = Eigen::VectorXd::Zero(2 * N + M);
  double n = 0;
  for (const auto& seg : split.train)
    for (Eigen::Index t = seg.begin; t < seg.end; ++t) {
      Eigen::VectorXd v(2 * N + M);
      v << recs[seg.recording].position.row(t).head(N).transpose(),
          recs[seg.recording].velocity.row(t).head(N).transpose(), targets[seg.recording].row(t).transpose();
      sum += v;
      sum2 += v.cwiseProduct(v);
      n += 1;
    }
  const Eigen::VectorXd mean = sum / n;
  Eigen::VectorXd sd = (sum2 / n - mean.cwiseProduct(mean)).cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index k = 0; k < sd.size(); ++k)
    if (!(sd(k) > 1e-9)) sd(k) = 1.0;  // a constant column: leave it unscaled
  SequenceData d;
  d.norm.input_mean = mean.head(2 * N).cast<float>();
  d.norm.input_scale = sd.head(2 * N).cast<float>();
  d.norm.output_mean = mean.tail(M).cast<float>();
  d.norm.output_scale = sd.tail(M).cast<float>();
  const auto F = static_cast<Eigen::Index>(velocity_tanh_scales.size());
  d.norm.velocity_tanh_scale.resize(F * N);
  for (Eigen::Index f = 0; f < F; ++f)
    for (int k = 0; k < N; ++k)
      d.norm.velocity_tanh_scale(f * N + k) = static_cast<float>(velocity_tanh_scales[f] * sd(N + k));
  // Acceleration features: computed over each whole recording from its start
  // (as a model runs), scaled by their root mean square over the training split.
  const auto K = static_cast<Eigen::Index>(features.acceleration_filters_s.size());
  std::vector<Eigen::MatrixXd> acceleration(recs.size());
  if (K > 0) {
    d.norm.acceleration_filter_s.resize(K);
    for (Eigen::Index f = 0; f < K; ++f)
      d.norm.acceleration_filter_s(f) = static_cast<float>(features.acceleration_filters_s[f]);
    for (std::size_t r = 0; r < recs.size(); ++r)
      acceleration[r] = compute_acceleration_features(d.norm.acceleration_filter_s, recs[r].time, recs[r].velocity, N);
    Eigen::VectorXd sq = Eigen::VectorXd::Zero(K * N);
    for (const auto& seg : split.train)
      sq += acceleration[seg.recording].middleRows(seg.begin, seg.size()).colwise().squaredNorm().transpose();
    d.norm.acceleration_scale = (sq / n).cwiseSqrt().cast<float>();
    for (Eigen::Index k = 0; k < K * N; ++k)
      if (!(d.norm.acceleration_scale(k) > 1e-12f)) d.norm.acceleration_scale(k) = 1.0f;  // never accelerated
  }
  // Dahl features: x_c = fraction x the joint's range over the training split,
  // the states computed over each whole recording from its start.
  const auto D = static_cast<Eigen::Index>(features.dahl_fractions.size());
  std::vector<Eigen::MatrixXd> dahl(recs.size());
  if (D > 0) {
    Eigen::VectorXd lo = Eigen::VectorXd::Constant(N, std::numeric_limits<double>::infinity()), hi = -lo;
    for (const auto& seg : split.train) {
      const auto block = recs[seg.recording].position.middleRows(seg.begin, seg.size()).leftCols(N);
      lo = lo.cwiseMin(block.colwise().minCoeff().transpose());
      hi = hi.cwiseMax(block.colwise().maxCoeff().transpose());
    }
    d.norm.dahl_displacement.resize(D * N);
    for (Eigen::Index f = 0; f < D; ++f)
      for (int k = 0; k < N; ++k) {
        const double range = hi(k) - lo(k);
        // A joint that never moved keeps z = 0 whatever x_c is; any positive value does.
        d.norm.dahl_displacement(f * N + k) =
            static_cast<float>(features.dahl_fractions[f] * (range > 0 ? range : 1.0));
      }
    for (std::size_t r = 0; r < recs.size(); ++r)
      dahl[r] = compute_dahl_features(d.norm.dahl_displacement, recs[r].position, N);
  }
  const int I = d.norm.network_inputs(N);
  for (std::size_t r = 0; r < recs.size(); ++r) {
    const auto T = static_cast<Eigen::Index>(recs[r].num_samples());
    Eigen::MatrixXf x(T, I), y(T, M);
    for (int k = 0; k < N; ++k) {
      x.col(k) = ((recs[r].position.col(k).array() - mean(k)) / sd(k)).cast<float>();
      x.col(N + k) = ((recs[r].velocity.col(k).array() - mean(N + k)) / sd(N + k)).cast<float>();
    }
    // Computed in float as the kernel does (normalize_input in src/dynamics/networks.cpp).
    for (Eigen::Index f = 0; f < F * N; ++f)
      x.col(2 * N + f) = (recs[r].velocity.col(f % N).cast<float>().array() / d.norm.velocity_tanh_scale(f)).tanh();
    for (Eigen::Index f = 0; f < K * N; ++f)
      x.col(2 * N + F * N + f) = acceleration[r].col(f).cast<float>().array() / d.norm.acceleration_scale(f);
    for (Eigen::Index f = 0; f < D * N; ++f) x.col(2 * N + (F + K) * N + f) = dahl[r].col(f).cast<float>();
    for (int j = 0; j < M; ++j)
      y.col(j) = ((targets[r].col(j).array() - mean(2 * N + j)) / sd(2 * N + j)).cast<float>();
    d.x.push_back(to_tensor(x));
    d.y.push_back(to_tensor(y));
  }
  return d;
}

}  // namespace rcm::dynamics::torch_detail
