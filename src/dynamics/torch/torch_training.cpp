// LibTorch side of the torque models: training of the lstm, mlp and hybrid
// kinds, TorchScript export/import, and LibTorch references for tests and
// benchmarks. Everything that includes <torch/torch.h> lives in this one file.

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <dlfcn.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <random>
#include <utility>

#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/training.hpp"
#include "rcm/io/atomic_file.hpp"

namespace rcm::dynamics {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Documented thresholds (docs/dynamics.md).
constexpr std::size_t kFewSamplesNetwork = 24000;   // 2 min at 200 Hz: below, "too few to trust"
constexpr std::size_t kSmallDataNetwork = 60000;    // 5 min at 200 Hz: below, a small network

torch::Device select_device(const FitOptions& options, std::string& name) {
  if (options.prefer_cuda && torch::cuda::is_available()) {
    name = "cuda";
    return torch::Device(torch::kCUDA);
  }
  name = "cpu";
  return torch::Device(torch::kCPU);
}

void setup_torch(const FitOptions& options) {
  torch::set_num_threads(options.threads);
  torch::manual_seed(options.seed);
}

torch::Tensor to_tensor(const Eigen::MatrixXf& m) {  // rows x cols, row-major copy
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> r = m;
  return torch::from_blob(r.data(), {r.rows(), r.cols()}, torch::kFloat32).clone();
}

Eigen::MatrixXf to_eigen(const torch::Tensor& t) {
  auto c = t.detach().to(torch::kCPU).to(torch::kFloat32).contiguous();
  if (c.dim() == 1) c = c.unsqueeze(1);
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> r(c.size(0), c.size(1));
  std::memcpy(r.data(), c.data_ptr<float>(), sizeof(float) * r.size());
  return r;
}

Eigen::VectorXf to_eigen_vector(const torch::Tensor& t) {
  auto c = t.detach().to(torch::kCPU).to(torch::kFloat32).contiguous().reshape({-1});
  Eigen::VectorXf v(c.size(0));
  std::memcpy(v.data(), c.data_ptr<float>(), sizeof(float) * v.size());
  return v;
}

// ---------------------------------------------------------------------------- data

// Inputs [q, qdot, direction, acceleration and Dahl features] and targets of
// every recording, normalized with statistics of the training split only (no
// leakage of validation or test statistics).
struct SequenceData {
  std::vector<torch::Tensor> x, y;  // per recording: [T, I], [T, M], normalized
  Normalization norm;
};

// The network's extra inputs; both empty for [q, qdot] only.
struct InputFeatures {
  std::vector<double> velocity_tanh_scales;    // multiples of the velocity sd
  std::vector<double> acceleration_filters_s;  // time constants, s
  std::vector<double> dahl_fractions;          // of each joint's range of motion
};

InputFeatures resolve_input_features(const FitOptions& o, TorqueModelKind kind) {
  return {o.velocity_tanh_scales.value_or(get_default_velocity_tanh_scales(kind)),
          o.acceleration_filters_s.value_or(get_default_acceleration_filters_s(kind)),
          o.dahl_fractions.value_or(get_default_dahl_fractions(kind))};
}

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

// ---------------------------------------------------------------------------- networks

struct LstmNetImpl : torch::nn::Module {
  LstmNetImpl(int inputs, int hidden, int layers, int head_hidden, int outputs)
      : lstm(register_module("lstm", torch::nn::LSTM(torch::nn::LSTMOptions(inputs, hidden)
                                                         .num_layers(layers)
                                                         .batch_first(true)))),
        head1(register_module("head1", torch::nn::Linear(hidden, head_hidden))),
        head2(register_module("head2", torch::nn::Linear(head_hidden, outputs))) {}
  // x: [B, T, I]; returns [B, T, M] and the final state.
  std::pair<torch::Tensor, std::tuple<torch::Tensor, torch::Tensor>> forward(
      const torch::Tensor& x, const c10::optional<std::tuple<torch::Tensor, torch::Tensor>>& state) {
    auto [out, st] = lstm->forward(x, state);
    return {head2->forward(torch::tanh(head1->forward(out))), st};
  }
  torch::nn::LSTM lstm;
  torch::nn::Linear head1, head2;
};
TORCH_MODULE(LstmNet);

LstmNetwork to_network(LstmNet& net) {
  torch::NoGradGuard guard;
  LstmNetwork n;
  const int L = static_cast<int>(net->lstm->options.num_layers());
  for (int k = 0; k < L; ++k) {
    auto params = net->lstm->named_parameters();
    LstmLayer l;
    l.weight_ih = to_eigen(params[fmt::format("weight_ih_l{}", k)]);
    l.weight_hh = to_eigen(params[fmt::format("weight_hh_l{}", k)]);
    l.bias_ih = to_eigen_vector(params[fmt::format("bias_ih_l{}", k)]);
    l.bias_hh = to_eigen_vector(params[fmt::format("bias_hh_l{}", k)]);
    n.layers.push_back(std::move(l));
  }
  n.head.layers.push_back({to_eigen(net->head1->weight), to_eigen_vector(net->head1->bias), Activation::tanh});
  n.head.layers.push_back({to_eigen(net->head2->weight), to_eigen_vector(net->head2->bias), Activation::identity});
  return n;
}

std::vector<torch::Tensor> clone_parameters(torch::nn::Module& m) {
  std::vector<torch::Tensor> out;
  for (auto& p : m.parameters()) out.push_back(p.detach().clone());
  return out;
}

void restore_parameters(torch::nn::Module& m, const std::vector<torch::Tensor>& saved) {
  torch::NoGradGuard guard;
  auto params = m.parameters();
  for (std::size_t k = 0; k < params.size(); ++k) params[k].copy_(saved[k]);
}

void set_learning_rate(torch::optim::Adam& opt, double lr) {
  for (auto& group : opt.param_groups()) static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
}

// Learning-rate halving on plateau and early stopping, shared by the trainers.
struct EarlyStopping {
  double best = std::numeric_limits<double>::infinity();
  int best_epoch = 0, since_best = 0, since_reduce = 0;
  double lr;
  EarlyStopping(double lr0) : lr(lr0) {}
  // Returns true when this epoch is the new best.
  bool update(double loss, int epoch, const FitOptions& o, torch::optim::Adam& opt) {
    if (loss < best * (1.0 - 1e-4)) {
      best = loss;
      best_epoch = epoch;
      since_best = since_reduce = 0;
      return true;
    }
    ++since_best;
    if (++since_reduce >= o.plateau_patience && lr > o.min_learning_rate) {
      lr = std::max(lr * 0.5, o.min_learning_rate);
      set_learning_rate(opt, lr);
      since_reduce = 0;
    }
    return false;
  }
  bool should_stop(const FitOptions& o) const { return since_best >= o.patience; }
};

// Per-joint sums of squared errors over an epoch, scored by compute_balanced_loss.
struct JointSquaredErrors {
  Eigen::ArrayXd sum;
  double count = 0;
  explicit JointSquaredErrors(int M) : sum(Eigen::ArrayXd::Zero(M)) {}
  void add(const torch::Tensor& per_joint_sum, std::int64_t n) {
    const auto s = per_joint_sum.to(torch::kCPU, torch::kFloat64).contiguous();
    sum += Eigen::Map<const Eigen::ArrayXd>(s.data_ptr<double>(), sum.size());
    count += static_cast<double>(n);
  }
  double get_balanced_loss(double p) const { return compute_balanced_loss(sum / std::max(1.0, count), p); }
};

// The training loss of FitOptions::loss_balance: mean_j mse_j / m_j^p, with m_j a
// running mean of joint j's batch MSE over about 50 batches (an epoch of the
// default fit is 40), held out of the gradient.
struct LossBalance {
  double power;
  torch::Tensor running_mse;
  explicit LossBalance(double p) : power(p) {}
  // pred, target: batch x time x joints. Also returns their per-joint mean
  // squared error, out of the gradient, for the epoch's score.
  std::pair<torch::Tensor, torch::Tensor> compute_loss(const torch::Tensor& pred, const torch::Tensor& target) {
    if (power == 0.0) {
      // torch::mse_loss sums in the order fits have always used, so that P = 0
      // takes the same training steps as fits before the balance.
      torch::Tensor mse;
      {
        torch::NoGradGuard guard;
        mse = (pred - target).pow(2).mean(torch::IntArrayRef{0, 1});
      }
      return {torch::mse_loss(pred, target), mse};
    }
    const auto mse = (pred - target).pow(2).mean(torch::IntArrayRef{0, 1});
    const auto m = mse.detach().clamp_min(1e-12);
    running_mse = running_mse.defined() ? 0.98 * running_mse + 0.02 * m : m;
    return {(mse / running_mse.pow(power)).mean(), mse.detach()};
  }
};

struct LstmShape {
  int hidden, layers, window, streams;
  double weight_decay;
};

LstmShape choose_shape(const FitOptions& o, std::size_t train_samples) {
  const bool small = train_samples < kSmallDataNetwork;
  LstmShape s;
  s.hidden = o.hidden_size > 0 ? o.hidden_size : (small ? 32 : 128);
  s.layers = o.num_layers > 0 ? o.num_layers : 1;
  s.window = o.window > 0 ? o.window : (small ? 50 : 100);
  s.streams = o.streams > 0 ? o.streams : 32;
  s.weight_decay = o.weight_decay > 0 ? o.weight_decay : (small ? 1e-4 : 0.0);
  // Each stream must hold the burn-in and a few windows.
  const auto min_stream = static_cast<std::size_t>(o.burn_in + 4 * s.window);
  while (s.streams > 1 && train_samples / static_cast<std::size_t>(s.streams) < min_stream) s.streams /= 2;
  return s;
}

// Stateful truncated BPTT: the training split is cut into `streams` contiguous
// pieces run side by side; each epoch walks them window by window in time order
// with (h, c) carried (detached) from one window to the next, so the state sees
// minutes of history and learns what the last motion left behind (friction
// memory). The first burn_in samples of each piece only warm the state up.
struct LstmTrainResult {
  LstmNetwork network;
  int epochs = 0, best_epoch = 0;
  double best_loss = 0.0;
  bool interrupted = false;
};

// An interrupt drops the epoch in progress; the best finished one is kept, or
// there is nothing to keep.
void check_training_interrupt(int best_epoch, const char* label, bool verbose) {
  if (best_epoch == 0)
    throw Interrupted(fmt::format("interrupted while training the {} network, before its first epoch ended", label));
  if (verbose)
    std::cerr << fmt::format("[{}] interrupted: keeping epoch {}, the best validation loss so far\n", label, best_epoch);
}

LstmTrainResult train_lstm(const SequenceData& data, const TimeSplit& split, int N, int M, const FitOptions& o,
                           const LstmShape& shape, double balance_power, torch::Device device,
                           Clock::time_point t0, const char* label) {
  const int W = shape.window;
  LstmNet net(data.norm.network_inputs(N), shape.hidden, shape.layers, o.head_hidden, M);
  LossBalance balance(balance_power);
  net->to(device);
  torch::optim::Adam opt(net->parameters(),
                         torch::optim::AdamOptions(o.learning_rate).weight_decay(shape.weight_decay));
  std::mt19937 rng(o.seed);

  std::size_t train_total = 0;
  for (const auto& s : split.train) train_total += static_cast<std::size_t>(s.size());
  const auto piece_len = static_cast<Eigen::Index>(train_total / static_cast<std::size_t>(shape.streams)) / W * W;
  if (piece_len < o.burn_in + W)
    throw std::invalid_argument(fmt::format("{}: training split too short for one window after burn-in", label));

  // Validation pieces with burn_in samples of preceding input as context.
  std::vector<torch::Tensor> vx, vy;
  const Eigen::Index val_len = 2000;
  for (const auto& seg : split.validation) {
    for (Eigen::Index b = std::max<Eigen::Index>(seg.begin, o.burn_in); b + val_len <= seg.end; b += val_len) {
      vx.push_back(data.x[seg.recording].slice(0, b - o.burn_in, b + val_len));
      vy.push_back(data.y[seg.recording].slice(0, b, b + val_len));
    }
    const Eigen::Index rem_begin = std::max<Eigen::Index>(seg.begin, o.burn_in) +
                                   (seg.end - std::max<Eigen::Index>(seg.begin, o.burn_in)) / val_len * val_len;
    if (vx.empty() && seg.end - rem_begin > 10) {  // short validation: one piece
      vx.push_back(data.x[seg.recording].slice(0, rem_begin - o.burn_in, seg.end));
      vy.push_back(data.y[seg.recording].slice(0, rem_begin, seg.end));
    }
  }
  if (vx.empty()) throw std::invalid_argument(fmt::format("{}: validation split too short", label));
  // Pieces of unequal length (the short case) are scored one by one.
  auto validate = [&]() {
    torch::NoGradGuard guard;
    net->eval();
    JointSquaredErrors err(M);
    std::size_t k = 0;
    while (k < vx.size()) {
      std::size_t e = k;
      while (e < vx.size() && vx[e].size(0) == vx[k].size(0)) ++e;
      auto x = torch::stack(std::vector<torch::Tensor>(vx.begin() + k, vx.begin() + e)).to(device);
      auto y = torch::stack(std::vector<torch::Tensor>(vy.begin() + k, vy.begin() + e)).to(device);
      auto pred = net->forward(x, c10::nullopt).first.slice(1, o.burn_in);
      err.add((pred - y).pow(2).sum(torch::IntArrayRef{0, 1}), y.size(0) * y.size(1));
      k = e;
    }
    net->train();
    return err.get_balanced_loss(balance.power);
  };

  EarlyStopping stop(o.learning_rate);
  std::vector<torch::Tensor> best_params = clone_parameters(*net);
  int epoch = 0;
  bool interrupted = false;
  for (epoch = 1; epoch <= o.max_epochs; ++epoch) {
    // Streams: cut the training segments at a random phase each epoch.
    std::vector<torch::Tensor> sx, sy;
    const Eigen::Index phase = std::uniform_int_distribution<Eigen::Index>(0, W - 1)(rng);
    for (const auto& seg : split.train)
      for (Eigen::Index b = seg.begin + (sx.empty() ? phase : 0); b + piece_len <= seg.end; b += piece_len) {
        sx.push_back(data.x[seg.recording].slice(0, b, b + piece_len));
        sy.push_back(data.y[seg.recording].slice(0, b, b + piece_len));
      }
    if (sx.empty()) throw std::invalid_argument(fmt::format("{}: no training stream fits", label));
    auto X = torch::stack(sx).to(device), Y = torch::stack(sy).to(device);
    c10::optional<std::tuple<torch::Tensor, torch::Tensor>> state;
    JointSquaredErrors train_err(M);
    for (Eigen::Index c = 0; c + W <= piece_len && !is_interrupt_requested(); c += W) {
      auto x = X.slice(1, c, c + W), y = Y.slice(1, c, c + W);
      auto [pred, st] = net->forward(x, state);
      state = std::make_tuple(std::get<0>(st).detach(), std::get<1>(st).detach());
      const Eigen::Index skip = std::max<Eigen::Index>(0, std::min<Eigen::Index>(W, o.burn_in - c));
      if (skip >= W) continue;  // still warming up the state
      auto [loss, mse] = balance.compute_loss(pred.slice(1, skip), y.slice(1, skip));
      opt.zero_grad();
      loss.backward();
      torch::nn::utils::clip_grad_norm_(net->parameters(), 1.0);
      opt.step();
      train_err.add(mse, 1);
    }
    if (is_interrupt_requested()) {
      interrupted = true;
      break;
    }
    const double val = validate();
    if (stop.update(val, epoch, o, opt)) best_params = clone_parameters(*net);
    if (o.verbose)
      std::cerr << fmt::format("[{}] epoch {:3d}  train {:.5f}  validation {:.5f}  lr {:.1e}  {:.0f} s\n", label,
                               epoch, train_err.get_balanced_loss(balance.power), val, stop.lr,
                               seconds_since(t0));
    if (stop.should_stop(o)) break;
    if (seconds_since(t0) > 60.0 * o.max_minutes) {
      if (o.verbose) std::cerr << fmt::format("[{}] time budget of {} min reached\n", label, o.max_minutes);
      break;
    }
  }
  if (interrupted) check_training_interrupt(stop.best_epoch, label, o.verbose);
  restore_parameters(*net, best_params);
  net->to(torch::kCPU);
  LstmTrainResult r;
  r.network = to_network(net);
  r.interrupted = interrupted;
  r.epochs = interrupted ? epoch - 1 : std::min(epoch, o.max_epochs);
  r.best_epoch = stop.best_epoch;
  r.best_loss = stop.best;
  return r;
}

void add_network_warnings(FitSummary& s, std::size_t few) {
  if (s.train_samples < few)
    s.warnings.push_back(fmt::format(
        "data too few to trust: {} training samples (< {}, i.e. 2 min at 200 Hz); a recurrent network this small "
        "data set cannot cover the joint space, expect poor generalization",
        s.train_samples, few));
  if (s.interrupted)
    s.warnings.push_back(fmt::format("training was interrupted after {} epochs, before early stopping ended it; the "
                                     "model is that of epoch {}",
                                     s.epochs, s.best_epoch));
  if (s.best_epoch <= 2 && s.epochs > 4)
    s.warnings.push_back("validation loss was best in the first epochs: the model did not learn beyond its start");
  // Debian's reference BLAS (blas/) and ATLAS are single-threaded and train 2.6-25x slower.
  const std::string blas = get_libtorch_blas_library();
  if (s.device == "cpu" && (blas.find("atlas") != std::string::npos || blas.find("/blas/") != std::string::npos))
    s.warnings.push_back(fmt::format("LibTorch calls the BLAS of {}, which is single-threaded and slow; install "
                                     "libopenblas0-openmp (docs/benchmarks.md, \"BLAS\")",
                                     blas));
}

std::vector<Eigen::MatrixXd> effort_targets(const std::vector<Recording>& recs, int M) {
  std::vector<Eigen::MatrixXd> t;
  for (const auto& r : recs) t.push_back(r.effort.leftCols(M));
  return t;
}

FitSummary make_summary(TorqueModelKind kind, const TimeSplit& split) {
  FitSummary s;
  s.kind = kind;
  for (const auto& g : split.train) s.train_samples += g.size();
  for (const auto& g : split.validation) s.validation_samples += g.size();
  for (const auto& g : split.test) s.test_samples += g.size();
  return s;
}

// What the LSTM and hybrid fits keep of a training run.
void record_training(FitSummary& summary, const LstmTrainResult& tr) {
  summary.epochs = tr.epochs;
  summary.best_epoch = tr.best_epoch;
  summary.best_validation_loss = tr.best_loss;
  summary.interrupted = tr.interrupted;
  add_network_warnings(summary, kFewSamplesNetwork);
}

TorqueModelInfo make_network_info(const std::vector<Recording>& recs, int N, int M) {
  TorqueModelInfo info;
  info.num_joints = N;
  info.num_outputs = M;
  info.sample_period_s = median_sample_period(recs);
  info.regime = compute_training_regime(recs, N);
  return info;
}

FitResult finish(std::unique_ptr<TorqueModel> model, FitSummary summary, const std::vector<Recording>& recs,
                 const TimeSplit& split, const FitOptions& o, Clock::time_point t0,
                 const std::function<std::unique_ptr<TorqueModel>(TorqueModelInfo)>& rebuild) {
  if (!split.test.empty()) summary.test_errors = evaluate_on_segments(*model, recs, split.test);
  summary.seconds = seconds_since(t0);
  if (o.verbose) std::cerr << summary.brief_report();
  TorqueModelInfo info = model->info();
  info.training = summary.to_json();
  FitResult r;
  r.model = rebuild(std::move(info));
  r.summary = std::move(summary);
  return r;
}

}  // namespace

