#pragma once
// LibTorch-backed training and TorchScript interop. Declared here without any
// LibTorch type; implemented in rcm::torch (src/dynamics/torch). Only available
// when the build has RCM_WITH_TORCH (the CLI sees RCM_HAVE_TORCH=1).

#include <filesystem>
#include <vector>

#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics {

// lstm: stateful truncated BPTT over contiguous streams, Adam, LR halved on
// plateau, early stopping on the validation split. mlp: per-joint tanh networks.
// hybrid: fit_linear_torque_model, then an LSTM on its residual.
FitResult fit_lstm_torque_model(const std::vector<Recording>& recordings, const FitOptions& options);
FitResult fit_mlp_torque_model(const std::vector<Recording>& recordings, const FitOptions& options);
FitResult fit_hybrid_torque_model(const std::vector<Recording>& recordings, const FitOptions& options);

// Any kind: dispatches to the fit_* above or to fit_linear_torque_model.
FitResult fit_torque_model(TorqueModelKind kind, const std::vector<Recording>& recordings,
                           const FitOptions& options);

// TorchScript module with forward(x: [B, T, 2N] raw [q, qdot], h0: [L, B, H],
// c0: [L, B, H]) -> (tau [B, T, M] in joint units, hN, cN); normalization inside.
// Layout in docs/formats.md, "Free-space model".
void export_torchscript(const LstmTorqueModel& model, const std::filesystem::path& path);

// Reads a TorchScript LSTM (trained in PyTorch) with the documented attributes:
// submodule `lstm` (nn.LSTM, batch_first), `head` (nn.Sequential of Linear and
// Tanh/ReLU), buffers input_mean, input_scale, output_mean, output_scale, and
// attribute sample_period_s (optional). Checks the result against the module's
// own forward on a random input; throws InputError on any mismatch.
std::unique_ptr<LstmTorqueModel> import_torchscript(const std::filesystem::path& path);

// LibTorch reference of one LSTM step sequence, for tests and benchmarks: runs
// torch::nn::LSTM + head over x (T x input) from zero state, returns T x outputs.
Eigen::MatrixXf run_lstm_with_libtorch(const LstmNetwork& network, const Eigen::MatrixXf& x);

}  // namespace rcm::dynamics

#include <functional>
#include <string>

namespace rcm::dynamics {
// For benchmarks: a closure that advances a torch::nn::LSTM (+ head) holding the
// given weights by one sample with its state carried (x: input_size floats,
// y: output_size floats), the way LibTorch would stream.
std::function<void(const float* x, float* y)> make_libtorch_lstm_stepper(const LstmNetwork& network);
// For benchmarks: one truncated-BPTT update (forward, backward, Adam step) of a
// freshly initialized network of the given shape on a random batch of `batch`
// streams x `window` samples, as fit_lstm_torque_model does per chunk.
void set_libtorch_threads(int threads);
std::function<void()> make_libtorch_training_step(int inputs, int hidden, int layers, int head_hidden, int outputs,
                                                  int batch, int window);
// The file (symlinks resolved) whose sgemm_ this process's LibTorch calls, or ""
// when none is loaded. Which BLAS wins depends on the link order of the whole
// program: Debian's Ceres once put ATLAS's single-threaded one ahead of OpenBLAS
// (cmake/rcm_blas.cmake), which a benchmark without Ceres did not show.
std::string get_libtorch_blas_library();
}  // namespace rcm::dynamics
