// Training of the mlp kind: one tanh network per joint on [q, qdot]
// (Yilmaz et al.), trained together, each on its own loss.

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <iostream>

#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/training.hpp"
#include "torch_parts.hpp"

namespace rcm::dynamics {

using namespace torch_detail;

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

}  // namespace rcm::dynamics
