#include "rcm/dynamics/networks.hpp"

#include <random>
#include <fmt/format.h>

#include <algorithm>
#include <cstddef>
#if defined(__x86_64__)
#include <immintrin.h>
#include <random>
#endif
#include <stdexcept>

#include "model_io.hpp"
#include "rcm/common/error.hpp"

namespace rcm::dynamics {

namespace {

// The per-sample kernels. Weights of each LSTM layer are stored as "panels": for
// every block of 64 gate rows, the 64 values of column 0, then column 1, ... so the
// GEMV reads them strictly sequentially while up to 8 AVX registers accumulate.
// An AVX2/FMA version is chosen at run time when the CPU has it; the generic
// version is plain loops the compiler vectorizes for the baseline ISA.
#define RCM_ALWAYS_INLINE inline __attribute__((always_inline))
constexpr int kPanelRows = 64;

RCM_ALWAYS_INLINE void panel_gemv_body(const float* __restrict p, int rows_padded, int cols,
                                       const float* __restrict x, float* __restrict y) {
  for (int rb = 0; rb < rows_padded; rb += kPanelRows) {
    const int nb = std::min(kPanelRows, rows_padded - rb);
    float acc[kPanelRows];
    for (int i = 0; i < nb; ++i) acc[i] = y[rb + i];
    for (int j = 0; j < cols; ++j) {
      const float xj = x[j];
      for (int i = 0; i < nb; ++i) acc[i] += p[i] * xj;
      p += nb;
    }
    for (int i = 0; i < nb; ++i) y[rb + i] = acc[i];
  }
}

// tanh by the rational approximation Eigen uses for float (error a few ulp),
// written as a branch-free loop.
RCM_ALWAYS_INLINE void tanh_body(float* __restrict v, int n) {
  for (int i = 0; i < n; ++i) {
    const float a = v[i];
    const float x = std::min(7.90531110763549805f, std::max(-7.90531110763549805f, a));
    const float x2 = x * x;
    float p = -2.76076847742355e-16f;
    p = p * x2 + 2.00018790482477e-13f;
    p = p * x2 + -8.60467152213735e-11f;
    p = p * x2 + 5.12229709037114e-08f;
    p = p * x2 + 1.48572235717979e-05f;
    p = p * x2 + 6.37261928875436e-04f;
    p = p * x2 + 4.89352455891786e-03f;
    p = p * x;
    float q = 1.19825839466702e-06f;
    q = q * x2 + 1.18534705686654e-04f;
    q = q * x2 + 2.26843463243900e-03f;
    q = q * x2 + 4.89352518554385e-03f;
    const float r = p / q;
    v[i] = std::abs(a) < 0.0004f ? a : r;
  }
}

// sigmoid(x) = (tanh(x / 2) + 1) / 2 on the i, f, o blocks; tanh on g.
RCM_ALWAYS_INLINE void gates_body(float* __restrict gates, float* __restrict c, float* __restrict h, int H) {
  float* gi = gates;
  float* gf = gates + H;
  float* go = gates + 3 * H;
  for (int k = 0; k < H; ++k) {
    gi[k] *= 0.5f;
    gf[k] *= 0.5f;
    go[k] *= 0.5f;
  }
  tanh_body(gates, 4 * H);
  const float* gg = gates + 2 * H;
  for (int k = 0; k < H; ++k) {
    const float i = 0.5f * gi[k] + 0.5f;
    const float f = 0.5f * gf[k] + 0.5f;
    c[k] = f * c[k] + i * gg[k];
    h[k] = c[k];
  }
  tanh_body(h, H);
  for (int k = 0; k < H; ++k) h[k] *= 0.5f * go[k] + 0.5f;
}

// y[0:rows] += W x, W column-major rows x cols (dense heads; small).
RCM_ALWAYS_INLINE void gemv_body(const float* __restrict W, int rows, int cols, const float* __restrict x,
                                 float* __restrict y) {
  for (int j = 0; j < cols; ++j) {
    const float xj = x[j];
    const float* w = W + static_cast<std::size_t>(j) * rows;
    for (int i = 0; i < rows; ++i) y[i] += xj * w[i];
  }
}

void panel_gemv_generic(const float* p, int rows_padded, int cols, const float* x, float* y) {
  panel_gemv_body(p, rows_padded, cols, x, y);
}
void gates_generic(float* gates, float* c, float* h, int H) { gates_body(gates, c, h, H); }
void tanh_generic(float* v, int n) { tanh_body(v, n); }
void gemv_generic(const float* W, int rows, int cols, const float* x, float* y) { gemv_body(W, rows, cols, x, y); }

#if defined(__x86_64__) && defined(__GNUC__)
#define RCM_HAVE_AVX2_PATH 1
template <int V>
__attribute__((target("avx2,fma"))) inline const float* panel_block_avx2(const float* p, int cols, const float* x,
                                                                       float* y) {
  __m256 acc[V];
  for (int v = 0; v < V; ++v) acc[v] = _mm256_loadu_ps(y + 8 * v);
  for (int j = 0; j < cols; ++j) {
    const __m256 xj = _mm256_broadcast_ss(x + j);
    for (int v = 0; v < V; ++v) acc[v] = _mm256_fmadd_ps(_mm256_loadu_ps(p + 8 * v), xj, acc[v]);
    p += 8 * V;
  }
  for (int v = 0; v < V; ++v) _mm256_storeu_ps(y + 8 * v, acc[v]);
  return p;
}

__attribute__((target("avx2,fma"))) void panel_gemv_avx2(const float* p, int rows_padded, int cols, const float* x,
                                                        float* y) {
  for (int rb = 0; rb < rows_padded; rb += kPanelRows) {
    switch (std::min(kPanelRows, rows_padded - rb) / 8) {
      case 8: p = panel_block_avx2<8>(p, cols, x, y + rb); break;
      case 7: p = panel_block_avx2<7>(p, cols, x, y + rb); break;
      case 6: p = panel_block_avx2<6>(p, cols, x, y + rb); break;
      case 5: p = panel_block_avx2<5>(p, cols, x, y + rb); break;
      case 4: p = panel_block_avx2<4>(p, cols, x, y + rb); break;
      case 3: p = panel_block_avx2<3>(p, cols, x, y + rb); break;
      case 2: p = panel_block_avx2<2>(p, cols, x, y + rb); break;
      default: p = panel_block_avx2<1>(p, cols, x, y + rb); break;
    }
  }
}
__attribute__((target("avx2,fma"))) void gates_avx2(float* gates, float* c, float* h, int H) {
  gates_body(gates, c, h, H);
}
__attribute__((target("avx2,fma"))) void tanh_avx2(float* v, int n) { tanh_body(v, n); }
__attribute__((target("avx2,fma"))) void gemv_avx2(const float* W, int rows, int cols, const float* x, float* y) {
  gemv_body(W, rows, cols, x, y);
}
#endif

bool cpu_has_avx2_fma() {
#if defined(RCM_HAVE_AVX2_PATH)
  static const bool has = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }();
  return has;
#else
  return false;
#endif
}

void panel_gemv(const float* p, int rows_padded, int cols, const float* x, float* y) {
#if defined(RCM_HAVE_AVX2_PATH)
  if (cpu_has_avx2_fma()) return panel_gemv_avx2(p, rows_padded, cols, x, y);
#endif
  panel_gemv_generic(p, rows_padded, cols, x, y);
}
void lstm_gates_and_state(float* gates, float* c, float* h, int H) {
#if defined(RCM_HAVE_AVX2_PATH)
  if (cpu_has_avx2_fma()) return gates_avx2(gates, c, h, H);
#endif
  gates_generic(gates, c, h, H);
}
void tanh_inplace(float* v, int n) {
#if defined(RCM_HAVE_AVX2_PATH)
  if (cpu_has_avx2_fma()) return tanh_avx2(v, n);
#endif
  tanh_generic(v, n);
}
void gemv_accumulate(const float* W, int rows, int cols, const float* x, float* y) {
#if defined(RCM_HAVE_AVX2_PATH)
  if (cpu_has_avx2_fma()) return gemv_avx2(W, rows, cols, x, y);
#endif
  gemv_generic(W, rows, cols, x, y);
}

// Panel layout of an R x C matrix with rows padded to a multiple of 8 (zeros).
Eigen::VectorXf make_panels(const Eigen::MatrixXf& W, int rows_padded) {
  Eigen::VectorXf p(static_cast<Eigen::Index>(rows_padded) * W.cols());
  Eigen::Index k = 0;
  for (int rb = 0; rb < rows_padded; rb += kPanelRows) {
    const int nb = std::min(kPanelRows, rows_padded - rb);
    for (Eigen::Index j = 0; j < W.cols(); ++j)
      for (int i = 0; i < nb; ++i) p[k++] = rb + i < W.rows() ? W(rb + i, j) : 0.0f;
  }
  return p;
}

void apply_activation(Activation a, float* v, int n) {
  switch (a) {
    case Activation::identity: return;
    case Activation::tanh: tanh_inplace(v, n); return;
    case Activation::relu:
      for (int i = 0; i < n; ++i) v[i] = std::max(v[i], 0.0f);
      return;
  }
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
  return {{"input_mean", detail::encode_vector(n.input_mean)},
          {"input_scale", detail::encode_vector(n.input_scale)},
          {"output_mean", detail::encode_vector(n.output_mean)},
          {"output_scale", detail::encode_vector(n.output_scale)}};
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
  return n;
}

void check_normalization(const Normalization& n, int joints, int outputs) {
  if (n.input_mean.size() != 2 * joints || n.input_scale.size() != 2 * joints)
    throw std::invalid_argument("normalization: expected 2 x num_joints input entries");
  if (n.output_mean.size() != outputs || n.output_scale.size() != outputs)
    throw std::invalid_argument("normalization: expected num_outputs output entries");
}

// Buffers shared by the recurrent kinds.
struct LstmWorkspace final : TorqueModelWorkspace {
  LstmKernel::State state;
  Eigen::VectorXf x, y;
  Eigen::VectorXd base;  // hybrid: model-based part
  std::unique_ptr<TorqueModelWorkspace> base_ws;
};

void normalize_input(const Normalization& n, int N, const double* q, const double* qd, float* x) {
  for (int k = 0; k < N; ++k) {
    x[k] = static_cast<float>((q[k] - n.input_mean[k]) / n.input_scale[k]);
    x[N + k] = static_cast<float>((qd[k] - n.input_mean[N + k]) / n.input_scale[N + k]);
  }
}

}  // namespace

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

