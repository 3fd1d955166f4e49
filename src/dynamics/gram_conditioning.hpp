#pragma once
// How well a least-squares problem's columns are told apart: the extreme
// eigenvalues of its Gram matrix once every column is scaled to unit norm (so
// that units drop out). Shared by the excitation design (excitation.hpp) and
// the payload refit (payload.hpp).

#include <Eigen/Eigenvalues>
#include <cmath>

namespace rcm::dynamics::detail {

// Smallest and largest eigenvalue of the Gram matrix with unit-norm columns;
// false when a column is zero (its index in `zero_column` when not null).
template <class Gram>
bool get_scaled_extreme_eigenvalues(const Gram& gram, double& lo, double& hi, Eigen::Index* zero_column = nullptr) {
  constexpr int K = Gram::RowsAtCompileTime;
  const Eigen::Matrix<double, K, 1> d = gram.diagonal();
  for (Eigen::Index k = 0; k < d.size(); ++k)
    if (!(d[k] > 0.0)) {
      if (zero_column) *zero_column = k;
      return false;
    }
  const Eigen::Matrix<double, K, 1> s = d.cwiseSqrt().cwiseInverse();
  const Gram n = s.asDiagonal() * gram * s.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Gram> solver(n, Eigen::EigenvaluesOnly);
  lo = solver.eigenvalues()(0);
  hi = solver.eigenvalues()(K - 1);
  return std::isfinite(lo) && std::isfinite(hi) && hi > 0.0;
}

// The column that weighs most in the weakest direction of the scaled Gram
// matrix (its eigenvector of the smallest eigenvalue); every column nonzero.
template <class Gram>
Eigen::Index get_weakest_column(const Gram& gram) {
  const auto s = gram.diagonal().cwiseSqrt().cwiseInverse().eval();
  const Gram n = s.asDiagonal() * gram * s.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Gram> solver(n);
  Eigen::Index worst = 0;
  solver.eigenvectors().col(0).cwiseAbs().maxCoeff(&worst);
  return worst;
}

}  // namespace rcm::dynamics::detail