// ---------------------------------------------------------------------------- fits

FitResult fit_lstm_torque_model(const std::vector<Recording>& recs, const FitOptions& o) {
  const auto t0 = Clock::now();
  o.check();
  check_fit_recordings(recs);
  setup_torch(o);
  const int N = recs.front().num_joints(), M = resolve_num_outputs(recs, o);
  const TimeSplit split = split_in_time(recs, o.train_fraction, o.validation_fraction);
  FitSummary summary = make_summary(TorqueModelKind::lstm, split);
  const torch::Device device = select_device(o, summary.device);
  const TorqueModelInfo info = make_network_info(recs, N, M);
  const int delay = resolve_output_delay_samples(TorqueModelKind::lstm, o, info.sample_period_s);
  SequenceData data =
      prepare_data(recs, effort_targets(recs, M), split, N, M, resolve_input_features(o, TorqueModelKind::lstm));
  // The output at sample t learns the torque of t - d. The first d targets of a
  // recording (its first sample repeated) lie in the burn-in, which is never scored.
  if (delay > 0)
    for (auto& y : data.y) {
      const int64_t T = y.size(0), d = std::min<int64_t>(delay, T);
      y = torch::cat({y.slice(0, 0, 1).expand({d, y.size(1)}), y.slice(0, 0, T - d)}).contiguous();
    }
  const LstmShape shape = choose_shape(o, summary.train_samples);
  summary.loss_balance = o.loss_balance.value_or(get_default_loss_balance(TorqueModelKind::lstm));
  summary.output_delay_samples = delay;
  if (o.verbose)
    std::cerr << fmt::format(
        "[lstm] {} layers x {} hidden, window {}, {} streams, weight decay {}, loss balance {}, output delay {} "
        "samples\n",
        shape.layers, shape.hidden, shape.window, shape.streams, shape.weight_decay, summary.loss_balance, delay);
  auto tr = train_lstm(data, split, N, M, o, shape, summary.loss_balance, device, t0, "lstm");
  record_training(summary, tr);
  auto model = std::make_unique<LstmTorqueModel>(info, tr.network, data.norm, delay);
  return finish(std::move(model), std::move(summary), recs, split, o, t0, [&](TorqueModelInfo i) {
    return std::make_unique<LstmTorqueModel>(std::move(i), tr.network, data.norm, delay);
  });
}

