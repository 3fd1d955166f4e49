#pragma once
// Internal to rcm::torch: what its files share. The conversions between Eigen
// and LibTorch, the training data, the LSTM module, early stopping and a fit's
// bookkeeping. torch_data.cpp prepares the data, torch_lstm_fit.cpp trains the
// lstm and hybrid kinds, torch_mlp_fit.cpp the mlp, torchscript.cpp exports and
// imports TorchScript; torch_support.cpp holds the rest.

#include <torch/torch.h>

#include <chrono>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics::torch_detail {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0);

// Thresholds documented by `rcm dynamics fit --help` (docs/cli.md).
constexpr std::size_t kFewSamplesNetwork = 24000;   // 2 min at 200 Hz: below, "too few to trust"
constexpr std::size_t kSmallDataNetwork = 60000;    // 5 min at 200 Hz: below, a small network

torch::Device select_device(const FitOptions& options, std::string& name);
void setup_torch(const FitOptions& options);

torch::Tensor to_tensor(const Eigen::MatrixXf& m);  // rows x cols, row-major copy
torch::Tensor tensor_of(const Eigen::MatrixXf& m);
torch::Tensor tensor_of(const Eigen::VectorXf& v);
Eigen::MatrixXf to_eigen(const torch::Tensor& t);
Eigen::VectorXf to_eigen_vector(const torch::Tensor& t);

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

// The features of FitOptions, the kind's default where unset.
inline InputFeatures resolve_input_features(const FitOptions& o, TorqueModelKind kind) {
  return {o.velocity_tanh_scales.value_or(get_default_velocity_tanh_scales(kind)),
          o.acceleration_filters_s.value_or(get_default_acceleration_filters_s(kind)),
          o.dahl_fractions.value_or(get_default_dahl_fractions(kind))};
}

SequenceData prepare_data(const std::vector<Recording>& recs, const std::vector<Eigen::MatrixXd>& targets,
                          const TimeSplit& split, int N, int M, const InputFeatures& features);

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

LstmNetwork to_network(LstmNet& net);

std::vector<torch::Tensor> clone_parameters(torch::nn::Module& m);
void restore_parameters(torch::nn::Module& m, const std::vector<torch::Tensor>& saved);
void set_learning_rate(torch::optim::Adam& opt, double lr);

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

// An interrupt drops the epoch in progress; the best finished one is kept, or
// there is nothing to keep.
void check_training_interrupt(int best_epoch, const char* label, bool verbose);

// ---------------------------------------------------------------------------- a fit's bookkeeping

void add_network_warnings(FitSummary& s, std::size_t few);
std::vector<Eigen::MatrixXd> effort_targets(const std::vector<Recording>& recs, int M);
FitSummary make_summary(TorqueModelKind kind, const TimeSplit& split);
TorqueModelInfo make_network_info(const std::vector<Recording>& recs, int N, int M);
// The test errors, the time and the summary in the model's info: `rebuild`
// makes the model again with that info.
FitResult finish(std::unique_ptr<TorqueModel> model, FitSummary summary, const std::vector<Recording>& recs,
                 const TimeSplit& split, const FitOptions& o, Clock::time_point t0,
                 const std::function<std::unique_ptr<TorqueModel>(TorqueModelInfo)>& rebuild);

}  // namespace rcm::dynamics::torch_detail
