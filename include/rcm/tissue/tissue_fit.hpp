#pragma once
// Symbolic regression of the tissue law g (paper III-C step 2, V-D), exact and
// deterministic: every candidate of the search space (expression.hpp) up to a
// maximum complexity is enumerated and fitted, then PySR's selection rules pick
// the Pareto front and the "best" law. Same input -> same output, bit for bit.

#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "rcm/tissue/expression.hpp"
#include "rcm/tissue/tissue_law.hpp"
#include "rcm/tissue/tissue_pairs.hpp"

namespace rcm {

struct TissueFitOptions {
  // Largest PySR complexity enumerated. 15 covers the full cubic
  // a*x^3 + b*x^2 + c*x + d and every scaled sin/cos/exp with an intercept (8).
  int max_complexity = 15;
  // Which library terms may appear (default: all nine kinds).
  std::vector<TissueTermKind> terms = {
      TissueTermKind::x,          TissueTermKind::square,     TissueTermKind::cube,
      TissueTermKind::sin,        TissueTermKind::cos,        TissueTermKind::exp,
      TissueTermKind::sin_scaled, TissueTermKind::cos_scaled, TissueTermKind::exp_scaled};
  bool allow_intercept = true;

  // Inner constants: a deterministic grid over u = b * max|x| (variable
  // projection: outer constants by least squares at each grid point), then the
  // `restarts` best grid minima are refined by Ceres (all constants jointly).
  int grid_points = 48;          // per inner constant when there is one
  int grid_points_2d = 14;       // per inner constant when there are two or more
  double grid_u_min = 0.05, grid_u_max = 20.0;
  int restarts = 3;
  // Grid and first refinement run on at most this many pairs (evenly spaced in
  // x order); the final polish and every reported loss use all pairs.
  std::size_t search_subsample = 1000;
  int max_iterations = 30;       // Ceres, per solve on the search subset
  // Ceres on all pairs, from the search optimum. Well-posed candidates converge
  // in a few iterations; degenerate ones (b -> 0 making sin(b x) linear) creep
  // along a valley for hundreds without changing the loss that matters.
  int polish_iterations = 10;
  // Only candidates whose loss after the search is within (1 + polish_margin)
  // of the best at their complexity are polished on all pairs.
  double polish_margin = 0.05;
  // Fitted candidates whose predictions differ by less than this fraction of the
  // best RMS residual everywhere on the data range are one law: only the first
  // in canonical order is kept (see docs/methods.md).
  double duplicate_tolerance = 0.01;

  // Selection (PySR): a front entry must beat every simpler one by more than
  // this relative margin, so float noise does not make ties "strictly lower".
  double tie_relative_tolerance = 1e-10;
  // "best": highest score among front entries with loss <= factor * min loss.
  // PySR's 1.5 guards a few noisy points. A calibration gives thousands of
  // pairs, where a law 20 % worse is another law: on the simulated bench a line
  // through stiffening tissue came within 1.28-1.48 of the cubic on 6 of 10
  // seeds, and the simplest right law within 1.11 on linear and sliding tissue.
  double best_loss_factor = 1.2;

  // Equal-count binning of the pairs before fitting (0 = off); see
  // compute_binned_pairs. With bins the loss is the MSE over the bins.
  std::size_t bins = 0;

  // Throws std::invalid_argument naming the first bad option.
  void check() const;
};
const OptionTable<TissueFitOptions>& get_option_table(OptionTag<TissueFitOptions>);

struct TissueFrontEntry {
  TissueExpression expression;
  int complexity = 0;
  double loss = 0.0;   // mean squared error over the (binned) pairs, N^2
  double score = 0.0;  // -d ln(loss) / d complexity; +inf after a zero loss
  double bic = 0.0;    // n ln(loss) + k ln(n), k = number of constants
};

// PySR's selection on the best loss of each complexity (any order, one entry per
// complexity): the front keeps, walking complexity upward, each entry whose loss
// is below (1 - tie_relative_tolerance) x the last kept loss; score_0 = 0 and
// score_i = -(ln loss_i - ln loss_{i-1}) / (c_i - c_{i-1}); best = argmax score
// among front entries with loss <= best_loss_factor x min loss (first on ties).
struct TissueSelection {
  std::vector<std::size_t> front;  // indices into the input, by complexity
  std::vector<double> scores;      // one per front entry
  std::size_t best = 0;            // index into `front`
};
TissueSelection compute_tissue_selection(const std::vector<int>& complexity,
                                         const std::vector<double>& loss,
                                         double tie_relative_tolerance,
                                         double best_loss_factor);

struct TissueFitSummary {
  std::size_t num_pairs = 0;         // pairs fitted (after binning)
  std::size_t num_candidates = 0;    // structures enumerated
  std::size_t num_duplicates = 0;    // fitted candidates equal to a simpler one (fingerprint)
  std::size_t num_failed = 0;        // candidates without a finite loss
  std::size_t num_ceres_solves = 0;
  std::size_t num_ceres_not_converged = 0;  // hit max_iterations (result still used)
  std::size_t num_ceres_iterations = 0;
  std::size_t num_ceres_iterations_full = 0, num_ceres_iterations_search = 0;
  double x_min = 0.0, x_max = 0.0;
  std::string brief_report() const;
};

struct TissueFitResult {
  std::vector<TissueFrontEntry> hall_of_fame;  // best per complexity, ascending
  std::vector<TissueFrontEntry> front;         // Pareto front, ascending complexity
  std::size_t best_index = 0;                  // into front
  std::optional<TissueLaw> law;                // the chosen g on [x_min, x_max]
  TissueFitSummary summary;

  const TissueFrontEntry& best() const { return front.at(best_index); }
};

// Validates the pairs (InputError) and the options (std::invalid_argument),
// enumerates, fits and selects.
TissueFitResult fit_tissue_law(const TissuePairs& pairs, const TissueFitOptions& options = {});

// Sensitivity of the chosen law to the assumed offset (paper V-D: D* +- 3 mm).
struct TissueSensitivityEntry {
  double offset_m = 0.0;
  TissueFrontEntry best;
  double leading_coefficient = 0.0;
  std::string skeleton;
};
struct TissueSensitivity {
  std::vector<TissueSensitivityEntry> entries;  // ascending offset, includes D*
  double leading_min = 0.0, leading_max = 0.0;
  bool same_family = true;  // every refit chose the same skeleton
};

// Refits at `steps` offsets evenly spaced over [D* - delta, D* + delta] (steps
// odd >= 3 includes D* itself). make_pairs(D) must return the pairs for offset D.
TissueSensitivity fit_tissue_sensitivity(const std::function<TissuePairs(double)>& make_pairs,
                                         double D_star, double delta, int steps,
                                         const TissueFitOptions& options = {});

}  // namespace rcm
