// rcm::torch's shared pieces (torch_parts.hpp): conversions, device, the LSTM
// module's weights, a fit's bookkeeping; the dispatch of fit_torque_model; and
// the LibTorch references for tests and benchmarks.

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <dlfcn.h>

#include <cstring>
#include <filesystem>
#include <iostream>

#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/training.hpp"
#include "torch_parts.hpp"

namespace rcm::dynamics {

namespace torch_detail {

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

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

torch::Tensor tensor_of(const Eigen::MatrixXf& m) { return to_tensor(m); }
torch::Tensor tensor_of(const Eigen::VectorXf& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {v.size()}, torch::kFloat32).clone();
}

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

void check_training_interrupt(int best_epoch, const char* label, bool verbose) {
  if (best_epoch == 0)
    throw Interrupted(fmt::format("interrupted while training the {} network, before its first epoch ended", label));
  if (verbose)
    std::cerr << fmt::format("[{}] interrupted: keeping epoch {}, the best validation loss so far\n", label, best_epoch);
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
                                     "libopenblas0-openmp (README.md, \"Dependencies\")",
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

}  // namespace torch_detail

using namespace torch_detail;

FitResult fit_torque_model(TorqueModelKind kind, const std::vector<Recording>& recordings, const FitOptions& o) {
  switch (kind) {
    case TorqueModelKind::lstm: return fit_lstm_torque_model(recordings, o);
    case TorqueModelKind::mlp: return fit_mlp_torque_model(recordings, o);
    case TorqueModelKind::hybrid: return fit_hybrid_torque_model(recordings, o);
    case TorqueModelKind::linear: break;
  }
  return fit_linear_torque_model(recordings, o);
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
