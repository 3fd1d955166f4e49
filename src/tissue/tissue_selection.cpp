// The tissue law's options, PySR's selection of the Pareto front and the best
// law (compute_tissue_selection), and the law's sensitivity to D*
// (fit_tissue_sensitivity, paper V-D).

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcm/common/options.hpp"
#include "rcm/tissue/tissue_fit.hpp"

namespace rcm {

void TissueFitOptions::check() const {
  auto fail = [](const std::string& what) {
    throw std::invalid_argument("TissueFitOptions: " + what);
  };
  if (max_complexity < 1) fail(fmt::format("max_complexity must be >= 1, got {}", max_complexity));
  if (max_complexity > 40) fail(fmt::format("max_complexity must be <= 40, got {}", max_complexity));
  for (std::size_t i = 0; i < terms.size(); ++i) {
    const int k = static_cast<int>(terms[i]);
    if (k < 0 || k >= kNumTissueTermKinds) fail("unknown term kind");
    for (std::size_t j = 0; j < i; ++j) {
      if (terms[j] == terms[i]) fail(std::string("term listed twice: ") + to_string(terms[i]));
    }
  }
  if (terms.empty() && !allow_intercept) fail("no terms and no intercept: nothing to fit");
  if (grid_points < 2 || grid_points_2d < 2) fail("grid_points must be >= 2");
  if (!(grid_u_min > 0.0 && grid_u_max > grid_u_min)) fail("need 0 < grid_u_min < grid_u_max");
  if (restarts < 1) fail("restarts must be >= 1");
  if (search_subsample < 8) fail("search_subsample must be >= 8");
  if (max_iterations < 1 || polish_iterations < 1) fail("iteration limits must be >= 1");
  if (!(polish_margin >= 0.0)) fail("polish_margin must be >= 0");
  if (!(duplicate_tolerance >= 0.0)) fail("duplicate_tolerance must be >= 0");
  if (!(tie_relative_tolerance >= 0.0 && tie_relative_tolerance < 1.0)) {
    fail("tie_relative_tolerance must be in [0, 1)");
  }
  if (!(best_loss_factor >= 1.0)) fail("best_loss_factor must be >= 1");
}

std::string TissueFitSummary::brief_report() const {
  return fmt::format(
      "tissue fit: {} pairs, x in [{:.6g}, {:.6g}] m; {} candidates ({} duplicates, {} without a "
      "finite loss); {} Ceres solves ({} at the iteration limit)",
      num_pairs, x_min, x_max, num_candidates, num_duplicates, num_failed, num_ceres_solves,
      num_ceres_not_converged);
}

// ---------------------------------------------------------------------------
// Selection

TissueSelection compute_tissue_selection(const std::vector<int>& complexity,
                                         const std::vector<double>& loss,
                                         double tie_relative_tolerance, double best_loss_factor) {
  if (complexity.size() != loss.size()) {
    throw std::invalid_argument("compute_tissue_selection: complexity and loss differ in size");
  }
  std::vector<std::size_t> order(complexity.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return complexity[a] < complexity[b]; });
  for (std::size_t k = 1; k < order.size(); ++k) {
    if (complexity[order[k]] == complexity[order[k - 1]]) {
      throw std::invalid_argument("compute_tissue_selection: one entry per complexity expected");
    }
  }
  TissueSelection selection;
  double last_loss = std::numeric_limits<double>::infinity();
  for (std::size_t i : order) {
    const double l = loss[i];
    if (!std::isfinite(l) || l < 0.0) continue;
    if (selection.front.empty() || l < last_loss * (1.0 - tie_relative_tolerance)) {
      selection.front.push_back(i);
      last_loss = l;
    }
  }
  if (selection.front.empty()) {
    throw std::invalid_argument("compute_tissue_selection: no entry with a finite loss");
  }
  selection.scores.assign(selection.front.size(), 0.0);
  double min_loss = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < selection.front.size(); ++k) {
    const std::size_t i = selection.front[k];
    min_loss = std::min(min_loss, loss[i]);
    if (k == 0) continue;
    const std::size_t prev = selection.front[k - 1];
    if (loss[i] > 0.0) {
      selection.scores[k] = -(std::log(loss[i]) - std::log(loss[prev])) /
                            static_cast<double>(complexity[i] - complexity[prev]);
    } else {
      selection.scores[k] = std::numeric_limits<double>::infinity();
    }
  }
  bool found = false;
  for (std::size_t k = 0; k < selection.front.size(); ++k) {
    if (loss[selection.front[k]] > best_loss_factor * min_loss) continue;
    if (!found || selection.scores[k] > selection.scores[selection.best]) {
      selection.best = k;
      found = true;
    }
  }
  return selection;
}

