// The networks' arithmetic: the kernel ISA chosen at run time, the LSTM kernel
// (fused, padded weight panels), the dense stack forward pass, the networks'
// shape checks and random networks for tests and benchmarks.
#include <fmt/format.h>

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <random>
#include <stdexcept>

#include "kernels.hpp"
#include "network_parts.hpp"
#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics {

namespace {

bool cpu_has_avx2_fma() {
#if (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__)
  static const bool has = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }();
  return has;
#else
  return false;
#endif
}

const kernels::KernelTable& kernels_for(KernelIsa isa) {
  if (isa == KernelIsa::avx2_fma) {
    if (!kernel_isa_available(isa))
      throw std::invalid_argument("network kernels: AVX2/FMA kernels are not available on this CPU or build");
    return *kernels::avx2_fma_kernels();
  }
  return kernels::portable_kernels();
}

const kernels::KernelTable& best_kernels() {
  static const kernels::KernelTable& table = kernels_for(best_kernel_isa());
  return table;
}

int activation_code(Activation a) {
  switch (a) {
    case Activation::identity: return kernels::kIdentity;
    case Activation::tanh: return kernels::kTanh;
    case Activation::relu: return kernels::kRelu;
  }
  return kernels::kIdentity;
}

}  // namespace

void detail::check_stack(const DenseStack& s, const char* what) {
  for (std::size_t k = 0; k < s.layers.size(); ++k) {
    const auto& l = s.layers[k];
    if (l.bias.size() != l.weight.rows())
      throw std::invalid_argument(fmt::format("{} layer {}: bias size differs from weight rows", what, k));
    if (k > 0 && l.weight.cols() != s.layers[k - 1].weight.rows())
      throw std::invalid_argument(fmt::format("{} layer {}: input size does not match the previous layer", what, k));
  }
  if (s.layers.empty()) throw std::invalid_argument(fmt::format("{}: no layers", what));
}

int DenseStack::max_width() const {
  int w = input_size();
  for (const auto& l : layers) w = std::max(w, static_cast<int>(l.weight.rows()));
  return w;
}

void LstmNetwork::check() const {
  if (layers.empty()) throw std::invalid_argument("LSTM: no layers");
  const auto H = layers.front().weight_hh.cols();
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const auto& l = layers[k];
    if (l.weight_hh.rows() != 4 * H || l.weight_hh.cols() != H || l.weight_ih.rows() != 4 * H ||
        l.bias_ih.size() != 4 * H || l.bias_hh.size() != 4 * H)
      throw std::invalid_argument(fmt::format("LSTM layer {}: expected 4H x . weights and 4H biases, H = {}", k, H));
    if (k > 0 && l.weight_ih.cols() != H)
      throw std::invalid_argument(fmt::format("LSTM layer {}: input size must equal hidden size", k));
  }
  detail::check_stack(head, "LSTM head");
  if (head.input_size() != H) throw std::invalid_argument("LSTM head: input size must equal hidden size");
}

bool kernel_isa_available(KernelIsa isa) {
  if (isa == KernelIsa::portable) return true;
  return kernels::avx2_fma_kernels() != nullptr && cpu_has_avx2_fma();
}

KernelIsa best_kernel_isa() {
  return kernel_isa_available(KernelIsa::avx2_fma) ? KernelIsa::avx2_fma : KernelIsa::portable;
}

const char* to_string(KernelIsa isa) { return isa == KernelIsa::avx2_fma ? "avx2_fma" : "portable"; }

AlignedFloats::AlignedFloats(std::size_t size) : size_(size) {
  if (size == 0) return;
  const std::size_t bytes =
      (size * sizeof(float) + kernels::kAlignment - 1) / kernels::kAlignment * kernels::kAlignment;
  auto* p = static_cast<float*>(std::aligned_alloc(kernels::kAlignment, bytes));
  if (p == nullptr) throw std::bad_alloc();
  std::memset(p, 0, bytes);
  data_.reset(p);
}

