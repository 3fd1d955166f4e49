// Training of the lstm and hybrid kinds: stateful truncated BPTT over
// contiguous streams with a joint-balanced loss (train_lstm), the LSTM's output
// delay, and the hybrid's linear base with an LSTM on its residual.

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <iostream>
#include <random>
#include <utility>

#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/training.hpp"
#include "torch_parts.hpp"

namespace rcm::dynamics {

namespace {

using namespace torch_detail;

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

// What the LSTM and hybrid fits keep of a training run.
void record_training(FitSummary& summary, const LstmTrainResult& tr) {
  summary.epochs = tr.epochs;
  summary.best_epoch = tr.best_epoch;
  summary.best_validation_loss = tr.best_loss;
  summary.interrupted = tr.interrupted;
  add_network_warnings(summary, kFewSamplesNetwork);
}

}  // namespace

using namespace torch_detail;

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
  lo.live_zero_phase = false;  // the network beside it steps without delay
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

}  // namespace rcm::dynamics
