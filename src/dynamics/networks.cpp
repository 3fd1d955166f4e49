#include "rcm/dynamics/networks.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <random>
#include <stdexcept>

#include "kernels.hpp"
#include "model_io.hpp"
#include "rcm/common/error.hpp"

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

std::string to_string(Activation a) {
  switch (a) {
    case Activation::identity: return "identity";
    case Activation::tanh: return "tanh";
    case Activation::relu: return "relu";
  }
  return "identity";
}

Activation parse_activation(const nlohmann::json& j, const std::string& source, const std::string& field) {
  if (j.is_string()) {
    const auto s = j.get<std::string>();
    if (s == "identity") return Activation::identity;
    if (s == "tanh") return Activation::tanh;
    if (s == "relu") return Activation::relu;
  }
  detail::fail(source, field, "expected \"identity\", \"tanh\" or \"relu\"");
}

void check_stack(const DenseStack& s, const char* what) {
  for (std::size_t k = 0; k < s.layers.size(); ++k) {
    const auto& l = s.layers[k];
    if (l.bias.size() != l.weight.rows())
      throw std::invalid_argument(fmt::format("{} layer {}: bias size differs from weight rows", what, k));
    if (k > 0 && l.weight.cols() != s.layers[k - 1].weight.rows())
      throw std::invalid_argument(fmt::format("{} layer {}: input size does not match the previous layer", what, k));
  }
  if (s.layers.empty()) throw std::invalid_argument(fmt::format("{}: no layers", what));
}

nlohmann::json save_stack(const DenseStack& s) {
  nlohmann::json layers = nlohmann::json::array();
  for (const auto& l : s.layers)
    layers.push_back({{"weight", detail::encode_array(l.weight)},
                      {"bias", detail::encode_vector(l.bias)},
                      {"activation", to_string(l.activation)}});
  return layers;
}

DenseStack load_stack(const nlohmann::json& j, const std::string& source, const std::string& field) {
  if (!j.is_array()) detail::fail(source, field, "expected an array of layers");
  DenseStack s;
  for (std::size_t k = 0; k < j.size(); ++k) {
    const std::string f = fmt::format("{}[{}]", field, k);
    DenseLayer l;
    l.weight = detail::decode_array_f(detail::require(j[k], "weight", source, f), source, f + ".weight");
    l.bias = detail::decode_vector_f(detail::require(j[k], "bias", source, f), source, f + ".bias");
    l.activation = parse_activation(detail::require(j[k], "activation", source, f), source, f + ".activation");
    s.layers.push_back(std::move(l));
  }
  return s;
}

nlohmann::json save_lstm(const LstmNetwork& n) {
  nlohmann::json layers = nlohmann::json::array();
  for (const auto& l : n.layers)
    layers.push_back({{"weight_ih", detail::encode_array(l.weight_ih)},
                      {"weight_hh", detail::encode_array(l.weight_hh)},
                      {"bias_ih", detail::encode_vector(l.bias_ih)},
                      {"bias_hh", detail::encode_vector(l.bias_hh)}});
  return {{"hidden_size", n.hidden_size()}, {"num_layers", n.layers.size()}, {"layers", layers},
          {"head", save_stack(n.head)}};
}

LstmNetwork load_lstm(const nlohmann::json& j, const std::string& source, const std::string& field) {
  LstmNetwork n;
  const auto& layers = detail::require(j, "layers", source, field);
  if (!layers.is_array() || layers.empty()) detail::fail(source, field + ".layers", "expected a non-empty array");
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const std::string f = fmt::format("{}.layers[{}]", field, k);
    LstmLayer l;
    l.weight_ih = detail::decode_array_f(detail::require(layers[k], "weight_ih", source, f), source, f + ".weight_ih");
    l.weight_hh = detail::decode_array_f(detail::require(layers[k], "weight_hh", source, f), source, f + ".weight_hh");
    l.bias_ih = detail::decode_vector_f(detail::require(layers[k], "bias_ih", source, f), source, f + ".bias_ih");
    l.bias_hh = detail::decode_vector_f(detail::require(layers[k], "bias_hh", source, f), source, f + ".bias_hh");
    n.layers.push_back(std::move(l));
  }
  n.head = load_stack(detail::require(j, "head", source, field), source, field + ".head");
  try {
    n.check();
  } catch (const std::invalid_argument& e) {
    detail::fail(source, field, e.what());
  }
  return n;
}

