#pragma once
// Neural torque models run by hand-written float kernels (no LibTorch): an LSTM
// step (gate order i, f, g, o and weight layout of torch.nn.LSTM), dense stacks,
// and the three network-based TorqueModels (lstm, mlp, hybrid).

#include <Eigen/Core>
#include <cstddef>
#include <memory>
#include <vector>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/torque_model.hpp"

namespace rcm::dynamics {

namespace kernels {
struct KernelTable;  // src/dynamics/kernels.hpp
}

enum class Activation { identity, tanh, relu };

struct DenseLayer {
  Eigen::MatrixXf weight;  // out x in (torch.nn.Linear.weight)
  Eigen::VectorXf bias;    // out
  Activation activation = Activation::identity;
};

struct DenseStack {
  std::vector<DenseLayer> layers;
  int input_size() const { return layers.empty() ? 0 : static_cast<int>(layers.front().weight.cols()); }
  int output_size() const { return layers.empty() ? 0 : static_cast<int>(layers.back().weight.rows()); }
  int max_width() const;
};

struct LstmLayer {  // torch.nn.LSTM weight_ih_l{k}, weight_hh_l{k}, bias_ih_l{k}, bias_hh_l{k}
  Eigen::MatrixXf weight_ih;  // 4H x in
  Eigen::MatrixXf weight_hh;  // 4H x H
  Eigen::VectorXf bias_ih;    // 4H
  Eigen::VectorXf bias_hh;    // 4H
};

struct LstmNetwork {
  std::vector<LstmLayer> layers;
  DenseStack head;  // hidden -> outputs
  int input_size() const { return layers.empty() ? 0 : static_cast<int>(layers.front().weight_ih.cols()); }
  int hidden_size() const { return layers.empty() ? 0 : static_cast<int>(layers.front().weight_hh.cols()); }
  int output_size() const { return head.output_size(); }
  // Throws std::invalid_argument when the shapes do not chain.
  void check() const;
};

// Weights drawn from N(0, stddev^2) in a fixed order from `seed`, with a tanh
// head layer of head_hidden units: the networks of tests and benchmarks.
LstmNetwork make_random_lstm_network(int inputs, int hidden, int layers, int head_hidden, int outputs, unsigned seed,
                                     float stddev = 0.3f);
// One tanh network per output joint (inputs -> hidden -> 1), drawn the same way:
// the MLP models of tests and benchmarks.
std::vector<DenseStack> make_random_mlp_stacks(int inputs, int hidden, int outputs, unsigned seed,
                                               float stddev = 0.3f);

// Network input: [(q - mean) / scale, (qdot - mean) / scale, tanh(qdot / velocity_tanh_scale),
// acceleration / acceleration_scale, Dahl states]; output: y = y_normalized * scale + mean.
struct Normalization {
  Eigen::VectorXf input_mean, input_scale;    // 2 num_joints: [q, qdot]
  Eigen::VectorXf output_mean, output_scale;  // num_outputs
  // F x num_joints scales in joint velocity units, feature f of joint k at
  // f * num_joints + k; empty: the network sees [q, qdot] only. Direction
  // features exist because drawing the friction step at qdot = 0 from
  // z-normalized qdot needs input weights of ~100, which Adam grows only over
  // far more updates than a 10-minute fit makes (docs/dynamics.md, "Direction
  // features").
  Eigen::VectorXf velocity_tanh_scale;
  // K time constants (s) of the causal acceleration signals (AccelerationFilter)
  // and their K x num_joints scales (feature f of joint k at f * num_joints + k);
  // both empty: none. They exist because the inertial torque needs qddot, which
  // the LSTM would otherwise have to learn to differentiate from noisy qdot; the
  // raw difference of consecutive samples is mostly encoder noise
  // (docs/dynamics.md, "Acceleration features").
  Eigen::VectorXf acceleration_filter_s;
  Eigen::VectorXf acceleration_scale;
  // D x num_joints characteristic displacements x_c (joint units, feature f of
  // joint k at f * num_joints + k) of Dahl states (DahlFilter), fed unscaled
  // (they lie in [-1, 1]); empty: none. They exist because the friction at rest
  // and just after a reversal is set by the direction of the last motion and
  // the displacement since, a memory over arbitrarily long holds that the LSTM's
  // state did not learn to keep in a 10-minute fit (docs/dynamics.md, "Dahl
  // features").
  Eigen::VectorXf dahl_displacement;
  int network_inputs(int joints) const {
    return 2 * joints +
           static_cast<int>(velocity_tanh_scale.size() + acceleration_scale.size() + dahl_displacement.size());
  }
  bool has_acceleration() const { return acceleration_filter_s.size() > 0; }
  bool has_dahl() const { return dahl_displacement.size() > 0; }
};

// The causal acceleration signals behind Normalization::acceleration_*: for each
// time constant tau and joint, the backward difference of qdot low-passed with
// a <- a + dt / (tau + dt) * ((qdot - qdot_prev) / dt - a), starting from a = 0
// at the first sample. A sample at the same time as the previous one changes
// nothing; an earlier one restarts the filter (as at the first sample). Sized
// once; update() does not allocate.
class AccelerationFilter {
 public:
  AccelerationFilter() = default;
  AccelerationFilter(const Eigen::VectorXf& filter_s, int joints);
  void reset();
  // qd: num_joints values; the new values are in values().
  void update(double t, const double* qd);
  // K x num_joints, feature f of joint k at f * num_joints + k.
  const Eigen::VectorXd& values() const { return a_; }

