#include "rcm/tissue/tissue_fit.hpp"

// The expression search of the tissue law (paper V-D, docs/methods.md): every
// structure over the library up to max_complexity, in canonical order, fitted
// (tissue_structure_fit.cpp), duplicates dropped, and the front selected
// (tissue_selection.cpp).

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "tissue_fit_parts.hpp"

namespace rcm {

namespace {

using namespace tissue_detail;

struct Candidate {
  Structure structure;
  TissueExpression expression;
  double loss = std::numeric_limits<double>::infinity();
  bool duplicate = false;
  std::vector<double> theta;  // [outer..., inner...] for candidates with inner constants
  bool needs_polish = false;  // fitted on the search subset, not yet on all pairs
};

TissueExpression make_expression(const Structure& s, const Eigen::VectorXd& coefficients,
                                 const std::vector<double>& b) {
  TissueExpression e;
  int scaled = 0;
  for (std::size_t k = 0; k < s.kinds.size(); ++k) {
    TissueTerm t;
    t.kind = s.kinds[k];
    t.coefficient = coefficients[static_cast<Eigen::Index>(k)];
    if (has_inner_constant(t.kind)) {
      t.scale = b[static_cast<std::size_t>(scaled++)];
      // Canonical signs: sin(-b x) = -sin(b x), cos(-b x) = cos(b x).
      if (t.scale < 0.0 && t.kind == TissueTermKind::sin_scaled) {
        t.scale = -t.scale;
        t.coefficient = -t.coefficient;
      } else if (t.scale < 0.0 && t.kind == TissueTermKind::cos_scaled) {
        t.scale = -t.scale;
      }
    }
    e.terms.push_back(t);
  }
  if (s.intercept) {
    e.has_intercept = true;
    e.intercept = coefficients[coefficients.size() - 1];
  }
  return e;
}

class Engine {
 public:
  Engine(const TissueFitOptions& options, const FitData& full, const FitData& search, double x_scale,
         TissueFitSummary& summary)
      : options_(options), full_(full), search_(search), x_scale_(x_scale), summary_(summary) {}

  // Fits one structure on all pairs. Marks it a duplicate when its columns are
  // rank deficient on the data (its span is a simpler structure's).
  void fit(Candidate& c) {
    const Structure& s = c.structure;
    if (s.num_scaled == 0) {
      build_design(full_, s, nullptr, Phi_);
      LinearSolution sol = solve_linear(Phi_, full_.y);
      if (!sol.full_rank) {
        // Its span equals that of a structure with fewer columns, enumerated
        // earlier at lower complexity: the same functions, nothing new.
        c.duplicate = true;
        return;
      }
      c.loss = sol.mse;
      if (std::isfinite(c.loss)) c.expression = make_expression(s, sol.coefficients, {});
      return;
    }
    fit_scaled(c);
  }

 private:
  // Variable projection on a grid of the inner constants, then Ceres.
  void fit_scaled(Candidate& c) {
    const Structure& s = c.structure;
    const int S = s.num_scaled;
    std::vector<std::vector<double>> grids;
    for (TissueTermKind kind : s.kinds) {
      if (has_inner_constant(kind)) {
        grids.push_back(make_grid(kind, S == 1 ? options_.grid_points : options_.grid_points_2d,
                                  options_, x_scale_));
      }
    }
    struct GridPoint {
      double mse;
      std::vector<double> b;
      Eigen::VectorXd coefficients;
      std::size_t flat;
    };
    std::vector<GridPoint> points;
    std::vector<std::size_t> index(static_cast<std::size_t>(S), 0);
    std::size_t flat = 0;
    while (true) {
      std::vector<double> b(static_cast<std::size_t>(S));
      for (std::size_t d = 0; d < static_cast<std::size_t>(S); ++d) b[d] = grids[d][index[d]];
      build_design(search_, s, b.data(), Phi_);
      LinearSolution sol = solve_linear(Phi_, search_.y);
      points.push_back({sol.full_rank ? sol.mse : std::numeric_limits<double>::infinity(), b,
                        sol.coefficients, flat++});
      int d = 0;
      for (; d < S; ++d) {
        auto& id = index[static_cast<std::size_t>(d)];
        if (++id < grids[static_cast<std::size_t>(d)].size()) break;
        id = 0;
      }
      if (d == S) break;
    }
    // Starts: for one inner constant the local minima of the grid profile
    // (distinct basins), otherwise the best grid points; best first, ties by
    // grid position so that the order is deterministic.
    std::vector<std::size_t> starts;
    std::vector<std::size_t> order(points.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return points[a].mse < points[b].mse; });
    if (S == 1) {
      for (std::size_t i : order) {
        if (!std::isfinite(points[i].mse)) break;
        const bool left_ok = i == 0 || points[i - 1].mse >= points[i].mse;
        const bool right_ok = i + 1 == points.size() || points[i + 1].mse >= points[i].mse;
        if (left_ok && right_ok) starts.push_back(i);
        if (static_cast<int>(starts.size()) == options_.restarts) break;
      }
    }
    for (std::size_t i : order) {
      if (static_cast<int>(starts.size()) >= options_.restarts) break;
      if (!std::isfinite(points[i].mse)) break;
      if (std::find(starts.begin(), starts.end(), i) == starts.end()) starts.push_back(i);
    }
    if (starts.empty()) return;  // no finite loss anywhere on the grid