FitResult fit_hybrid_torque_model(const std::vector<Recording>& recs, const FitOptions& o) {
  const auto t0 = Clock::now();
  o.check();
  check_fit_recordings(recs);
  setup_torch(o);
  const int N = recs.front().num_joints(), M = resolve_num_outputs(recs, o);
  resolve_output_delay_samples(TorqueModelKind::hybrid, o, median_sample_period(recs));
  FitOptions lo = o;
  lo.verbose = false;
  FitResult base_fit = fit_linear_torque_model(recs, lo);
  std::shared_ptr<const LinearTorqueModel> base(
      static_cast<const LinearTorqueModel*>(base_fit.model.release()));
  if (o.verbose) std::cerr << fmt::format("[hybrid] model-based part fitted in {:.1f} s\n", seconds_since(t0));
  // The LSTM learns what the model-based part leaves, with the base's own state
  // carried over each whole recording.
  std::vector<Eigen::MatrixXd> residual;
  for (const auto& r : recs) residual.push_back(r.effort.leftCols(M) - predict_torque(*base, r));
  const TimeSplit split = split_in_time(recs, o.train_fraction, o.validation_fraction);
  FitSummary summary = make_summary(TorqueModelKind::hybrid, split);
  summary.warnings = base_fit.summary.warnings;
  const torch::Device device = select_device(o, summary.device);
  const SequenceData data =
      prepare_data(recs, residual, split, N, M, resolve_input_features(o, TorqueModelKind::hybrid));
  const LstmShape shape = choose_shape(o, summary.train_samples);
  summary.loss_balance = o.loss_balance.value_or(get_default_loss_balance(TorqueModelKind::hybrid));
  auto tr = train_lstm(data, split, N, M, o, shape, summary.loss_balance, device, t0, "hybrid");
  record_training(summary, tr);
  const TorqueModelInfo info = make_network_info(recs, N, M);
  auto model = std::make_unique<HybridTorqueModel>(info, base, tr.network, data.norm);
  return finish(std::move(model), std::move(summary), recs, split, o, t0, [&](TorqueModelInfo i) {
    return std::make_unique<HybridTorqueModel>(std::move(i), base, tr.network, data.norm);
  });
}