AlignedFloats::AlignedFloats(const AlignedFloats& other) : AlignedFloats(other.size_) {
  if (size_ > 0) std::memcpy(data_.get(), other.data_.get(), size_ * sizeof(float));
}

AlignedFloats& AlignedFloats::operator=(const AlignedFloats& other) {
  if (this != &other) *this = AlignedFloats(other);
  return *this;
}

void AlignedFloats::Free::operator()(float* p) const noexcept { std::free(p); }

LstmKernel::LstmKernel(const LstmNetwork& network, KernelIsa isa)
    : network_(network), isa_(isa), kernels_(&kernels_for(isa)) {
  network_.check();
  const int H = network_.hidden_size();
  constexpr int U = kernels::kUnitBlock;
  units_padded_ = (H + U - 1) / U * U;
  // LSTM layers: panel of unit block u0 = rows (gate, unit) for gate in i, f, g, o
  // and unit in u0 .. u0 + 15, column after column of [W_ih W_hh].
  for (const auto& l : network_.layers) {
    const auto in = l.weight_ih.cols();
    const auto cols = in + H;
    AlignedFloats panels(static_cast<std::size_t>(4 * units_padded_) * static_cast<std::size_t>(cols));
    AlignedFloats bias(static_cast<std::size_t>(4 * units_padded_));
    float* p = panels.data();
    for (int u0 = 0; u0 < units_padded_; u0 += U) {
      for (Eigen::Index j = 0; j < cols; ++j)
        for (int g = 0; g < 4; ++g)
          for (int k = 0; k < U; ++k) {
            const int unit = u0 + k, row = g * H + unit;
            *p++ = unit >= H ? 0.0f : (j < in ? l.weight_ih(row, j) : l.weight_hh(row, j - in));
          }
      for (int g = 0; g < 4; ++g)
        for (int k = 0; k < U; ++k) {
          const int unit = u0 + k, row = g * H + unit;
          bias.data()[4 * u0 + g * U + k] = unit >= H ? 0.0f : l.bias_ih[row] + l.bias_hh[row];
        }
    }
    lstm_panels_.push_back(std::move(panels));
    lstm_bias_.push_back(std::move(bias));
  }
  // Head: rows padded to a multiple of 8, blocks of up to 64 rows, column after column.
  for (const auto& l : network_.head.layers) {
    DensePanels d;
    d.rows = static_cast<int>(l.weight.rows());
    d.rows_padded = (d.rows + 7) / 8 * 8;
    d.cols = static_cast<int>(l.weight.cols());
    d.activation = activation_code(l.activation);
    d.panels = AlignedFloats(static_cast<std::size_t>(d.rows_padded) * static_cast<std::size_t>(d.cols));
    d.bias = AlignedFloats(static_cast<std::size_t>(d.rows_padded));
    float* p = d.panels.data();
    for (int rb = 0; rb < d.rows_padded; rb += kernels::kPanelRows) {
      const int nb = std::min(kernels::kPanelRows, d.rows_padded - rb);
      for (int j = 0; j < d.cols; ++j)
        for (int i = 0; i < nb; ++i) *p++ = rb + i < d.rows ? l.weight(rb + i, j) : 0.0f;
    }
    for (int i = 0; i < d.rows; ++i) d.bias.data()[i] = l.bias[i];
    head_width_ = std::max(head_width_, d.rows_padded);
    head_.push_back(std::move(d));
  }
}

LstmKernel::State LstmKernel::create_state() const {
  State s;
  const int H = network_.hidden_size();
  for (std::size_t k = 0; k < network_.layers.size(); ++k) {
    s.h.push_back(Eigen::VectorXf::Zero(units_padded_));
    s.c.push_back(Eigen::VectorXf::Zero(units_padded_));
  }
  s.xh = Eigen::VectorXf::Zero(std::max(network_.input_size(), H) + H);
  s.head_a = Eigen::VectorXf::Zero(head_width_);
  s.head_b = Eigen::VectorXf::Zero(head_width_);
  return s;
}