    const int p = num_columns(s);
    const bool separate_search = search_.size() < full_.size();
    std::vector<double> best_theta;
    double best_mse = std::numeric_limits<double>::infinity();
    for (std::size_t start : starts) {
      std::vector<double> theta(static_cast<std::size_t>(p + S));
      for (int j = 0; j < p; ++j) theta[static_cast<std::size_t>(j)] = points[start].coefficients[j];
      for (int d = 0; d < S; ++d) {
        theta[static_cast<std::size_t>(p + d)] = points[start].b[static_cast<std::size_t>(d)];
      }
      const double mse = refine(search_, s, theta, points[start].mse, options_.max_iterations);
      if (mse < best_mse) {
        best_mse = mse;
        best_theta = theta;
      }
    }
    if (best_theta.empty()) return;
    // Outer constants by exact least squares on all pairs at the inner ones.
    std::vector<double> b(best_theta.begin() + p, best_theta.end());
    build_design(full_, s, b.data(), Phi_);
    LinearSolution sol = solve_linear(Phi_, full_.y);
    if (!std::isfinite(sol.mse)) return;
    for (int j = 0; j < p; ++j) best_theta[static_cast<std::size_t>(j)] = sol.coefficients[j];
    c.theta = std::move(best_theta);
    c.loss = sol.mse;
    c.expression = make_expression(s, sol.coefficients, b);
    c.needs_polish = separate_search;
  }

 public:
  // Ceres on all pairs from the search optimum; keeps the result if it lowers
  // the loss.
  void polish(Candidate& c) {
    if (!c.needs_polish) return;
    c.needs_polish = false;
    const Structure& s = c.structure;
    const int p = num_columns(s);
    std::vector<double> theta = c.theta;
    const double mse = refine(full_, s, theta, c.loss, options_.polish_iterations);
    if (!(mse < c.loss)) return;
    std::vector<double> b(theta.begin() + p, theta.end());
    Eigen::VectorXd coefficients(p);
    for (int j = 0; j < p; ++j) coefficients[j] = theta[static_cast<std::size_t>(j)];
    c.theta = std::move(theta);
    c.loss = mse;
    c.expression = make_expression(s, coefficients, b);
  }

 private:

  // Ceres from theta; keeps theta only if it improved on `start_mse`. Returns
  // the MSE at the returned theta.
  double refine(const FitData& data, const Structure& s, std::vector<double>& theta,
                double start_mse, int max_iterations) {
    std::vector<double> trial = theta;
    ++summary_.num_ceres_solves;
    // The search only has to find the basin; the polish on all pairs finishes.
    const bool search = &data != &full_;
    const RefineOutcome outcome =
        refine_with_ceres(data, s, trial, max_iterations, search ? 1e-8 : 1e-10);
    if (outcome.at_iteration_limit) ++summary_.num_ceres_not_converged;
    summary_.num_ceres_iterations += static_cast<std::size_t>(outcome.iterations);
    std::size_t& per_stage = &data == &full_ ? summary_.num_ceres_iterations_full
                                             : summary_.num_ceres_iterations_search;
    per_stage += static_cast<std::size_t>(outcome.iterations);
    if (!outcome.usable) return start_mse;
    const int p = num_columns(s);
    std::vector<double> b(trial.begin() + p, trial.end());
    build_design(data, s, b.data(), Phi_);
    LinearSolution sol = solve_linear(Phi_, data.y);
    if (!(sol.mse < start_mse)) return start_mse;
    for (int j = 0; j < p; ++j) trial[static_cast<std::size_t>(j)] = sol.coefficients[j];
    theta = trial;
    return sol.mse;
  }

