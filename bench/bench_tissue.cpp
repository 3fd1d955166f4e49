// Tissue-law symbolic regression: the whole fit_tissue_law (enumeration,
// constant fitting, selection) on calibration-sized data. Target: 10^4 pairs
// in <= 1 s (docs/benchmarks.md).

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "rcm/tissue/tissue_fit.hpp"

namespace {

// The paper's calibration: D* = 30 mm, theta up to 45 degrees, a linear law
// y = 788 x with 5 % noise; `law` 1 is a saturating a*sin(b*x) instead.
rcm::TissuePairs make_pairs(int n, int law) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> ux(0.002, 0.030);
  rcm::TissuePairs pairs;
  pairs.source = "bench";
  pairs.x.resize(n);
  pairs.y.resize(n);
  for (int i = 0; i < n; ++i) {
    const double x = ux(rng);
    pairs.x[i] = x;
    pairs.y[i] = law == 0 ? 788.0 * x : 30.0 * std::sin(50.0 * x);
  }
  const double sigma = 0.05 * std::sqrt(pairs.y.squaredNorm() / n);
  std::normal_distribution<double> noise(0.0, sigma);
  for (int i = 0; i < n; ++i) pairs.y[i] += noise(rng);
  return pairs;
}

void BM_FitTissueLaw(benchmark::State& state) {
  const auto pairs = make_pairs(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  rcm::TissueFitResult fit;
  for (auto _ : state) {
    fit = rcm::fit_tissue_law(pairs);
    benchmark::DoNotOptimize(fit.best_index);
  }
  state.counters["candidates"] = static_cast<double>(fit.summary.num_candidates);
  state.counters["ceres_solves"] = static_cast<double>(fit.summary.num_ceres_solves);
  state.counters["it_full"] = static_cast<double>(fit.summary.num_ceres_iterations_full);
  state.counters["it_search"] = static_cast<double>(fit.summary.num_ceres_iterations_search);
  state.counters["not_conv"] = static_cast<double>(fit.summary.num_ceres_not_converged);
  state.counters["best_complexity"] = fit.best().complexity;
  state.SetLabel(rcm::format_expression(fit.best().expression, rcm::ExpressionFormat::sympy, 4));
}
BENCHMARK(BM_FitTissueLaw)
    ->ArgNames({"pairs", "law"})
    ->Args({1000, 0})
    ->Args({10000, 0})
    ->Args({10000, 1})
    ->Args({90000, 0})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