FitResult fit_mlp_torque_model(const std::vector<Recording>& recs, const FitOptions& o) {
  const auto t0 = Clock::now();
  o.check();
  check_fit_recordings(recs);
  setup_torch(o);
  const int N = recs.front().num_joints(), M = resolve_num_outputs(recs, o);
  resolve_output_delay_samples(TorqueModelKind::mlp, o, median_sample_period(recs));
  const TimeSplit split = split_in_time(recs, o.train_fraction, o.validation_fraction);
  FitSummary summary = make_summary(TorqueModelKind::mlp, split);
  const torch::Device device = select_device(o, summary.device);
  // Yilmaz et al.'s inputs: [q, qdot] only.
  const SequenceData data = prepare_data(recs, effort_targets(recs, M), split, N, M, InputFeatures{});
  auto gather = [&](const std::vector<SampleSegment>& segs, bool y) {
    std::vector<torch::Tensor> parts;
    for (const auto& s : segs) parts.push_back((y ? data.y : data.x)[s.recording].slice(0, s.begin, s.end));
    return torch::cat(parts).to(device);
  };
  const auto Xt = gather(split.train, false), Yt = gather(split.train, true);
  const auto Xv = gather(split.validation, false), Yv = gather(split.validation, true);

  // One tanh network per joint (Yilmaz et al.); trained together, each on its own loss.
  std::vector<torch::nn::Sequential> nets;
  torch::nn::Module holder;
  for (int j = 0; j < M; ++j) {
    nets.push_back(holder.register_module(
        fmt::format("joint{}", j),
        torch::nn::Sequential(torch::nn::Linear(data.norm.network_inputs(N), o.mlp_hidden), torch::nn::Tanh(),
                              torch::nn::Linear(o.mlp_hidden, 1))));
  }
  holder.to(device);
  const double wd = o.weight_decay > 0 ? o.weight_decay : (summary.train_samples < kSmallDataNetwork ? 1e-4 : 0.0);
  torch::optim::Adam opt(holder.parameters(), torch::optim::AdamOptions(o.learning_rate).weight_decay(wd));
  auto forward_all = [&](const torch::Tensor& x) {
    std::vector<torch::Tensor> cols;
    for (auto& n : nets) cols.push_back(n->forward(x));
    return torch::cat(cols, 1);
  };
  EarlyStopping stop(o.learning_rate);
  auto best_params = clone_parameters(holder);
  const int64_t batch = 256;
  int epoch = 0;
  bool interrupted = false;
  for (epoch = 1; epoch <= o.max_epochs; ++epoch) {
    auto perm = torch::randperm(Xt.size(0), torch::TensorOptions().dtype(torch::kLong).device(device));
    double sum = 0, count = 0;
    for (int64_t b = 0; b < Xt.size(0) && !is_interrupt_requested(); b += batch) {
      auto idx = perm.slice(0, b, std::min(b + batch, Xt.size(0)));
      auto loss = torch::mse_loss(forward_all(Xt.index_select(0, idx)), Yt.index_select(0, idx));
      opt.zero_grad();
      loss.backward();
      opt.step();
      sum += loss.item<double>();
      count += 1;
    }
    if (is_interrupt_requested()) {
      interrupted = true;
      break;
    }
    double val;
    {
      torch::NoGradGuard guard;
      val = torch::mse_loss(forward_all(Xv), Yv).item<double>();
    }
    if (stop.update(val, epoch, o, opt)) best_params = clone_parameters(holder);
    if (o.verbose)
      std::cerr << fmt::format("[mlp] epoch {:3d}  train {:.5f}  validation {:.5f}  lr {:.1e}  {:.0f} s\n", epoch,
                               sum / count, val, stop.lr, seconds_since(t0));
    if (stop.should_stop(o) || seconds_since(t0) > 60.0 * o.max_minutes) break;
  }
  if (interrupted) check_training_interrupt(stop.best_epoch, "mlp", o.verbose);
  restore_parameters(holder, best_params);
  holder.to(torch::kCPU);
  std::vector<DenseStack> stacks;
  for (auto& n : nets) {
    auto l1 = n[0]->as<torch::nn::Linear>();
    auto l2 = n[2]->as<torch::nn::Linear>();
    DenseStack s;
    s.layers.push_back({to_eigen(l1->weight), to_eigen_vector(l1->bias), Activation::tanh});
    s.layers.push_back({to_eigen(l2->weight), to_eigen_vector(l2->bias), Activation::identity});
    stacks.push_back(std::move(s));
  }
  summary.epochs = interrupted ? epoch - 1 : std::min(epoch, o.max_epochs);
  summary.best_epoch = stop.best_epoch;
  summary.best_validation_loss = stop.best;
  summary.interrupted = interrupted;
  add_network_warnings(summary, kFewSamplesNetwork / 4);
  const TorqueModelInfo info = make_network_info(recs, N, M);
  auto model = std::make_unique<MlpTorqueModel>(info, stacks, data.norm);
  return finish(std::move(model), std::move(summary), recs, split, o, t0, [&](TorqueModelInfo i) {
    return std::make_unique<MlpTorqueModel>(std::move(i), stacks, data.norm);
  });
}