nlohmann::json save_normalization(const Normalization& n) {
  nlohmann::json j = {{"input_mean", detail::encode_vector(n.input_mean)},
                      {"input_scale", detail::encode_vector(n.input_scale)},
                      {"output_mean", detail::encode_vector(n.output_mean)},
                      {"output_scale", detail::encode_vector(n.output_scale)}};
  // Absent when empty, so that a model without direction features writes no such field.
  if (n.velocity_tanh_scale.size() > 0) j["velocity_tanh_scale"] = detail::encode_vector(n.velocity_tanh_scale);
  if (n.has_acceleration()) {
    j["acceleration_filter_s"] = detail::encode_vector(n.acceleration_filter_s);
    j["acceleration_scale"] = detail::encode_vector(n.acceleration_scale);
  }
  if (n.has_dahl()) j["dahl_displacement"] = detail::encode_vector(n.dahl_displacement);
  return j;
}

Normalization load_normalization(const nlohmann::json& j, const std::string& source, const std::string& field,
                                 int inputs, int outputs) {
  Normalization n;
  auto get = [&](const char* key, int size) {
    Eigen::VectorXf v =
        detail::decode_vector_f(detail::require(j, key, source, field), source, field + "." + key, size);
    return v;
  };
  n.input_mean = get("input_mean", inputs);
  n.input_scale = get("input_scale", inputs);
  n.output_mean = get("output_mean", outputs);
  n.output_scale = get("output_scale", outputs);
  if ((n.input_scale.array() <= 0).any() || (n.output_scale.array() <= 0).any())
    detail::fail(source, field, "scales must be positive");
  if (j.contains("velocity_tanh_scale")) {
    const std::string f = field + ".velocity_tanh_scale";
    n.velocity_tanh_scale = detail::decode_vector_f(j["velocity_tanh_scale"], source, f, -1);
    if (n.velocity_tanh_scale.size() % (inputs / 2) != 0)
      detail::fail(source, f, fmt::format("expected a multiple of {} values (features x joints), got {}", inputs / 2,
                                          n.velocity_tanh_scale.size()));
    if (!(n.velocity_tanh_scale.array() > 0).all()) detail::fail(source, f, "scales must be positive");
  }
  if (j.contains("acceleration_filter_s") || j.contains("acceleration_scale")) {
    // One without the other would shift every later input: both or neither.
    const std::string ff = field + ".acceleration_filter_s", fs = field + ".acceleration_scale";
    n.acceleration_filter_s =
        detail::decode_vector_f(detail::require(j, "acceleration_filter_s", source, field), source, ff, -1);
    if (n.acceleration_filter_s.size() == 0) detail::fail(source, ff, "expected at least one time constant");
    if (!(n.acceleration_filter_s.array() > 0).all()) detail::fail(source, ff, "time constants must be positive");
    n.acceleration_scale = detail::decode_vector_f(detail::require(j, "acceleration_scale", source, field), source, fs,
                                                   static_cast<int>(n.acceleration_filter_s.size()) * (inputs / 2));
    if (!(n.acceleration_scale.array() > 0).all()) detail::fail(source, fs, "scales must be positive");
  }
  if (j.contains("dahl_displacement")) {
    const std::string f = field + ".dahl_displacement";
    n.dahl_displacement = detail::decode_vector_f(j["dahl_displacement"], source, f, -1);
    if (n.dahl_displacement.size() == 0 || n.dahl_displacement.size() % (inputs / 2) != 0)
      detail::fail(source, f, fmt::format("expected a positive multiple of {} values (features x joints), got {}",
                                          inputs / 2, n.dahl_displacement.size()));
    if (!(n.dahl_displacement.array() > 0).all() || !n.dahl_displacement.allFinite())
      detail::fail(source, f, "displacements must be positive and finite");
  }
  return n;
}