  const TissueFitOptions& options_;
  const FitData& full_;
  const FitData& search_;
  double x_scale_;
  TissueFitSummary& summary_;
  Eigen::MatrixXd Phi_;
};

std::vector<Structure> enumerate_structures(const TissueFitOptions& options) {
  std::vector<TissueTermKind> kinds = options.terms;
  std::sort(kinds.begin(), kinds.end(),
            [](TissueTermKind a, TissueTermKind b) { return static_cast<int>(a) < static_cast<int>(b); });
  const int K = static_cast<int>(kinds.size());
  std::vector<Structure> out;
  for (unsigned mask = 0; mask < (1u << K); ++mask) {
    for (int intercept = 0; intercept < 2; ++intercept) {
      if (intercept && !options.allow_intercept) continue;
      Structure s;
      s.intercept = intercept != 0;
      TissueExpression e;
      e.has_intercept = s.intercept;
      for (int k = 0; k < K; ++k) {
        if (mask & (1u << k)) {
          s.kinds.push_back(kinds[static_cast<std::size_t>(k)]);
          TissueTerm t;
          t.kind = kinds[static_cast<std::size_t>(k)];
          e.terms.push_back(t);
          if (has_inner_constant(t.kind)) ++s.num_scaled;
        }
      }
      if (e.empty()) continue;
      s.complexity = e.complexity();
      if (s.complexity > options.max_complexity) continue;
      out.push_back(std::move(s));
    }
  }
  // Canonical enumeration order: complexity, then number of parts, then the
  // term kinds lexicographically, intercept-free first.
  std::stable_sort(out.begin(), out.end(), [](const Structure& a, const Structure& b) {
    if (a.complexity != b.complexity) return a.complexity < b.complexity;
    const int pa = num_columns(a), pb = num_columns(b);
    if (pa != pb) return pa < pb;
    if (a.kinds != b.kinds) return a.kinds < b.kinds;
    return !a.intercept && b.intercept;
  });
  return out;
}

// Predictions at fixed probe abscissae: equal fingerprints mean the same
// function on the data's range.
std::vector<double> fingerprint(const TissueExpression& e, const std::vector<double>& probes) {
  std::vector<double> out;
  out.reserve(probes.size());
  for (double x : probes) out.push_back(e.evaluate(x));
  return out;
}

}  // namespace

