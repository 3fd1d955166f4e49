#pragma once
// Internal to the tissue layer: the least-squares pieces of one candidate
// structure (tissue_structure_fit.cpp) that the expression search
// (tissue_fit.cpp) fits every structure with.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "rcm/tissue/tissue_fit.hpp"

namespace rcm::tissue_detail {

constexpr int kNumFixedKinds = 6;  // x, square, cube, sin, cos, exp: columns without inner constants

// The data the candidates are fitted to, with the columns of the fixed kinds
// precomputed once.
struct FitData {
  Eigen::VectorXd x, y;
  Eigen::MatrixXd fixed;  // n x 6: x, x^2, x^3, sin x, cos x, exp x
  double y_scale = 1.0;

  void build(const Eigen::VectorXd& xs, const Eigen::VectorXd& ys) {
    x = xs;
    y = ys;
    const Eigen::Index n = x.size();
    fixed.resize(n, kNumFixedKinds);
    for (Eigen::Index i = 0; i < n; ++i) {
      const double v = x[i];
      fixed(i, 0) = v;
      fixed(i, 1) = v * v;
      fixed(i, 2) = v * v * v;
      fixed(i, 3) = std::sin(v);
      fixed(i, 4) = std::cos(v);
      fixed(i, 5) = std::exp(v);
    }
    y_scale = std::max(y.cwiseAbs().maxCoeff(), std::numeric_limits<double>::min());
  }
  Eigen::Index size() const { return x.size(); }
};

// A candidate's structure: intercept flag and term kinds in canonical order.
struct Structure {
  bool intercept = false;
  std::vector<TissueTermKind> kinds;
  int complexity = 0;
  int num_scaled = 0;
};

int num_columns(const Structure& s);

// Design matrix for the structure at inner constants `b` (one per scaled kind,

// Design matrix for the structure at inner constants `b` (one per scaled kind,
// in order). Column order: terms in canonical order, then the intercept.
void build_design(const FitData& data, const Structure& s, const double* b, Eigen::MatrixXd& Phi);

struct LinearSolution {
  Eigen::VectorXd coefficients;
  double mse = std::numeric_limits<double>::infinity();
  bool full_rank = true;
};

// Least squares with unit-norm column scaling (x^3 of a few centimetres is
// ~1e-5: unscaled, the pivoting threshold would misjudge the rank).
LinearSolution solve_linear(Eigen::MatrixXd& Phi, const Eigen::VectorXd& y);

struct RefineOutcome {
  bool usable = false;
  bool at_iteration_limit = false;
  int iterations = 0;
};

// All constants of a structure jointly by Ceres, from theta = [coefficients
// (terms, intercept), b...], which it overwrites.
RefineOutcome refine_with_ceres(const FitData& data, const Structure& s, std::vector<double>& theta,
                                int max_iterations, double function_tolerance);

// Grid values of one inner constant b for `kind`, u = b * x_scale.
std::vector<double> make_grid(TissueTermKind kind, int points, const TissueFitOptions& options, double x_scale);

}  // namespace rcm::tissue_detail