FitResult fit_torque_model(TorqueModelKind kind, const std::vector<Recording>& recordings, const FitOptions& o) {
  switch (kind) {
    case TorqueModelKind::lstm: return fit_lstm_torque_model(recordings, o);
    case TorqueModelKind::mlp: return fit_mlp_torque_model(recordings, o);
    case TorqueModelKind::hybrid: return fit_hybrid_torque_model(recordings, o);
    case TorqueModelKind::linear: break;
  }
  return fit_linear_torque_model(recordings, o);
}

// ---------------------------------------------------------------------------- TorchScript

namespace {

torch::Tensor tensor_of(const Eigen::MatrixXf& m) { return to_tensor(m); }
torch::Tensor tensor_of(const Eigen::VectorXf& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {v.size()}, torch::kFloat32).clone();
}

const char* activation_name(Activation a) {
  return a == Activation::tanh ? "tanh" : a == Activation::relu ? "relu" : "identity";
}

[[noreturn]] void import_error(const std::filesystem::path& path, const std::string& field, const std::string& what) {
  InputLocation where;
  where.file = path.string();
  where.field = field;
  throw InputError(where, what);
}

}  // namespace

void export_torchscript(const LstmTorqueModel& model, const std::filesystem::path& path) {
  const auto& net = model.network();
  const auto& norm = model.normalization();
  torch::jit::Module m("rcm_torque_lstm");
  const int L = static_cast<int>(net.layers.size());
  std::string params = "[";
  for (int k = 0; k < L; ++k) {
    const auto& l = net.layers[k];
    m.register_parameter(fmt::format("lstm_weight_ih_l{}", k), tensor_of(l.weight_ih), false);
    m.register_parameter(fmt::format("lstm_weight_hh_l{}", k), tensor_of(l.weight_hh), false);
    m.register_parameter(fmt::format("lstm_bias_ih_l{}", k), tensor_of(l.bias_ih), false);
    m.register_parameter(fmt::format("lstm_bias_hh_l{}", k), tensor_of(l.bias_hh), false);
    params += fmt::format("{0}self.lstm_weight_ih_l{1}, self.lstm_weight_hh_l{1}, self.lstm_bias_ih_l{1}, "
                          "self.lstm_bias_hh_l{1}",
                          k > 0 ? ", " : "", k);
  }
  params += "]";
  std::string head;
  c10::List<std::string> acts;
  for (std::size_t k = 0; k < net.head.layers.size(); ++k) {
    const auto& l = net.head.layers[k];
    m.register_parameter(fmt::format("head_weight_{}", k), tensor_of(l.weight), false);
    m.register_parameter(fmt::format("head_bias_{}", k), tensor_of(l.bias), false);
    head += fmt::format("        y = torch.matmul(y, self.head_weight_{0}.t()) + self.head_bias_{0}\n", k);
    if (l.activation == Activation::tanh) head += "        y = torch.tanh(y)\n";
    if (l.activation == Activation::relu) head += "        y = torch.relu(y)\n";
    acts.push_back(activation_name(l.activation));
  }
  m.register_buffer("input_mean", tensor_of(norm.input_mean));
  m.register_buffer("input_scale", tensor_of(norm.input_scale));
  m.register_buffer("output_mean", tensor_of(norm.output_mean));
  m.register_buffer("output_scale", tensor_of(norm.output_scale));
  const int N = static_cast<int>(norm.input_mean.size()) / 2;
  const int F = static_cast<int>(norm.velocity_tanh_scale.size()) / std::max(1, N);
  std::string features;
  if (F > 0) {
    m.register_buffer("velocity_tanh_scale", tensor_of(norm.velocity_tanh_scale));
    features = fmt::format("        qd = x[:, :, {}:{}]\n        xn = torch.cat([xn", N, 2 * N);
    for (int f = 0; f < F; ++f)
      features += fmt::format(", torch.tanh(qd / self.velocity_tanh_scale[{}:{}])", f * N, (f + 1) * N);
    features += "], 2)\n";
  }
  // Acceleration and Dahl features: the AccelerationFilter and DahlFilter of
  // networks.hpp (the former at the model's sample period), their state
  // z = [qdot_prev, a, q_prev, z_dahl] (the parts of the features present)
  // carried across calls like (h, c); z0 = None is the reset state.
  const int K = static_cast<int>(norm.acceleration_filter_s.size());
  const int D = static_cast<int>(norm.dahl_displacement.size()) / std::max(1, N);
  std::string signature = "x: Tensor, h0: Tensor, c0: Tensor) -> Tuple[Tensor, Tensor, Tensor]";
  std::string result = ", hn, cn";
  if (K > 0 || D > 0) {
    signature =
        "x: Tensor, h0: Tensor, c0: Tensor, z0: Optional[Tensor] = None) -> Tuple[Tensor, Tensor, Tensor, Tensor]";
    result = fmt::format(", hn, cn, torch.cat([{}], 1)", K > 0 && D > 0 ? "prev, a, qprev, zd"
                                                         : K > 0       ? "prev, a"
                                                                       : "qprev, zd");
  }
  if (K > 0) {
    if (!(model.info().sample_period_s > 0))
      throw std::invalid_argument("TorchScript export: acceleration features need the model's sample period");
    m.register_buffer("acceleration_filter_s", tensor_of(norm.acceleration_filter_s));
    m.register_buffer("acceleration_scale", tensor_of(norm.acceleration_scale));
    features += fmt::format(R"JIT(        qd = x[:, :, {0}:{1}]
        dt = self.sample_period_s
        if z0 is None:
            prev = qd[:, 0]
            a = torch.zeros(x.size(0), {2}, dtype=x.dtype)
        else:
            prev = z0[:, 0:{0}]
            a = z0[:, {0}:{4}]
        alpha = (dt / (self.acceleration_filter_s + dt)).repeat_interleave({0})
        acc: List[Tensor] = []
        for t in range(x.size(1)):
            a = a + alpha * (((qd[:, t] - prev) / dt).repeat(1, {3}) - a)
            acc.append(a)
            prev = qd[:, t]
        xn = torch.cat([xn, torch.stack(acc, 1) / self.acceleration_scale], 2)
)JIT",
                            N, 2 * N, K * N, K, N + K * N);
  }
  if (D > 0) {
    // In double, as DahlFilter: x_c can be a few micrometres on a joint whose
    // position is tenths of a metre, below float resolution of q differences.
    m.register_buffer("dahl_displacement", tensor_of(norm.dahl_displacement));
    const int o = K > 0 ? N + K * N : 0;
    features += fmt::format(R"JIT(        q = x[:, :, 0:{0}].double()
        if z0 is None:
            qprev = q[:, 0]
            zd = torch.zeros(x.size(0), {3}, dtype=x.dtype).double()
        else:
            qprev = z0[:, {1}:{2}].double()
            zd = z0[:, {2}:].double()
        xc = self.dahl_displacement.double()
        dahl: List[Tensor] = []
        for t in range(x.size(1)):
            dq = (q[:, t] - qprev).repeat(1, {4})
            sg = torch.sign(dq)
            zd = sg + (zd - sg) * torch.exp(-torch.abs(dq) / xc)
            dahl.append(zd)
            qprev = q[:, t]
        xn = torch.cat([xn, torch.stack(dahl, 1).to(x.dtype)], 2)
        qprev = qprev.to(x.dtype)
        zd = zd.to(x.dtype)
)JIT",
                            N, o, o + N, D * N, D);
  }
  m.register_attribute("head_activations", c10::ListType::ofStrings(), acts);
  m.register_attribute("sample_period_s", c10::FloatType::get(), model.info().sample_period_s);
  m.register_attribute("num_layers", c10::IntType::get(), static_cast<int64_t>(L));
  m.register_attribute("hidden_size", c10::IntType::get(), static_cast<int64_t>(net.hidden_size()));
  // forward's torque at step t is that of step t - output_delay_samples.
  m.register_attribute("output_delay_samples", c10::IntType::get(), static_cast<int64_t>(model.output_delay()));
  m.define(fmt::format(R"JIT(
    def forward(self, {4}:
        xn = (x - self.input_mean) / self.input_scale
{3}        out, hn, cn = torch.lstm(xn, [h0, c0], {0}, True, {1}, 0.0, False, False, True)
        y = out
{2}        return y * self.output_scale + self.output_mean{5}
  )JIT",
                       params, L, head, features, signature, result));
  // LibTorch writes by name: to a temporary renamed once whole (rcm/io/atomic_file.hpp).
  AtomicFile file(path);
  try {
    m.save(file.get_temp_path().string());
  } catch (const c10::Error& e) {
    InputLocation where;
    where.file = path.string();
    throw InputError(where, std::string("cannot be written: ") + e.what_without_backtrace());
  }
  file.commit();
}