TissueFitResult fit_tissue_law(const TissuePairs& input, const TissueFitOptions& options) {
  options.check();
  validate_tissue_pairs(input);
  const TissuePairs pairs = options.bins > 0 ? compute_binned_pairs(input, options.bins) : input;
  if (options.bins > 0) validate_tissue_pairs(pairs);

  TissueFitResult result;
  TissueFitSummary& summary = result.summary;
  summary.num_pairs = pairs.size();
  summary.x_min = input.x.minCoeff();
  summary.x_max = input.x.maxCoeff();

  FitData full;
  full.build(pairs.x, pairs.y);
  // Search subset: evenly spaced in x order, so the grid sees the whole range.
  FitData search_storage;
  const FitData* search = &full;
  const std::size_t n = pairs.size();
  if (n > options.search_subsample) {
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return pairs.x[static_cast<Eigen::Index>(a)] < pairs.x[static_cast<Eigen::Index>(b)];
    });
    const std::size_t m = options.search_subsample;
    Eigen::VectorXd xs(static_cast<Eigen::Index>(m)), ys(static_cast<Eigen::Index>(m));
    for (std::size_t i = 0; i < m; ++i) {
      const std::size_t k = order[i * (n - 1) / (m - 1)];
      xs[static_cast<Eigen::Index>(i)] = pairs.x[static_cast<Eigen::Index>(k)];
      ys[static_cast<Eigen::Index>(i)] = pairs.y[static_cast<Eigen::Index>(k)];
    }
    search_storage.build(xs, ys);
    search = &search_storage;
  }
  const double x_scale = std::max(std::fabs(summary.x_min), std::fabs(summary.x_max));

  std::vector<Candidate> candidates;
  for (Structure& s : enumerate_structures(options)) {
    Candidate c;
    c.structure = std::move(s);
    candidates.push_back(std::move(c));
  }
  summary.num_candidates = candidates.size();

  Engine engine(options, full, *search, x_scale, summary);
  for (Candidate& c : candidates) engine.fit(c);
  // Polish on all pairs only the candidates that can still be the best of their
  // complexity: from the search optimum, a polish lowers the loss by O(p/m)
  // relative (m = search subset size), far below polish_margin.
  std::vector<double> best_loss(static_cast<std::size_t>(options.max_complexity) + 1,
                                std::numeric_limits<double>::infinity());
  for (const Candidate& c : candidates) {
    if (c.duplicate || !std::isfinite(c.loss)) continue;
    double& slot = best_loss[static_cast<std::size_t>(c.structure.complexity)];
    slot = std::min(slot, c.loss);
  }
  for (Candidate& c : candidates) {
    const double best_here = best_loss[static_cast<std::size_t>(c.structure.complexity)];
    if (c.needs_polish && c.loss <= best_here * (1.0 + options.polish_margin)) {
      engine.polish(c);
    }
  }
  // Fingerprint deduplication: two fitted candidates whose predictions differ
  // everywhere on the data range by less than duplicate_tolerance x the best
  // RMS residual are the same law as far as the data can tell (5.36e6*(x - sin x)
  // is 8.9e5*x^3 to 1e-5 on a few centimetres); only the first in canonical
  // order (lower complexity, polynomials before sin/cos/exp) is kept, so the
  // choice does not flip with the noise.
  double min_loss = std::numeric_limits<double>::infinity();
  for (const Candidate& c : candidates) {
    if (!c.duplicate && std::isfinite(c.loss)) min_loss = std::min(min_loss, c.loss);
  }
  const double fp_tol =
      std::max(1e-9 * full.y_scale,
               std::isfinite(min_loss) ? options.duplicate_tolerance * std::sqrt(min_loss) : 0.0);
  std::vector<double> probes;
  for (int i = 0; i < 32; ++i) {
    probes.push_back(summary.x_min + (summary.x_max - summary.x_min) * i / 31.0);
  }
  std::vector<std::vector<double>> seen;
  for (Candidate& c : candidates) {
    if (c.duplicate) {
      ++summary.num_duplicates;
      continue;
    }
    if (!std::isfinite(c.loss)) {
      ++summary.num_failed;
      continue;
    }
    std::vector<double> fp = fingerprint(c.expression, probes);
    bool same = false;
    for (const auto& other : seen) {
      bool equal = true;
      for (std::size_t k = 0; k < fp.size() && equal; ++k) {
        equal = std::fabs(fp[k] - other[k]) <= fp_tol;
      }
      if (equal) {
        same = true;
        break;
      }
    }
    if (same) {
      // Enumerated in complexity order: the earlier one is at most as complex.
      c.duplicate = true;
      ++summary.num_duplicates;
      continue;
    }
    seen.push_back(std::move(fp));
  }

  // Hall of fame: the lowest loss at each complexity (first enumerated on ties).
  std::vector<const Candidate*> best_at(static_cast<std::size_t>(options.max_complexity) + 1, nullptr);
  for (const Candidate& c : candidates) {
    if (c.duplicate || !std::isfinite(c.loss)) continue;
    const Candidate*& slot = best_at[static_cast<std::size_t>(c.structure.complexity)];
    if (slot == nullptr || c.loss < slot->loss) slot = &c;
  }
  const double log_n = std::log(static_cast<double>(n));
  for (const Candidate* c : best_at) {
    if (c == nullptr) continue;
    TissueFrontEntry entry;
    entry.expression = c->expression;
    entry.complexity = c->structure.complexity;
    entry.loss = c->loss;
    entry.bic = static_cast<double>(n) * std::log(c->loss) + c->expression.num_constants() * log_n;
    result.hall_of_fame.push_back(std::move(entry));
  }
  if (result.hall_of_fame.empty()) {
    throw InputError({input.source, 0, 0, ""},
                     "no candidate law has a finite loss on these pairs");
  }
  std::vector<int> complexity;
  std::vector<double> loss;
  for (const auto& e : result.hall_of_fame) {
    complexity.push_back(e.complexity);
    loss.push_back(e.loss);
  }
  const TissueSelection selection = compute_tissue_selection(
      complexity, loss, options.tie_relative_tolerance, options.best_loss_factor);
  for (std::size_t k = 0; k < selection.front.size(); ++k) {
    TissueFrontEntry entry = result.hall_of_fame[selection.front[k]];
    entry.score = selection.scores[k];
    result.front.push_back(std::move(entry));
  }
  result.best_index = selection.best;
  result.law.emplace(result.best().expression, summary.x_min, summary.x_max);
  return result;
}

}  // namespace rcm
