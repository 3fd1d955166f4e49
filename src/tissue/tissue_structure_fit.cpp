// The parameters of one candidate structure of the tissue law: its design
// matrix, the outer constants by least squares, and all constants jointly by
// Ceres (paper V-D; docs/methods.md).

#include <ceres/ceres.h>

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>

#include "tissue_fit_parts.hpp"

namespace rcm::tissue_detail {

namespace {

double basis_value(TissueTermKind kind, double b, double x) {
  switch (kind) {
    case TissueTermKind::sin_scaled: return std::sin(b * x);
    case TissueTermKind::cos_scaled: return std::cos(b * x);
    case TissueTermKind::exp_scaled: return std::exp(b * x);
    default: return 0.0;  // fixed kinds use the precomputed columns
  }
}

}  // namespace

int num_columns(const Structure& s) {
  return static_cast<int>(s.kinds.size()) + (s.intercept ? 1 : 0);
}

void build_design(const FitData& data, const Structure& s, const double* b, Eigen::MatrixXd& Phi) {
  const Eigen::Index n = data.size();
  Phi.resize(n, num_columns(s));
  int scaled = 0;
  for (std::size_t k = 0; k < s.kinds.size(); ++k) {
    const TissueTermKind kind = s.kinds[k];
    const auto col = static_cast<Eigen::Index>(k);
    if (has_inner_constant(kind)) {
      const double bk = b[scaled++];
      for (Eigen::Index i = 0; i < n; ++i) Phi(i, col) = basis_value(kind, bk, data.x[i]);
    } else {
      Phi.col(col) = data.fixed.col(static_cast<int>(kind));
    }
  }
  if (s.intercept) Phi.col(Phi.cols() - 1).setOnes();
}

LinearSolution solve_linear(Eigen::MatrixXd& Phi, const Eigen::VectorXd& y) {
  LinearSolution out;
  const Eigen::Index p = Phi.cols();
  Eigen::VectorXd norms(p);
  for (Eigen::Index j = 0; j < p; ++j) {
    const double nj = Phi.col(j).norm();
    if (!std::isfinite(nj) || nj == 0.0) {
      out.full_rank = false;
      return out;
    }
    norms[j] = nj;
    Phi.col(j) /= nj;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Phi);
  qr.setThreshold(1e-12);
  if (qr.rank() < p) out.full_rank = false;
  Eigen::VectorXd c = qr.solve(y);
  const Eigen::VectorXd r = Phi * c - y;
  out.mse = r.squaredNorm() / static_cast<double>(y.size());
  out.coefficients = c.cwiseQuotient(norms);
  if (!out.coefficients.allFinite() || !std::isfinite(out.mse)) {
    out.mse = std::numeric_limits<double>::infinity();
  }
  return out;
}

namespace {

// All constants of a structure jointly: [coefficients (terms, intercept), b...].
class StructureCost final : public ceres::DynamicCostFunction {
 public:
  StructureCost(const FitData& data, const Structure& s) : data_(data), s_(s) {
    SetNumResiduals(static_cast<int>(data.size()));
    AddParameterBlock(num_columns(s) + s.num_scaled);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* theta = parameters[0];
    const int p = num_columns(s_);
    const int np = p + s_.num_scaled;
    const Eigen::Index n = data_.size();
    double* J = jacobians != nullptr ? jacobians[0] : nullptr;
    for (Eigen::Index i = 0; i < n; ++i) {
      const double xi = data_.x[i];
      double value = 0.0;
      int scaled = 0;
      for (std::size_t k = 0; k < s_.kinds.size(); ++k) {
        const TissueTermKind kind = s_.kinds[k];
        const double a = theta[k];
        double phi;
        if (has_inner_constant(kind)) {
          // Value and d/db from one sin/cos/exp evaluation.
          const double b = theta[p + scaled];
          const double u = b * xi;
          double dphi_db;
          if (kind == TissueTermKind::exp_scaled) {
            phi = std::exp(u);
            dphi_db = xi * phi;
          } else {
            const double sn = std::sin(u), cs = std::cos(u);
            phi = kind == TissueTermKind::sin_scaled ? sn : cs;
            dphi_db = kind == TissueTermKind::sin_scaled ? xi * cs : -xi * sn;
          }
          if (J != nullptr) J[i * np + p + scaled] = a * dphi_db;
          ++scaled;
        } else {
          phi = data_.fixed(i, static_cast<int>(kind));
        }
        if (J != nullptr) J[i * np + static_cast<Eigen::Index>(k)] = phi;
        value += a * phi;
      }
      if (s_.intercept) {
        value += theta[p - 1];
        if (J != nullptr) J[i * np + p - 1] = 1.0;
      }
      const double r = value - data_.y[i];
      if (!std::isfinite(r)) return false;
      residuals[i] = r;
    }
    if (J != nullptr) {
      for (Eigen::Index k = 0; k < n * np; ++k) {
        if (!std::isfinite(J[k])) return false;
      }
    }
    return true;
  }

 private:
  const FitData& data_;
  const Structure& s_;
};

}  // namespace

RefineOutcome refine_with_ceres(const FitData& data, const Structure& s, std::vector<double>& theta,
                                int max_iterations, double function_tolerance) {
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  problem.AddResidualBlock(new StructureCost(data, s), nullptr, theta.data());
  ceres::Solver::Options options;
  // Normal equations: p <= 7 columns, Jacobi-scaled by Ceres; half the cost of QR.
  options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  options.max_num_iterations = max_iterations;
  options.function_tolerance = function_tolerance;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-10;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  RefineOutcome out;
  out.usable = summary.IsSolutionUsable();
  out.at_iteration_limit = summary.termination_type == ceres::NO_CONVERGENCE;
  out.iterations = static_cast<int>(summary.iterations.size());
  return out;
}

// Grid values of one inner constant b for `kind`, u = b * x_scale.
std::vector<double> make_grid(TissueTermKind kind, int points, const TissueFitOptions& options,
                              double x_scale) {
  std::vector<double> grid;
  auto logspace = [&](int count, double sign) {
    for (int i = 0; i < count; ++i) {
      const double t = count == 1 ? 0.5 : static_cast<double>(i) / (count - 1);
      const double u = options.grid_u_min * std::pow(options.grid_u_max / options.grid_u_min, t);
      grid.push_back(sign * u / x_scale);
    }
  };
  if (kind == TissueTermKind::exp_scaled) {
    // exp(b x) with b < 0 is a decaying/saturating law: both signs.
    const int half = std::max(1, points / 2);
    logspace(half, -1.0);
    std::reverse(grid.begin(), grid.end());  // ascending b
    logspace(half, 1.0);
  } else {
    logspace(points, 1.0);  // sin, cos: b > 0 without loss of generality
  }
  return grid;
}

}  // namespace rcm::tissue_detail