LstmKernel::LstmKernel(const LstmNetwork& network) : network_(network) {
  network_.check();
  const int H = network_.hidden_size();
  rows_padded_ = (4 * H + 7) / 8 * 8;
  for (const auto& l : network_.layers) {
    Eigen::MatrixXf fused(l.weight_ih.rows(), l.weight_ih.cols() + l.weight_hh.cols());
    fused << l.weight_ih, l.weight_hh;
    fused_.push_back(make_panels(fused, rows_padded_));
    Eigen::VectorXf b = Eigen::VectorXf::Zero(rows_padded_);
    b.head(4 * H) = l.bias_ih + l.bias_hh;
    bias_.push_back(std::move(b));
  }
}

LstmKernel::State LstmKernel::create_state() const {
  State s;
  const int H = network_.hidden_size();
  for (std::size_t k = 0; k < network_.layers.size(); ++k) {
    s.h.push_back(Eigen::VectorXf::Zero(H));
    s.c.push_back(Eigen::VectorXf::Zero(H));
  }
  s.gates = Eigen::VectorXf::Zero(rows_padded_);
  s.xh = Eigen::VectorXf::Zero(std::max(network_.input_size(), H) + H);
  s.head_a = Eigen::VectorXf::Zero(network_.head.max_width());
  s.head_b = Eigen::VectorXf::Zero(network_.head.max_width());
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
  for (std::size_t k = 0; k < fused_.size(); ++k) {
    float* gates = s.gates.data();
    std::copy(bias_[k].data(), bias_[k].data() + rows_padded_, gates);
    // [W_ih W_hh] [x; h] in one pass over the panels.
    std::copy(in, in + in_size, xh);
    std::copy(s.h[k].data(), s.h[k].data() + H, xh + in_size);
    panel_gemv(fused_[k].data(), rows_padded_, in_size + H, xh, gates);
    lstm_gates_and_state(gates, s.c[k].data(), s.h[k].data(), H);
    in = s.h[k].data();
    in_size = H;
  }
  compute_dense_forward(network_.head, in, y, s.head_a.data(), s.head_b.data());
}