void LstmKernel::reset(State& state) {
  for (auto& h : state.h) h.setZero();
  for (auto& c : state.c) c.setZero();
}

void LstmKernel::step(State& s, const float* x, float* y) const {
  const int H = network_.hidden_size();
  const float* in = x;
  int in_size = network_.input_size();
  float* xh = s.xh.data();
  for (std::size_t k = 0; k < lstm_panels_.size(); ++k) {
    // [x; h_prev] for one pass over the fused [W_ih W_hh] panels; h is rewritten in place.
    std::copy(in, in + in_size, xh);
    std::copy(s.h[k].data(), s.h[k].data() + H, xh + in_size);
    kernels_->lstm_layer(lstm_panels_[k].data(), lstm_bias_[k].data(), units_padded_, in_size + H, xh,
                         s.c[k].data(), s.h[k].data());
    in = s.h[k].data();
    in_size = H;
  }
  float* bufs[2] = {s.head_a.data(), s.head_b.data()};
  for (std::size_t k = 0; k < head_.size(); ++k) {
    const auto& d = head_[k];
    float* out = bufs[k % 2];
    kernels_->dense_layer(d.panels.data(), d.bias.data(), d.rows_padded, d.cols, in, out, d.activation);
    in = out;
  }
  std::copy(in, in + head_.back().rows, y);
}

void compute_dense_forward(const DenseStack& stack, const float* x, float* y, float* a, float* b) {
  const auto& kern = best_kernels();
  const float* in = x;
  const std::size_t L = stack.layers.size();
  for (std::size_t k = 0; k < L; ++k) {
    const auto& l = stack.layers[k];
    const int rows = static_cast<int>(l.weight.rows());
    float* out = k + 1 == L ? y : (k % 2 == 0 ? a : b);
    std::copy(l.bias.data(), l.bias.data() + rows, out);
    kern.gemv_colmajor(l.weight.data(), rows, static_cast<int>(l.weight.cols()), in, out);
    kern.activate(out, rows, activation_code(l.activation));
    in = out;
  }
}

namespace {
// N(0, stddev^2) matrices drawn in call order from one generator.
class RandomMatrices {
 public:
  RandomMatrices(unsigned seed, float stddev) : rng_(seed), g_(0.0f, stddev) {}
  Eigen::MatrixXf operator()(int r, int c) {
    Eigen::MatrixXf m(r, c);
    for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = g_(rng_);
    return m;
  }

 private:
  std::mt19937 rng_;
  std::normal_distribution<float> g_;
};
}  // namespace

std::vector<DenseStack> make_random_mlp_stacks(int inputs, int hidden, int outputs, unsigned seed, float stddev) {
  RandomMatrices rnd(seed, stddev);
  std::vector<DenseStack> stacks(static_cast<std::size_t>(outputs));
  for (auto& s : stacks) {
    s.layers.push_back({rnd(hidden, inputs), rnd(hidden, 1).col(0), Activation::tanh});
    s.layers.push_back({rnd(1, hidden), rnd(1, 1).col(0), Activation::identity});
  }
  return stacks;
}

LstmNetwork make_random_lstm_network(int inputs, int hidden, int layers, int head_hidden, int outputs, unsigned seed,
                                     float stddev) {
  RandomMatrices rnd(seed, stddev);
  const int H = hidden;
  LstmNetwork n;
  for (int k = 0; k < layers; ++k)
    n.layers.push_back({rnd(4 * H, k ? H : inputs), rnd(4 * H, H), rnd(4 * H, 1).col(0), rnd(4 * H, 1).col(0)});
  n.head.layers.push_back({rnd(head_hidden, H), rnd(head_hidden, 1).col(0), Activation::tanh});
  n.head.layers.push_back({rnd(outputs, head_hidden), rnd(outputs, 1).col(0), Activation::identity});
  return n;
}

}  // namespace rcm::dynamics
