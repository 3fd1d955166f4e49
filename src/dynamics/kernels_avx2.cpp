// The per-sample network kernels with AVX2 and FMA intrinsics. This is the only
// file of the library compiled with -mavx2 -mfma (src/CMakeLists.txt); the
// networks call it through avx2_fma_kernels() only when the CPU reports both
// (__builtin_cpu_supports), so the library still runs on any x86-64. It includes
// nothing but kernels.hpp and <immintrin.h> (see kernels.hpp on why).
//
// The LSTM layer is one pass over its weight panels (kernels.hpp): per block of
// 16 hidden units, 8 ymm accumulators hold the 64 gate pre-activations while the
// panel streams past, and the cell update runs on those registers before the next
// panel, so the nonlinearities overlap the weight stream (for the default 1 x 128
// LSTM the 287 KB of weights come from L2; that stream bounds the step).

#include "kernels.hpp"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>

namespace rcm::dynamics::kernels {

namespace {

constexpr int kPrefetchFloats = 512;  // 2 KB ahead in the weight stream

inline __m256 tanh8(__m256 a) {
  using namespace tanh_coefficients;
  const __m256 x = _mm256_min_ps(_mm256_set1_ps(kClamp), _mm256_max_ps(_mm256_set1_ps(-kClamp), a));
  const __m256 x2 = _mm256_mul_ps(x, x);
  __m256 p = _mm256_fmadd_ps(_mm256_set1_ps(kAlpha13), x2, _mm256_set1_ps(kAlpha11));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(kAlpha9));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(kAlpha7));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(kAlpha5));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(kAlpha3));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(kAlpha1));
  p = _mm256_mul_ps(p, x);
  __m256 q = _mm256_fmadd_ps(_mm256_set1_ps(kBeta6), x2, _mm256_set1_ps(kBeta4));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(kBeta2));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(kBeta0));
  const __m256 r = _mm256_div_ps(p, q);
  const __m256 abs_a = _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a);
  const __m256 tiny = _mm256_cmp_ps(abs_a, _mm256_set1_ps(kTiny), _CMP_LT_OQ);
  return _mm256_blendv_ps(r, a, tiny);
}

// sigmoid(x) = tanh(x / 2) / 2 + 1 / 2, as the portable build computes it.
inline __m256 sigmoid8(__m256 a) {
  const __m256 half = _mm256_set1_ps(0.5f);
  return _mm256_fmadd_ps(half, tanh8(_mm256_mul_ps(half, a)), half);
}

inline void tanh_inplace(float* v, int n) {
  int i = 0;
  for (; i + 8 <= n; i += 8) _mm256_storeu_ps(v + i, tanh8(_mm256_loadu_ps(v + i)));
  if (i < n) {
    float tail[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int k = i; k < n; ++k) tail[k - i] = v[k];
    _mm256_storeu_ps(tail, tanh8(_mm256_loadu_ps(tail)));
    for (int k = i; k < n; ++k) v[k] = tail[k - i];
  }
}

void activate(float* v, int n, int activation) {
  if (activation == kTanh) {
    tanh_inplace(v, n);
  } else if (activation == kRelu) {
    for (int i = 0; i < n; ++i) v[i] = v[i] > 0.0f ? v[i] : 0.0f;
  }
}