TissueSensitivity fit_tissue_sensitivity(const std::function<TissuePairs(double)>& make_pairs,
                                         double D_star, double delta, int steps,
                                         const TissueFitOptions& options) {
  if (!(std::isfinite(D_star) && std::isfinite(delta) && delta >= 0.0) || steps < 1) {
    throw std::invalid_argument("fit_tissue_sensitivity: need finite D*, delta >= 0, steps >= 1");
  }
  TissueSensitivity out;
  for (int i = 0; i < steps; ++i) {
    const double D = steps == 1 ? D_star : D_star - delta + 2.0 * delta * i / (steps - 1);
    const TissueFitResult fit = fit_tissue_law(make_pairs(D), options);
    TissueSensitivityEntry entry;
    entry.offset_m = D;
    entry.best = fit.best();
    entry.leading_coefficient = fit.best().expression.get_leading_coefficient();
    entry.skeleton = fit.best().expression.get_skeleton();
    out.entries.push_back(std::move(entry));
  }
  out.leading_min = out.leading_max = out.entries.front().leading_coefficient;
  for (const auto& e : out.entries) {
    out.leading_min = std::min(out.leading_min, e.leading_coefficient);
    out.leading_max = std::max(out.leading_max, e.leading_coefficient);
    if (e.skeleton != out.entries.front().skeleton) out.same_family = false;
  }
  return out;
}

const OptionTable<TissueFitOptions>& get_option_table(OptionTag<TissueFitOptions>) {
  static const auto table =
      OptionTable<TissueFitOptions>("TissueFitOptions")
          .add("max_complexity", &TissueFitOptions::max_complexity,
               "largest PySR complexity enumerated (15: cubic polynomials, scaled sin/cos/exp)", "",
               OptionLimits::within(1, 40))
          .add("terms", &TissueFitOptions::terms, "library terms that may appear in g")
          .add("allow_intercept", &TissueFitOptions::allow_intercept, "g may have a constant term")
          .add("grid_points", &TissueFitOptions::grid_points, "grid of an inner constant when there is one", "",
               OptionLimits::at_least(2))
          .add("grid_points_2d", &TissueFitOptions::grid_points_2d,
               "grid of each inner constant when there are two or more", "", OptionLimits::at_least(2))
          .add("grid_u_min", &TissueFitOptions::grid_u_min, "smallest inner constant times max|x|", "",
               OptionLimits::above(0))
          .add("grid_u_max", &TissueFitOptions::grid_u_max, "largest inner constant times max|x|", "",
               OptionLimits::above(0))
          .add("restarts", &TissueFitOptions::restarts, "best grid minima refined by Ceres", "",
               OptionLimits::at_least(1))
          .add("search_subsample", &TissueFitOptions::search_subsample,
               "pairs the grid and the first refinement run on, at most", "", OptionLimits::at_least(8))
          .add("max_iterations", &TissueFitOptions::max_iterations, "Ceres iterations per solve on the search subset",
               "", OptionLimits::at_least(1))
          .add("polish_iterations", &TissueFitOptions::polish_iterations, "Ceres iterations of the polish on all pairs",
               "", OptionLimits::at_least(1))
          .add("polish_margin", &TissueFitOptions::polish_margin,
               "candidates within (1 + margin) of their complexity's best loss are polished", "",
               OptionLimits::at_least(0))
          .add("duplicate_tolerance", &TissueFitOptions::duplicate_tolerance,
               "candidates closer than this fraction of the best RMS residual are one law", "",
               OptionLimits::at_least(0))
          .add("tie_relative_tolerance", &TissueFitOptions::tie_relative_tolerance,
               "a front entry beats every simpler one by more than this relative margin", "",
               OptionLimits::from_below(0, 1))
          .add("best_loss_factor", &TissueFitOptions::best_loss_factor,
               "best: highest score among front entries with loss <= factor x the least loss (PySR's 1.5 suits a "
               "few noisy points, e.g. bins)", "",
               OptionLimits::at_least(1))
          .add("bins", &TissueFitOptions::bins, "equal-count bins along x before fitting (0: none)")
          .add_check([](const TissueFitOptions& o) { o.check(); });
  return table;
}

}  // namespace rcm