 private:
  Eigen::VectorXd tau_, qd_prev_, a_;
  double t_prev_ = 0.0;
  bool started_ = false;
};

// The filter over a whole recording from the reset state: T x (K num_joints).
Eigen::MatrixXd compute_acceleration_features(const Eigen::VectorXf& filter_s, const Eigen::VectorXd& time,
                                              const Eigen::MatrixXd& velocity, int joints);

// The Dahl states behind Normalization::dahl_displacement: for each displacement
// x_c and joint, z <- compute_dahl_state(z, q - q_prev, x_c) (linear_model.hpp;
// computed vectorized, equal to it within rounding),
// starting from z = 0 at the first sample. Position-driven, so time stamps play
// no part. Sized once; update() does not allocate.
class DahlFilter {
 public:
  DahlFilter() = default;
  // displacement: D x num_joints positive values, feature f of joint k at f * num_joints + k.
  DahlFilter(const Eigen::VectorXf& displacement, int joints);
  void reset();
  // q: num_joints values; the new states are in values().
  void update(const double* q);
  const Eigen::VectorXd& values() const { return z_; }

 private:
  Eigen::ArrayXd inverse_x_c_, q_prev_, dq_, sign_;
  Eigen::VectorXd z_;
  bool started_ = false;
};

// The filter over a whole recording from the reset state: T x (D num_joints).
Eigen::MatrixXd compute_dahl_features(const Eigen::VectorXf& displacement, const Eigen::MatrixXd& position,
                                      int joints);

// Instruction set of the per-sample kernels: a portable build for the baseline
// ISA, and an AVX2/FMA build (one translation unit compiled with -mavx2 -mfma)
// that is used only when the CPU reports both.
enum class KernelIsa { portable, avx2_fma };
// True when this build has kernels for `isa` and this CPU can run them.
bool kernel_isa_available(KernelIsa isa);
// avx2_fma when available, else portable: what every kernel uses by default.
KernelIsa best_kernel_isa();
const char* to_string(KernelIsa isa);

// Floats starting on a 64-byte boundary (the kernels' weight panels).
class AlignedFloats {
 public:
  AlignedFloats() = default;
  explicit AlignedFloats(std::size_t size);  // zero-filled
  AlignedFloats(const AlignedFloats& other);
  AlignedFloats& operator=(const AlignedFloats& other);
  AlignedFloats(AlignedFloats&&) noexcept = default;
  AlignedFloats& operator=(AlignedFloats&&) noexcept = default;
  float* data() { return data_.get(); }
  const float* data() const { return data_.get(); }
  std::size_t size() const { return size_; }