void lstm_layer(const float* panels, const float* bias, int units_padded, int cols, const float* xh, float* c,
                float* h) {
  const float* p = panels;
  for (int u0 = 0; u0 < units_padded; u0 += kUnitBlock) {
    const float* b = bias + 4 * u0;
    __m256 acc[8];
    for (int v = 0; v < 8; ++v) acc[v] = _mm256_load_ps(b + 8 * v);
    for (int j = 0; j < cols; ++j) {
      const __m256 xj = _mm256_broadcast_ss(xh + j);
      for (int v = 0; v < 8; v += 2) _mm_prefetch(reinterpret_cast<const char*>(p + kPrefetchFloats + 8 * v), _MM_HINT_T0);
      for (int v = 0; v < 8; ++v) acc[v] = _mm256_fmadd_ps(_mm256_load_ps(p + 8 * v), xj, acc[v]);
      p += 64;
    }
    // acc[0..1] = i, acc[2..3] = f, acc[4..5] = g, acc[6..7] = o for 16 units.
    for (int half = 0; half < 2; ++half) {
      const __m256 ig = sigmoid8(acc[half]);
      const __m256 fg = sigmoid8(acc[2 + half]);
      const __m256 gg = tanh8(acc[4 + half]);
      const __m256 og = sigmoid8(acc[6 + half]);
      float* cu = c + u0 + 8 * half;
      const __m256 cn = _mm256_fmadd_ps(fg, _mm256_loadu_ps(cu), _mm256_mul_ps(ig, gg));
      _mm256_storeu_ps(cu, cn);
      _mm256_storeu_ps(h + u0 + 8 * half, _mm256_mul_ps(og, tanh8(cn)));
    }
  }
}

// One block of V x 8 rows with C accumulator chains over the columns (chains
// break the FMA latency when V is small, e.g. the 6-output head layer).
template <int V, int C>
inline const float* dense_block(const float* p, int cols, const float* x, const float* b, float* y) {
  __m256 acc[C][V];
  for (int v = 0; v < V; ++v) acc[0][v] = _mm256_load_ps(b + 8 * v);
  for (int k = 1; k < C; ++k)
    for (int v = 0; v < V; ++v) acc[k][v] = _mm256_setzero_ps();
  int j = 0;
  for (; j + C <= cols; j += C) {
    for (int k = 0; k < C; ++k) {
      const __m256 xj = _mm256_broadcast_ss(x + j + k);
      for (int v = 0; v < V; ++v) acc[k][v] = _mm256_fmadd_ps(_mm256_load_ps(p + 8 * v), xj, acc[k][v]);
      p += 8 * V;
    }
  }
  for (; j < cols; ++j) {
    const __m256 xj = _mm256_broadcast_ss(x + j);
    for (int v = 0; v < V; ++v) acc[0][v] = _mm256_fmadd_ps(_mm256_load_ps(p + 8 * v), xj, acc[0][v]);
    p += 8 * V;
  }
  for (int k = 1; k < C; ++k)
    for (int v = 0; v < V; ++v) acc[0][v] = _mm256_add_ps(acc[0][v], acc[k][v]);
  for (int v = 0; v < V; ++v) _mm256_storeu_ps(y + 8 * v, acc[0][v]);
  return p;
}

void dense_layer(const float* panels, const float* bias, int rows_padded, int cols, const float* x, float* y,
                 int activation) {
  const float* p = panels;
  for (int rb = 0; rb < rows_padded; rb += kPanelRows) {
    const int nb = rows_padded - rb < kPanelRows ? rows_padded - rb : kPanelRows;
    const float* b = bias + rb;
    float* out = y + rb;
    switch (nb / 8) {
      case 8: p = dense_block<8, 1>(p, cols, x, b, out); break;
      case 7: p = dense_block<7, 1>(p, cols, x, b, out); break;
      case 6: p = dense_block<6, 1>(p, cols, x, b, out); break;
      case 5: p = dense_block<5, 1>(p, cols, x, b, out); break;
      case 4: p = dense_block<4, 2>(p, cols, x, b, out); break;
      case 3: p = dense_block<3, 2>(p, cols, x, b, out); break;
      case 2: p = dense_block<2, 4>(p, cols, x, b, out); break;
      default: p = dense_block<1, 4>(p, cols, x, b, out); break;
    }
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

const KernelTable* avx2_fma_kernels() {
  static const KernelTable table{"avx2_fma", &lstm_layer, &dense_layer, &gemv_colmajor, &activate};
  return &table;
}

}  // namespace rcm::dynamics::kernels

#else

namespace rcm::dynamics::kernels {
const KernelTable* avx2_fma_kernels() { return nullptr; }
}  // namespace rcm::dynamics::kernels

#endif