std::unique_ptr<LstmTorqueModel> import_torchscript(const std::filesystem::path& path) {
  torch::jit::Module m;
  try {
    m = torch::jit::load(path.string());
  } catch (const c10::Error& e) {
    import_error(path, "", std::string("not a loadable TorchScript file: ") + e.what_without_backtrace());
  }
  std::map<std::string, torch::Tensor> p;
  for (const auto& np : m.named_parameters(true)) p[np.name] = np.value;
  for (const auto& nb : m.named_buffers(true)) p[nb.name] = nb.value;
  auto get = [&](const std::string& name) -> torch::Tensor {
    auto it = p.find(name);
    if (it == p.end()) import_error(path, name, "missing parameter or buffer (see docs/dynamics.md for the layout)");
    return it->second;
  };
  LstmNetwork net;
  const bool rcm_layout = p.count("lstm_weight_ih_l0") > 0;
  const std::string pre = rcm_layout ? "lstm_" : "lstm.";
  for (int k = 0; p.count(fmt::format("{}weight_ih_l{}", pre, k)); ++k) {
    LstmLayer l;
    l.weight_ih = to_eigen(get(fmt::format("{}weight_ih_l{}", pre, k)));
    l.weight_hh = to_eigen(get(fmt::format("{}weight_hh_l{}", pre, k)));
    l.bias_ih = to_eigen_vector(get(fmt::format("{}bias_ih_l{}", pre, k)));
    l.bias_hh = to_eigen_vector(get(fmt::format("{}bias_hh_l{}", pre, k)));
    net.layers.push_back(std::move(l));
  }
  if (net.layers.empty()) import_error(path, "lstm.weight_ih_l0", "no LSTM layer found");
  if (rcm_layout) {
    auto acts = m.attr("head_activations").toListRef();
    for (std::size_t k = 0; k < acts.size(); ++k) {
      const auto a = acts[k].toStringRef();
      net.head.layers.push_back({to_eigen(get(fmt::format("head_weight_{}", k))),
                                 to_eigen_vector(get(fmt::format("head_bias_{}", k))),
                                 a == "tanh" ? Activation::tanh : a == "relu" ? Activation::relu : Activation::identity});
    }
  } else {
    // PyTorch layout: head = nn.Sequential(Linear, Tanh|ReLU, ..., Linear).
    if (!m.hasattr("head")) import_error(path, "head", "missing submodule (nn.Sequential of Linear and Tanh/ReLU)");
    for (const auto& child : m.attr("head").toModule().named_children()) {
      const std::string type = child.value.type()->name() ? child.value.type()->name()->qualifiedName() : "";
      if (type.find("Linear") != std::string::npos) {
        net.head.layers.push_back({to_eigen(get("head." + child.name + ".weight")),
                                   to_eigen_vector(get("head." + child.name + ".bias")), Activation::identity});
      } else if (type.find("Tanh") != std::string::npos || type.find("ReLU") != std::string::npos) {
        if (net.head.layers.empty()) import_error(path, "head." + child.name, "an activation before any Linear");
        net.head.layers.back().activation =
            type.find("Tanh") != std::string::npos ? Activation::tanh : Activation::relu;
      } else {
        import_error(path, "head." + child.name, "unsupported layer type " + type + " (Linear, Tanh, ReLU only)");
      }
    }
  }
  Normalization norm;
  norm.input_mean = to_eigen_vector(get("input_mean"));
  norm.input_scale = to_eigen_vector(get("input_scale"));
  norm.output_mean = to_eigen_vector(get("output_mean"));
  norm.output_scale = to_eigen_vector(get("output_scale"));
  if (p.count("velocity_tanh_scale")) norm.velocity_tanh_scale = to_eigen_vector(p["velocity_tanh_scale"]);
  if (p.count("acceleration_filter_s") || p.count("acceleration_scale")) {
    norm.acceleration_filter_s = to_eigen_vector(get("acceleration_filter_s"));
    norm.acceleration_scale = to_eigen_vector(get("acceleration_scale"));
  }
  if (p.count("dahl_displacement")) norm.dahl_displacement = to_eigen_vector(p["dahl_displacement"]);
  try {
    net.check();
  } catch (const std::invalid_argument& e) {
    import_error(path, "", e.what());
  }
  TorqueModelInfo info;
  if (norm.input_mean.size() % 2 != 0 || norm.input_mean.size() == 0)
    import_error(path, "input_mean", "expected 2 x joints values ([q, qdot])");
  info.num_joints = static_cast<int>(norm.input_mean.size()) / 2;
  info.num_outputs = net.output_size();
  info.sample_period_s = m.hasattr("sample_period_s") ? m.attr("sample_period_s").toDouble() : 0.0;
  if (norm.has_acceleration() && !(info.sample_period_s > 0))
    import_error(path, "sample_period_s", "acceleration features need the module's sample period (s), a float attribute");
  info.training = {{"imported_from", path.string()}};
  int delay = 0;
  if (m.hasattr("output_delay_samples")) {
    const auto d = m.attr("output_delay_samples");
    if (!d.isInt() || d.toInt() < 0 || d.toInt() > 100000)
      import_error(path, "output_delay_samples", "expected an int attribute in [0, 100000] (samples)");
    delay = static_cast<int>(d.toInt());
  }
  std::unique_ptr<LstmTorqueModel> model, undelayed;
  try {
    model = std::make_unique<LstmTorqueModel>(info, net, norm, delay);
    // The check below compares the network step for step, as forward returns it.
    undelayed = std::make_unique<LstmTorqueModel>(info, net, norm, 0);
  } catch (const std::invalid_argument& e) {
    import_error(path, "", e.what());
  }
  // The module's own forward on a random sequence must agree with the kernel.
  torch::NoGradGuard guard;
  torch::manual_seed(0);
  const int64_t T = 50, I = 2 * info.num_joints, H = net.hidden_size(), L = static_cast<int64_t>(net.layers.size());
  // A random walk rather than white noise: white qdot would make accelerations
  // that saturate every gate and hide a filter that differs from the documented one.
  // Its steps span four decades so that some are comparable to any Dahl
  // displacement (else every Dahl state would sit at +-1, whatever its x_c).
  auto walk = torch::randn({1, T, I}) * 0.05 * torch::pow(10.0, -4.0 * torch::rand({1, T, 1}));
  walk.select(1, 0).copy_(torch::randn({1, I}));
  auto x = walk.cumsum(1) * torch::from_blob(norm.input_scale.data(), {I}).clone() +
           torch::from_blob(norm.input_mean.data(), {I}).clone();
  const auto nargs = m.get_method("forward").function().getSchema().arguments().size();
  torch::Tensor y;
  if (nargs == 2) {
    auto out = m.forward({x});
    y = out.isTuple() ? out.toTuple()->elements()[0].toTensor() : out.toTensor();
  } else if (nargs == 4) {
    y = m.forward({x, torch::zeros({L, 1, H}), torch::zeros({L, 1, H})}).toTuple()->elements()[0].toTensor();
  } else if (nargs == 5) {  // forward(x, h0, c0, z0) with z0 = None: the reset state
    y = m.forward({x, torch::zeros({L, 1, H}), torch::zeros({L, 1, H}), torch::jit::IValue()})
            .toTuple()
            ->elements()[0]
            .toTensor();
  } else {
    import_error(path, "forward", "expected forward(x), forward(x, h0, c0) or forward(x, h0, c0, z0)");
  }
  Eigen::MatrixXd xd = to_eigen(x[0]).cast<double>();
  // At the module's own sample period: what its acceleration features assume.
  const double dt = info.sample_period_s > 0 ? info.sample_period_s : 1.0;
  const Eigen::MatrixXd mine = predict_torque(*undelayed, Eigen::VectorXd::LinSpaced(T, 0, dt * (T - 1)),
                                              xd.leftCols(I / 2), xd.rightCols(I / 2));
  const Eigen::MatrixXd theirs = to_eigen(y[0]).cast<double>();
  const double scale = std::max(1.0, theirs.cwiseAbs().maxCoeff());
  if ((mine - theirs).cwiseAbs().maxCoeff() > 1e-4 * scale)
    import_error(path, "forward",
                 fmt::format("the module's forward disagrees with its parameters read as the documented layout "
                             "(max difference {:.3g}); is the layout as in docs/dynamics.md?",
                             (mine - theirs).cwiseAbs().maxCoeff()));
  return model;
}