void compute_dense_forward(const DenseStack& stack, const float* x, float* y, float* a, float* b) {
  const float* in = x;
  const std::size_t L = stack.layers.size();
  for (std::size_t k = 0; k < L; ++k) {
    const auto& l = stack.layers[k];
    const int rows = static_cast<int>(l.weight.rows());
    float* out = k + 1 == L ? y : (k % 2 == 0 ? a : b);
    std::copy(l.bias.data(), l.bias.data() + rows, out);
    gemv_accumulate(l.weight.data(), rows, static_cast<int>(l.weight.cols()), in, out);
    apply_activation(l.activation, out, rows);
    in = out;
  }
}

// ---------------------------------------------------------------------------- lstm

LstmTorqueModel::LstmTorqueModel(TorqueModelInfo info, LstmNetwork network, Normalization normalization)
    : TorqueModel(std::move(info)), kernel_(network), normalization_(std::move(normalization)) {
  if (network.input_size() != 2 * num_joints() || network.output_size() != num_outputs())
    throw std::invalid_argument("LSTM model: network sizes do not match 2 x num_joints inputs / num_outputs");
  check_normalization(normalization_, num_joints(), num_outputs());
}

std::unique_ptr<TorqueModelWorkspace> LstmTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LstmWorkspace>();
  ws->state = kernel_.create_state();
  ws->x = Eigen::VectorXf::Zero(2 * num_joints());
  ws->y = Eigen::VectorXf::Zero(num_outputs());
  return ws;
}

void LstmTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  LstmKernel::reset(static_cast<LstmWorkspace&>(workspace).state);
}

void LstmTorqueModel::compute_step(TorqueModelWorkspace& workspace, double, const double* q, const double* qd,
                                   double* tau) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  normalize_input(normalization_, num_joints(), q, qd, ws.x.data());
  kernel_.step(ws.state, ws.x.data(), ws.y.data());
  for (int j = 0; j < num_outputs(); ++j)
    tau[j] = static_cast<double>(ws.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
}

nlohmann::json LstmTorqueModel::save_parameters() const {
  return {{"lstm", save_lstm(kernel_.network())}, {"normalization", save_normalization(normalization_)}};
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
    if (s.input_size() != 2 * num_joints() || s.output_size() != 1)
      throw std::invalid_argument("MLP model: each network maps 2 x num_joints inputs to 1 output");
  }
  check_normalization(normalization_, num_joints(), num_outputs());
}

std::unique_ptr<TorqueModelWorkspace> MlpTorqueModel::create_workspace() const {
  auto ws = std::make_unique<MlpWorkspace>();
  int w = 0;
  for (const auto& s : per_joint_) w = std::max(w, s.max_width());
  ws->x = Eigen::VectorXf::Zero(2 * num_joints());
  ws->a = Eigen::VectorXf::Zero(w);
  ws->b = Eigen::VectorXf::Zero(w);
  return ws;
}

void MlpTorqueModel::reset_state(TorqueModelWorkspace&) const {}

void MlpTorqueModel::compute_step(TorqueModelWorkspace& workspace, double, const double* q, const double* qd,
                                  double* tau) const {
  auto& ws = static_cast<MlpWorkspace&>(workspace);
  normalize_input(normalization_, num_joints(), q, qd, ws.x.data());
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
  if (residual.input_size() != 2 * num_joints() || residual.output_size() != num_outputs())
    throw std::invalid_argument("hybrid model: residual network sizes do not match");
  check_normalization(normalization_, num_joints(), num_outputs());
}

std::unique_ptr<TorqueModelWorkspace> HybridTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LstmWorkspace>();
  ws->state = kernel_.create_state();
  ws->x = Eigen::VectorXf::Zero(2 * num_joints());
  ws->y = Eigen::VectorXf::Zero(num_outputs());
  ws->base_ws = base_->create_workspace();
  return ws;
}

void HybridTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  LstmKernel::reset(ws.state);
  base_->reset_state(*ws.base_ws);
}

void HybridTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                     double* tau) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  base_->compute_step(*ws.base_ws, t, q, qd, tau);
  normalize_input(normalization_, num_joints(), q, qd, ws.x.data());
  kernel_.step(ws.state, ws.x.data(), ws.y.data());
  for (int j = 0; j < num_outputs(); ++j)
    tau[j] += static_cast<double>(ws.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
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
      return std::make_unique<LstmTorqueModel>(std::move(info), std::move(net), std::move(norm));
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

LstmNetwork make_random_lstm_network(int inputs, int hidden, int layers, int head_hidden, int outputs, unsigned seed,
                                     float stddev) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, stddev);
  auto rnd = [&](int r, int c) {
    Eigen::MatrixXf m(r, c);
    for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = g(rng);
    return m;
  };
  const int H = hidden;
  LstmNetwork n;
  for (int k = 0; k < layers; ++k)
    n.layers.push_back({rnd(4 * H, k ? H : inputs), rnd(4 * H, H), rnd(4 * H, 1).col(0), rnd(4 * H, 1).col(0)});
  n.head.layers.push_back({rnd(head_hidden, H), rnd(head_hidden, 1).col(0), Activation::tanh});
  n.head.layers.push_back({rnd(outputs, head_hidden), rnd(outputs, 1).col(0), Activation::identity});
  return n;
}

}  // namespace rcm::dynamics
