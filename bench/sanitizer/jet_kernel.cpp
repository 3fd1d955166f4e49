// The kind of arithmetic the estimator's automatic differentiation does
// (ceres::Jet<double, 7> through small Eigen expressions), timed: what each
// sanitizer flag costs on it (bench/sanitizer_cost.py).
#include <ceres/jet.h>

#include <Eigen/Core>
#include <chrono>
#include <cstdio>

using Jet = ceres::Jet<double, 7>;

template <class T>
__attribute__((noinline)) Eigen::Matrix<T, 3, 1> compute_kernel(const Eigen::Matrix3d& A, const Eigen::Matrix<T, 3, 1>& x,
                                                                 const T* p) {
  Eigen::Matrix<T, 3, 1> y = A.cast<T>() * x;
  for (int i = 0; i < 20; ++i) y = p[0] * y + p[1] * x.cwiseProduct(y) - p[2] * x / (T(1.0) + p[3] * y.squaredNorm());
  return y;
}

int main() {
  Eigen::Matrix3d A;
  A << 0.6, -0.2, 0.1, 0.3, 0.5, -0.4, -0.1, 0.2, 0.7;
  Jet p[4];
  for (int i = 0; i < 4; ++i) p[i] = Jet(0.1 * (i + 1), i);
  Eigen::Matrix<Jet, 3, 1> x;
  for (int i = 0; i < 3; ++i) x[i] = Jet(0.3 * i, 4 + i);
  const auto t0 = std::chrono::steady_clock::now();
  double sum = 0;
  for (int k = 0; k < 200000; ++k) {
    x[0].a += 1e-9;
    sum += compute_kernel(A, x, p)[1].v[2];
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%.6f %.17g\n", s, sum);  // seconds, and the result (the same in every build)
}
