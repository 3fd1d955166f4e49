// The per-sample network kernels for the baseline instruction set: plain loops
// over fixed-size blocks that the compiler vectorizes (SSE2 on x86-64). Same
// layouts and arithmetic as kernels_avx2.cpp; see kernels.hpp.

#include "kernels.hpp"

namespace rcm::dynamics::kernels {

namespace {

inline float tanh_one(float a) {
  using namespace tanh_coefficients;
  float x = a > kClamp ? kClamp : a;
  x = x < -kClamp ? -kClamp : x;
  const float x2 = x * x;
  float p = kAlpha13;
  p = p * x2 + kAlpha11;
  p = p * x2 + kAlpha9;
  p = p * x2 + kAlpha7;
  p = p * x2 + kAlpha5;
  p = p * x2 + kAlpha3;
  p = p * x2 + kAlpha1;
  p = p * x;
  float q = kBeta6;
  q = q * x2 + kBeta4;
  q = q * x2 + kBeta2;
  q = q * x2 + kBeta0;
  const float r = p / q;
  const float abs_a = a < 0.0f ? -a : a;
  return abs_a < kTiny ? a : r;
}

void tanh_inplace(float* __restrict v, int n) {
  for (int i = 0; i < n; ++i) v[i] = tanh_one(v[i]);
}

void activate(float* v, int n, int activation) {
  if (activation == kTanh) {
    tanh_inplace(v, n);
  } else if (activation == kRelu) {
    for (int i = 0; i < n; ++i) v[i] = v[i] > 0.0f ? v[i] : 0.0f;
  }
}

// acc[0:nb] += panel * x, the panel read column after column.
inline const float* panel_block(const float* __restrict p, int nb, int cols, const float* __restrict x,
                                float* __restrict acc) {
  for (int j = 0; j < cols; ++j) {
    const float xj = x[j];
    for (int i = 0; i < nb; ++i) acc[i] += p[i] * xj;
    p += nb;
  }
  return p;
}

void lstm_layer(const float* panels, const float* bias, int units_padded, int cols, const float* xh, float* c,
                float* h) {
  constexpr int U = kUnitBlock;
  const float* p = panels;
  for (int u0 = 0; u0 < units_padded; u0 += U) {
    float acc[4 * U];
    for (int i = 0; i < 4 * U; ++i) acc[i] = bias[4 * u0 + i];
    p = panel_block(p, 4 * U, cols, xh, acc);
    // sigmoid(x) = tanh(x / 2) / 2 + 1 / 2 on the i, f, o rows; tanh on g.
    for (int k = 0; k < U; ++k) {
      acc[k] *= 0.5f;
      acc[U + k] *= 0.5f;
      acc[3 * U + k] *= 0.5f;
    }
    tanh_inplace(acc, 4 * U);
    float t[U];
    for (int k = 0; k < U; ++k) {
      const float ig = 0.5f * acc[k] + 0.5f;
      const float fg = 0.5f * acc[U + k] + 0.5f;
      c[u0 + k] = fg * c[u0 + k] + ig * acc[2 * U + k];
      t[k] = c[u0 + k];
    }
    tanh_inplace(t, U);
    for (int k = 0; k < U; ++k) h[u0 + k] = (0.5f * acc[3 * U + k] + 0.5f) * t[k];
  }
}

void dense_layer(const float* panels, const float* bias, int rows_padded, int cols, const float* x, float* y,
                 int activation) {
  const float* p = panels;
  for (int rb = 0; rb < rows_padded; rb += kPanelRows) {
    const int nb = rows_padded - rb < kPanelRows ? rows_padded - rb : kPanelRows;
    float acc[kPanelRows];
    for (int i = 0; i < nb; ++i) acc[i] = bias[rb + i];
    p = panel_block(p, nb, cols, x, acc);
    for (int i = 0; i < nb; ++i) y[rb + i] = acc[i];
  }
  activate(y, rows_padded, activation);
}

void gemv_colmajor(const float* __restrict W, int rows, int cols, const float* __restrict x, float* __restrict y) {
  for (int j = 0; j < cols; ++j) {
    const float xj = x[j];
    const float* w = W + static_cast<std::size_t>(j) * static_cast<std::size_t>(rows);
    for (int i = 0; i < rows; ++i) y[i] += xj * w[i];
  }
}

}  // namespace

const KernelTable& portable_kernels() {
  static const KernelTable table{"portable", &lstm_layer, &dense_layer, &gemv_colmajor, &activate};
  return table;
}

}  // namespace rcm::dynamics::kernels
