#pragma once
// Internal: the per-sample float kernels of the networks, in two builds with one
// interface — kernels_portable.cpp (baseline ISA) and kernels_avx2.cpp (the only
// file compiled with -mavx2 -mfma; chosen at run time when the CPU has both).
// This header includes nothing but <cstddef> so that the AVX2 file instantiates
// no inline function shared with the rest of the library (one definition rule:
// an AVX2 copy of a shared inline function could be picked by the linker).
//
// Layouts (built by LstmKernel / DensePanels in network_kernels.cpp):
// * LSTM layer panels. Hidden units are taken in blocks of kUnitBlock = 16; the
//   panel of block b holds the 64 gate rows (i, f, g, o) x (units 16b .. 16b+15)
//   of the fused matrix [W_ih W_hh], column after column: 64 floats of column 0,
//   then column 1, ... so the GEMV reads the weights strictly sequentially. The
//   bias is stored in the same row order. Units are padded with zero rows to a
//   multiple of 16 (a padded unit keeps c = h = 0).
// * Dense panels. Rows padded to a multiple of 8 (zeros), cut into blocks of up
//   to 64 rows, each block column after column as above.

#include <cstddef>

namespace rcm::dynamics::kernels {

constexpr int kUnitBlock = 16;  // hidden units per LSTM panel (4 gates x 16 = 64 rows)
constexpr int kPanelRows = 64;  // rows per dense panel
constexpr int kAlignment = 64;  // bytes: panels start on a cache line

enum ActivationCode : int { kIdentity = 0, kTanh = 1, kRelu = 2 };

struct KernelTable {
  const char* name;
  // One LSTM layer: gates = panels [x; h_prev] + bias, then c and h of every unit
  // (c, h: units_padded values; h may not alias xh). cols = in + H.
  void (*lstm_layer)(const float* panels, const float* bias, int units_padded, int cols, const float* xh, float* c,
                     float* h);
  // y[0:rows_padded] = act(panels x + bias), rows_padded a multiple of 8.
  void (*dense_layer)(const float* panels, const float* bias, int rows_padded, int cols, const float* x, float* y,
                      int activation);
  // y[0:rows] += W x, W column-major rows x cols (the MLP's per-joint layers).
  void (*gemv_colmajor)(const float* W, int rows, int cols, const float* x, float* y);
  // v = act(v) on n values.
  void (*activate)(float* v, int n, int activation);
};

const KernelTable& portable_kernels();
// nullptr when this build has no AVX2/FMA kernels (not x86-64, or another compiler).
const KernelTable* avx2_fma_kernels();

// tanh for float by Eigen's rational approximation (Eigen 3.4 ptanh_float, error
// a few ulp): clamp to +-7.9053, odd degree-13 numerator over even degree-6
// denominator, and x itself for |x| < 4e-4. Both builds use these coefficients.
namespace tanh_coefficients {
constexpr float kClamp = 7.90531110763549805f;
constexpr float kTiny = 0.0004f;
constexpr float kAlpha13 = -2.76076847742355e-16f;
constexpr float kAlpha11 = 2.00018790482477e-13f;
constexpr float kAlpha9 = -8.60467152213735e-11f;
constexpr float kAlpha7 = 5.12229709037114e-08f;
constexpr float kAlpha5 = 1.48572235717979e-05f;
constexpr float kAlpha3 = 6.37261928875436e-04f;
constexpr float kAlpha1 = 4.89352455891786e-03f;
constexpr float kBeta6 = 1.19825839466702e-06f;
constexpr float kBeta4 = 1.18534705686654e-04f;
constexpr float kBeta2 = 2.26843463243900e-03f;
constexpr float kBeta0 = 4.89352518554385e-03f;
}  // namespace tanh_coefficients

}  // namespace rcm::dynamics::kernels