void check_normalization(const Normalization& n, int joints, int outputs) {
  if (n.input_mean.size() != 2 * joints || n.input_scale.size() != 2 * joints)
    throw std::invalid_argument("normalization: expected 2 x num_joints input entries");
  if (n.output_mean.size() != outputs || n.output_scale.size() != outputs)
    throw std::invalid_argument("normalization: expected num_outputs output entries");
  if (n.velocity_tanh_scale.size() % joints != 0 || !(n.velocity_tanh_scale.array() > 0).all())
    throw std::invalid_argument("normalization: velocity_tanh_scale must hold features x num_joints positive values");
  if (!(n.acceleration_filter_s.array() > 0).all() || !(n.acceleration_scale.array() > 0).all() ||
      n.acceleration_scale.size() != n.acceleration_filter_s.size() * joints)
    throw std::invalid_argument(
        "normalization: acceleration_filter_s (K positive time constants) and acceleration_scale (K x num_joints "
        "positive values) do not match");
  if (n.dahl_displacement.size() % joints != 0 || !(n.dahl_displacement.array() > 0).all() ||
      !n.dahl_displacement.allFinite())
    throw std::invalid_argument(
        "normalization: dahl_displacement must hold features x num_joints positive finite values");
}

// Buffers shared by the recurrent kinds.
struct LstmWorkspace final : TorqueModelWorkspace {
  LstmKernel::State state;
  AccelerationFilter acceleration;
  DahlFilter dahl;
  Eigen::VectorXf x, y;
  Eigen::VectorXd base;  // hybrid: model-based part
  std::unique_ptr<TorqueModelWorkspace> base_ws;
};

// x: n.network_inputs(N) floats; acceleration, dahl: the filters' values (read
// only when n has those features).
void normalize_input(const Normalization& n, int N, const double* q, const double* qd, const double* acceleration,
                     const double* dahl, float* x) {
  for (int k = 0; k < N; ++k) {
    x[k] = static_cast<float>((q[k] - n.input_mean[k]) / n.input_scale[k]);
    x[N + k] = static_cast<float>((qd[k] - n.input_mean[N + k]) / n.input_scale[N + k]);
  }
  const auto F = n.velocity_tanh_scale.size();
  if (F > 0) {
    for (Eigen::Index f = 0; f < F; ++f) x[2 * N + f] = static_cast<float>(qd[f % N]) / n.velocity_tanh_scale[f];
    // Eigen's vectorized tanh, as for the training's inputs; a scalar std::tanh loop was slower.
    Eigen::Map<Eigen::ArrayXf> features(x + 2 * N, F);
    features = features.tanh();
  }
  float* xa = x + 2 * N + F;
  for (Eigen::Index f = 0; f < n.acceleration_scale.size(); ++f)
    xa[f] = static_cast<float>(acceleration[f]) / n.acceleration_scale[f];
  float* xd = xa + n.acceleration_scale.size();
  for (Eigen::Index f = 0; f < n.dahl_displacement.size(); ++f) xd[f] = static_cast<float>(dahl[f]);
}

void init_filters(const Normalization& n, int N, LstmWorkspace& ws) {
  ws.acceleration = AccelerationFilter(n.acceleration_filter_s, N);
  ws.dahl = DahlFilter(n.dahl_displacement, N);
}

void reset_filters(LstmWorkspace& ws) {
  ws.acceleration.reset();
  ws.dahl.reset();
}

// Advances the feature filters by one sample and writes the network input to ws.x.
void compute_network_input(const Normalization& n, int N, LstmWorkspace& ws, double t, const double* q,
                           const double* qd) {
  if (n.has_acceleration()) ws.acceleration.update(t, qd);
  if (n.has_dahl()) ws.dahl.update(q);
  normalize_input(n, N, q, qd, ws.acceleration.values().data(), ws.dahl.values().data(), ws.x.data());
}

}  // namespace

AccelerationFilter::AccelerationFilter(const Eigen::VectorXf& filter_s, int joints)
    : tau_(filter_s.cast<double>()),
      qd_prev_(Eigen::VectorXd::Zero(joints)),
      a_(Eigen::VectorXd::Zero(filter_s.size() * joints)) {}

void AccelerationFilter::reset() {
  a_.setZero();
  started_ = false;
}

void AccelerationFilter::update(double t, const double* qd) {
  const Eigen::Index N = qd_prev_.size();
  const double dt = t - t_prev_;
  if (started_ && dt == 0.0) return;  // a repeated time stamp carries no new difference
  if (!started_ || !(dt > 0)) {
    a_.setZero();
  } else {
    for (Eigen::Index f = 0; f < tau_.size(); ++f) {
      const double alpha = dt / (tau_[f] + dt);
      for (Eigen::Index k = 0; k < N; ++k) {
        double& a = a_[f * N + k];
        a += alpha * ((qd[k] - qd_prev_[k]) / dt - a);
      }
    }
  }
  for (Eigen::Index k = 0; k < N; ++k) qd_prev_[k] = qd[k];
  t_prev_ = t;
  started_ = true;
}