// ---------------------------------------------------------------------------- references

namespace {
LstmNet make_libtorch_net(const LstmNetwork& network) {
  if (network.head.layers.size() != 2 || network.head.layers[0].activation != Activation::tanh)
    throw std::invalid_argument("LibTorch reference: head must be Linear-Tanh-Linear");
  LstmNet net(network.input_size(), network.hidden_size(), static_cast<int>(network.layers.size()),
              static_cast<int>(network.head.layers[0].weight.rows()), network.output_size());
  torch::NoGradGuard guard;
  auto params = net->lstm->named_parameters();
  for (std::size_t k = 0; k < network.layers.size(); ++k) {
    params[fmt::format("weight_ih_l{}", k)].copy_(tensor_of(network.layers[k].weight_ih));
    params[fmt::format("weight_hh_l{}", k)].copy_(tensor_of(network.layers[k].weight_hh));
    params[fmt::format("bias_ih_l{}", k)].copy_(tensor_of(network.layers[k].bias_ih));
    params[fmt::format("bias_hh_l{}", k)].copy_(tensor_of(network.layers[k].bias_hh));
  }
  net->head1->weight.copy_(tensor_of(network.head.layers[0].weight));
  net->head1->bias.copy_(tensor_of(network.head.layers[0].bias));
  net->head2->weight.copy_(tensor_of(network.head.layers[1].weight));
  net->head2->bias.copy_(tensor_of(network.head.layers[1].bias));
  net->eval();
  return net;
}
}  // namespace