 private:
  struct Free {
    void operator()(float* p) const noexcept;
  };
  std::unique_ptr<float[], Free> data_;
  std::size_t size_ = 0;
};

// Streaming LSTM with its state (h, c per layer) and every buffer preallocated.
// Each layer's [W_ih W_hh] is fused into one weight stream of 64-row panels
// (gates i, f, g, o of 16 hidden units, column after column) read once per step;
// the cell update of those 16 units runs on the accumulators right after their
// panel. The head's layers use the same panel layout.
class LstmKernel {
 public:
  // Throws std::invalid_argument when `isa` is not available on this CPU.
  explicit LstmKernel(const LstmNetwork& network, KernelIsa isa = best_kernel_isa());
  struct State {
    std::vector<Eigen::VectorXf> h, c;  // per layer; hidden units padded to a multiple of 16 (zeros)
    Eigen::VectorXf xh, head_a, head_b;
  };
  State create_state() const;
  static void reset(State& state);
  // x: input_size values (already normalized); y: output_size values. No allocation.
  void step(State& state, const float* x, float* y) const;
  const LstmNetwork& network() const { return network_; }
  KernelIsa isa() const { return isa_; }

 private:
  struct DensePanels {
    int rows = 0, rows_padded = 0, cols = 0, activation = 0;
    AlignedFloats panels, bias;
  };
  LstmNetwork network_;
  KernelIsa isa_;
  const kernels::KernelTable* kernels_ = nullptr;
  int units_padded_ = 0;                  // H rounded up to a multiple of 16
  std::vector<AlignedFloats> lstm_panels_;  // per layer, see src/dynamics/kernels.hpp
  std::vector<AlignedFloats> lstm_bias_;    // b_ih + b_hh in panel row order
  std::vector<DensePanels> head_;
  int head_width_ = 0;                    // largest padded head layer
};

// Dense stack forward in float; a and b are scratch of max_width() each. No allocation.
void compute_dense_forward(const DenseStack& stack, const float* x, float* y, float* a, float* b);

// output_delay: d >= 0; the network's output at sample t is the torque of
// sample t - d (see TorqueModel::output_delay), trained so with its targets
// shifted by d.
class LstmTorqueModel final : public TorqueModel {
 public:
  LstmTorqueModel(TorqueModelInfo info, LstmNetwork network, Normalization normalization, int output_delay = 0);
  TorqueModelKind kind() const override { return TorqueModelKind::lstm; }
  int output_delay() const override { return output_delay_; }
  std::unique_ptr<TorqueModelWorkspace> create_workspace() const override;
  void reset_state(TorqueModelWorkspace& workspace) const override;
  void compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                    double* tau) const override;
  nlohmann::json save_parameters() const override;
  const LstmNetwork& network() const { return kernel_.network(); }
  const Normalization& normalization() const { return normalization_; }

 private:
  LstmKernel kernel_;
  Normalization normalization_;
  int output_delay_ = 0;
};

// Yilmaz et al.: one dense network per joint on [q, qdot] of all joints (memoryless).
class MlpTorqueModel final : public TorqueModel {
 public:
  MlpTorqueModel(TorqueModelInfo info, std::vector<DenseStack> per_joint, Normalization normalization);
  TorqueModelKind kind() const override { return TorqueModelKind::mlp; }
  std::unique_ptr<TorqueModelWorkspace> create_workspace() const override;
  void reset_state(TorqueModelWorkspace& workspace) const override;
  void compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                    double* tau) const override;
  nlohmann::json save_parameters() const override;
  const std::vector<DenseStack>& networks() const { return per_joint_; }
  const Normalization& normalization() const { return normalization_; }

 private:
  std::vector<DenseStack> per_joint_;
  Normalization normalization_;
};

// Yang et al.: model-based prediction plus an LSTM on its residual.
class HybridTorqueModel final : public TorqueModel {
 public:
  HybridTorqueModel(TorqueModelInfo info, std::shared_ptr<const LinearTorqueModel> base,
                    LstmNetwork residual, Normalization residual_normalization);
  TorqueModelKind kind() const override { return TorqueModelKind::hybrid; }
  std::unique_ptr<TorqueModelWorkspace> create_workspace() const override;
  void reset_state(TorqueModelWorkspace& workspace) const override;
  void compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                    double* tau) const override;
  Eigen::MatrixXd predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                   const Eigen::MatrixXd& velocity) const override;
  nlohmann::json save_parameters() const override;
  const LinearTorqueModel& base() const { return *base_; }
  const LstmNetwork& residual_network() const { return kernel_.network(); }
  const Normalization& normalization() const { return normalization_; }
  std::unique_ptr<TorqueSequencePredictor> create_sequence_predictor() const override;

 private:
  friend class HybridSequencePredictor;
  std::shared_ptr<const LinearTorqueModel> base_;
  LstmKernel kernel_;
  Normalization normalization_;
};

}  // namespace rcm::dynamics