DahlFilter::DahlFilter(const Eigen::VectorXf& displacement, int joints)
    : inverse_x_c_(displacement.cast<double>().array().inverse()),
      q_prev_(Eigen::ArrayXd::Zero(joints)),
      dq_(Eigen::ArrayXd::Zero(displacement.size())),
      sign_(Eigen::ArrayXd::Zero(displacement.size())),
      z_(Eigen::VectorXd::Zero(displacement.size())) {}

void DahlFilter::reset() {
  z_.setZero();
  started_ = false;
}

void DahlFilter::update(const double* q) {
  const Eigen::Index N = q_prev_.size();
  const Eigen::Map<const Eigen::ArrayXd> q_now(q, N);
  if (started_ && z_.size() > 0) {
    dq_.head(N) = q_now - q_prev_;  // the same displacement drives every x_c of a joint
    for (Eigen::Index f = 1; f < z_.size() / N; ++f) dq_.segment(f * N, N) = dq_.head(N);
    // compute_dahl_state for every state at once with Eigen's vectorized exp
    // (scalar std::exp cost 0.3 us of the 4.9 us default step); dq = 0 gives
    // sign 0 and a factor 1, so a joint at rest keeps its state as there.
    sign_ = dq_.sign();
    z_.array() = sign_ + (z_.array() - sign_) * (-dq_.abs() * inverse_x_c_).exp();
  }
  q_prev_ = q_now;
  started_ = true;
}

Eigen::MatrixXd compute_dahl_features(const Eigen::VectorXf& displacement, const Eigen::MatrixXd& position,
                                      int joints) {
  DahlFilter filter(displacement, joints);
  Eigen::MatrixXd out(position.rows(), displacement.size());
  Eigen::VectorXd q(joints);
  for (Eigen::Index t = 0; t < position.rows(); ++t) {
    q = position.row(t).head(joints).transpose();
    filter.update(q.data());
    out.row(t) = filter.values().transpose();
  }
  return out;
}

Eigen::MatrixXd compute_acceleration_features(const Eigen::VectorXf& filter_s, const Eigen::VectorXd& time,
                                              const Eigen::MatrixXd& velocity, int joints) {
  AccelerationFilter filter(filter_s, joints);
  Eigen::MatrixXd out(time.size(), filter_s.size() * joints);
  Eigen::VectorXd qd(joints);
  for (Eigen::Index t = 0; t < time.size(); ++t) {
    qd = velocity.row(t).head(joints).transpose();
    filter.update(time[t], qd.data());
    out.row(t) = filter.values().transpose();
  }
  return out;
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
  check_stack(head, "LSTM head");
  if (head.input_size() != H) throw std::invalid_argument("LSTM head: input size must equal hidden size");
}

// ---------------------------------------------------------------------------- kernels

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

// ---------------------------------------------------------------------------- lstm

LstmTorqueModel::LstmTorqueModel(TorqueModelInfo info, LstmNetwork network, Normalization normalization,
                                 int output_delay)
    : TorqueModel(std::move(info)),
      kernel_(network),
      normalization_(std::move(normalization)),
      output_delay_(output_delay) {
  check_normalization(normalization_, num_joints(), num_outputs());
  if (output_delay_ < 0) throw std::invalid_argument("LSTM model: output_delay must be >= 0 samples");
  if (network.input_size() != normalization_.network_inputs(num_joints()) || network.output_size() != num_outputs())
    throw std::invalid_argument(
        "LSTM model: network sizes do not match the normalization's inputs (2 x num_joints + direction, "
        "acceleration and Dahl features) / num_outputs");
}

std::unique_ptr<TorqueModelWorkspace> LstmTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LstmWorkspace>();
  ws->state = kernel_.create_state();
  init_filters(normalization_, num_joints(), *ws);
  ws->x = Eigen::VectorXf::Zero(normalization_.network_inputs(num_joints()));
  ws->y = Eigen::VectorXf::Zero(num_outputs());
  return ws;
}

void LstmTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  LstmKernel::reset(ws.state);
  reset_filters(ws);
}

void LstmTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                   double* tau) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  compute_network_input(normalization_, num_joints(), ws, t, q, qd);
  kernel_.step(ws.state, ws.x.data(), ws.y.data());
  for (int j = 0; j < num_outputs(); ++j)
    tau[j] = static_cast<double>(ws.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
}

nlohmann::json LstmTorqueModel::save_parameters() const {
  nlohmann::json j = {{"lstm", save_lstm(kernel_.network())}, {"normalization", save_normalization(normalization_)}};
  // Absent at 0, so that a causal model writes no such field.
  if (output_delay_ > 0) j["output_delay_samples"] = output_delay_;
  return j;
}

// ---------------------------------------------------------------------------- mlp

namespace {
struct MlpWorkspace final : TorqueModelWorkspace {
  Eigen::VectorXf x, a, b;
  float y = 0;
};
}  // namespace

MlpTorqueModel::MlpTorqueModel(TorqueModelInfo info, std::vector<DenseStack> per_joint, Normalization normalization)
    : TorqueModel(std::move(info)), per_joint_(std::move(per_joint)), normalization_(std::move(normalization)) {
  if (static_cast<int>(per_joint_.size()) != num_outputs())
    throw std::invalid_argument("MLP model: expected one network per output joint");
  for (const auto& s : per_joint_) {
    check_stack(s, "MLP");
  }
  check_normalization(normalization_, num_joints(), num_outputs());
  if (normalization_.has_acceleration() || normalization_.has_dahl())
    throw std::invalid_argument("MLP model: acceleration and Dahl features need a state, and the MLP is memoryless");
  for (const auto& s : per_joint_)
    if (s.input_size() != normalization_.network_inputs(num_joints()) || s.output_size() != 1)
      throw std::invalid_argument("MLP model: each network maps the normalization's inputs to 1 output");
}

std::unique_ptr<TorqueModelWorkspace> MlpTorqueModel::create_workspace() const {
  auto ws = std::make_unique<MlpWorkspace>();
  int w = 0;
  for (const auto& s : per_joint_) w = std::max(w, s.max_width());
  ws->x = Eigen::VectorXf::Zero(normalization_.network_inputs(num_joints()));
  ws->a = Eigen::VectorXf::Zero(w);
  ws->b = Eigen::VectorXf::Zero(w);
  return ws;
}

void MlpTorqueModel::reset_state(TorqueModelWorkspace&) const {}

void MlpTorqueModel::compute_step(TorqueModelWorkspace& workspace, double, const double* q, const double* qd,
                                  double* tau) const {
  auto& ws = static_cast<MlpWorkspace&>(workspace);
  normalize_input(normalization_, num_joints(), q, qd, nullptr, nullptr, ws.x.data());
  for (int j = 0; j < num_outputs(); ++j) {
    compute_dense_forward(per_joint_[j], ws.x.data(), &ws.y, ws.a.data(), ws.b.data());
    tau[j] = static_cast<double>(ws.y) * normalization_.output_scale[j] + normalization_.output_mean[j];
  }
}

nlohmann::json MlpTorqueModel::save_parameters() const {
  nlohmann::json nets = nlohmann::json::array();
  for (const auto& s : per_joint_) nets.push_back(save_stack(s));
  return {{"networks", nets}, {"normalization", save_normalization(normalization_)}};
}

// ---------------------------------------------------------------------------- hybrid

HybridTorqueModel::HybridTorqueModel(TorqueModelInfo info, std::shared_ptr<const LinearTorqueModel> base,
                                     LstmNetwork residual, Normalization residual_normalization)
    : TorqueModel(std::move(info)),
      base_(std::move(base)),
      kernel_(residual),
      normalization_(std::move(residual_normalization)) {
  if (!base_ || base_->num_joints() != num_joints() || base_->num_outputs() != num_outputs())
    throw std::invalid_argument("hybrid model: base model joints differ");
  check_normalization(normalization_, num_joints(), num_outputs());
  if (residual.input_size() != normalization_.network_inputs(num_joints()) || residual.output_size() != num_outputs())
    throw std::invalid_argument("hybrid model: residual network sizes do not match");
}

std::unique_ptr<TorqueModelWorkspace> HybridTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LstmWorkspace>();
  ws->state = kernel_.create_state();
  init_filters(normalization_, num_joints(), *ws);
  ws->x = Eigen::VectorXf::Zero(normalization_.network_inputs(num_joints()));
  ws->y = Eigen::VectorXf::Zero(num_outputs());
  ws->base_ws = base_->create_workspace();
  return ws;
}

void HybridTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  LstmKernel::reset(ws.state);
  reset_filters(ws);
  base_->reset_state(*ws.base_ws);
}

void HybridTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                     double* tau) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  base_->compute_step(*ws.base_ws, t, q, qd, tau);
  compute_network_input(normalization_, num_joints(), ws, t, q, qd);
  kernel_.step(ws.state, ws.x.data(), ws.y.data());
  for (int j = 0; j < num_outputs(); ++j)
    tau[j] += static_cast<double>(ws.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
}

Eigen::MatrixXd HybridTorqueModel::predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                                    const Eigen::MatrixXd& velocity) const {
  // The base's whole-recording prediction (its residual was trained against
  // that one, see training), plus the residual network stepped with its state.
  Eigen::MatrixXd out = base_->predict_sequence(time, position, velocity);
  auto ws = create_workspace();
  auto& lw = static_cast<LstmWorkspace&>(*ws);
  const int N = num_joints();
  Eigen::VectorXd q(N), qd(N);
  for (Eigen::Index t = 0; t < time.size(); ++t) {
    q = position.row(t).head(N).transpose();
    qd = velocity.row(t).head(N).transpose();
    compute_network_input(normalization_, N, lw, time[t], q.data(), qd.data());
    kernel_.step(lw.state, lw.x.data(), lw.y.data());
    for (int j = 0; j < num_outputs(); ++j)
      out(t, j) += static_cast<double>(lw.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
  }
  return out;
}

nlohmann::json HybridTorqueModel::save_parameters() const {
  return {{"base", base_->save_parameters()},
          {"residual", save_lstm(kernel_.network())},
          {"normalization", save_normalization(normalization_)}};
}

// ---------------------------------------------------------------------------- loading

std::unique_ptr<TorqueModel> detail::load_network_parameters(TorqueModelInfo info, int kind_int,
                                                             const nlohmann::json& p, const std::string& source) {
  const auto kind = static_cast<TorqueModelKind>(kind_int);
  const int N = info.num_joints, M = info.num_outputs;
  try {
    if (kind == TorqueModelKind::lstm) {
      auto net = load_lstm(require(p, "lstm", source, "parameters"), source, "parameters.lstm");
      auto norm = load_normalization(require(p, "normalization", source, "parameters"), source,
                                     "parameters.normalization", 2 * N, M);
      int delay = 0;
      if (p.contains("output_delay_samples")) {
        const auto& d = p["output_delay_samples"];
        if (!d.is_number_integer() || d.get<std::int64_t>() < 0 || d.get<std::int64_t>() > 100000)
          fail(source, "parameters.output_delay_samples", "expected an integer number of samples in [0, 100000]");
        delay = d.get<int>();
      }
      return std::make_unique<LstmTorqueModel>(std::move(info), std::move(net), std::move(norm), delay);
    }
    if (kind == TorqueModelKind::mlp) {
      const auto& nets = require(p, "networks", source, "parameters");
      if (!nets.is_array()) fail(source, "parameters.networks", "expected an array");
      std::vector<DenseStack> stacks;
      for (std::size_t k = 0; k < nets.size(); ++k)
        stacks.push_back(load_stack(nets[k], source, fmt::format("parameters.networks[{}]", k)));
      auto norm = load_normalization(require(p, "normalization", source, "parameters"), source,
                                     "parameters.normalization", 2 * N, M);
      return std::make_unique<MlpTorqueModel>(std::move(info), std::move(stacks), std::move(norm));
    }
    TorqueModelInfo base_info = info;
    base_info.training = nlohmann::json::object();
    std::shared_ptr<const TorqueModel> base =
        load_linear_parameters(base_info, require(p, "base", source, "parameters"), source);
    auto linear = std::dynamic_pointer_cast<const LinearTorqueModel>(base);
    auto net = load_lstm(require(p, "residual", source, "parameters"), source, "parameters.residual");
    auto norm = load_normalization(require(p, "normalization", source, "parameters"), source,
                                   "parameters.normalization", 2 * N, M);
    return std::make_unique<HybridTorqueModel>(std::move(info), linear, std::move(net), std::move(norm));
  } catch (const std::invalid_argument& e) {
    fail(source, "parameters", e.what());
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