Eigen::MatrixXf run_lstm_with_libtorch(const LstmNetwork& network, const Eigen::MatrixXf& x) {
  auto net = make_libtorch_net(network);
  torch::NoGradGuard guard;
  auto y = net->forward(tensor_of(x).unsqueeze(0), c10::nullopt).first;
  return to_eigen(y[0]);
}

std::function<void(const float*, float*)> make_libtorch_lstm_stepper(const LstmNetwork& network) {
  auto net = make_libtorch_net(network);
  const int64_t I = network.input_size(), M = network.output_size();
  auto state = std::make_shared<c10::optional<std::tuple<torch::Tensor, torch::Tensor>>>();
  return [net, state, I, M](const float* x, float* y) mutable {
    torch::NoGradGuard guard;
    auto in = torch::from_blob(const_cast<float*>(x), {1, 1, I}, torch::kFloat32);
    auto [out, st] = net->forward(in, *state);
    *state = st;
    std::memcpy(y, out.contiguous().data_ptr<float>(), sizeof(float) * M);
  };
}

void set_libtorch_threads(int threads) { torch::set_num_threads(threads); }

std::string get_libtorch_blas_library() {
  void* symbol = dlsym(RTLD_DEFAULT, "sgemm_");
  Dl_info info{};
  if (symbol == nullptr || dladdr(symbol, &info) == 0 || info.dli_fname == nullptr) return "";
  std::error_code ec;
  const auto resolved = std::filesystem::canonical(info.dli_fname, ec);
  return ec ? std::string(info.dli_fname) : resolved.string();
}

std::function<void()> make_libtorch_training_step(int inputs, int hidden, int layers, int head_hidden, int outputs,
                                                  int batch, int window) {
  torch::manual_seed(0);
  LstmNet net(inputs, hidden, layers, head_hidden, outputs);
  auto opt = std::make_shared<torch::optim::Adam>(net->parameters(), torch::optim::AdamOptions(1e-3));
  auto x = torch::randn({batch, window, inputs});
  auto y = torch::randn({batch, window, outputs});
  return [net, opt, x, y]() mutable {
    auto loss = torch::mse_loss(net->forward(x, c10::nullopt).first, y);
    opt->zero_grad();
    loss.backward();
    torch::nn::utils::clip_grad_norm_(net->parameters(), 1.0);
    opt->step();
  };
}

}  // namespace rcm::dynamics
