// Tissue-law symbolic regression: expression semantics (PySR complexity,
// exports, derivatives), PySR selection against a hand-computed front, family
// recovery from noisy synthetic laws, determinism, g^-1, JSON round trip.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "rcm/tissue/expression.hpp"
#include "rcm/tissue/tissue_fit.hpp"
#include "rcm/tissue/tissue_law.hpp"
#include "rcm/tissue/tissue_pairs.hpp"
#include "temp_dir.hpp"
#include "statistical_test.hpp"

namespace {

using rcm::ExpressionFormat;
using rcm::TissueExpression;
using rcm::TissueTerm;
using rcm::TissueTermKind;

TissueTerm term(TissueTermKind kind, double a, double b = 1.0) {
  TissueTerm t;
  t.kind = kind;
  t.coefficient = a;
  t.scale = b;
  return t;
}

TissueExpression expr(std::vector<TissueTerm> terms, bool intercept = false, double c = 0.0) {
  TissueExpression e;
  e.terms = std::move(terms);
  e.has_intercept = intercept;
  e.intercept = c;
  return e;
}

// ---------------------------------------------------------------------------
// Expression semantics

TEST(TissueExpression, ComplexityCountsNodesAsPySR) {
  // 788.0*x: *, 788.0, x.
  EXPECT_EQ(expr({term(TissueTermKind::x, 788.0)}).complexity(), 3);
  // A bare constant.
  EXPECT_EQ(expr({}, true, 2.0).complexity(), 1);
  // a*x + c: +, *, a, x, c.
  EXPECT_EQ(expr({term(TissueTermKind::x, 1.0)}, true, 1.0).complexity(), 5);
  // a*square(x): *, a, square, x.
  EXPECT_EQ(expr({term(TissueTermKind::square, 1.0)}).complexity(), 4);
  // a*sin(b*x): *, a, sin, *, b, x.
  EXPECT_EQ(expr({term(TissueTermKind::sin_scaled, 1.0, 2.0)}).complexity(), 6);
  // a*exp(b*x) + c.
  EXPECT_EQ(expr({term(TissueTermKind::exp_scaled, 1.0, 2.0)}, true, 1.0).complexity(), 8);
  // a*x + b*x^3.
  EXPECT_EQ(expr({term(TissueTermKind::x, 1.0), term(TissueTermKind::cube, 1.0)}).complexity(), 8);
  // Full cubic a*x + b*x^2 + c*x^3 + d.
  EXPECT_EQ(expr({term(TissueTermKind::x, 1.0), term(TissueTermKind::square, 1.0),
                  term(TissueTermKind::cube, 1.0)},
                 true, 1.0)
                .complexity(),
            15);
  // Default maximum covers both.
  EXPECT_GE(rcm::TissueFitOptions{}.max_complexity, 15);
}

TEST(TissueExpression, ConstantsCountForBic) {
  EXPECT_EQ(expr({term(TissueTermKind::x, 1.0)}).num_constants(), 1);
  EXPECT_EQ(expr({term(TissueTermKind::exp_scaled, 1.0, 2.0)}, true, 1.0).num_constants(), 3);
}

TEST(TissueExpression, ExportsSympyPlainAndLatex) {
  const auto linear = expr({term(TissueTermKind::x, 788.0)});
  EXPECT_EQ(rcm::format_expression(linear, ExpressionFormat::sympy), "788.0*x");
  const auto e = expr({term(TissueTermKind::x, 400.0), term(TissueTermKind::cube, 1.5e7),
                       term(TissueTermKind::exp_scaled, -2.5, -80.0)},
                      true, -0.25);
  EXPECT_EQ(rcm::format_expression(e, ExpressionFormat::sympy),
            "400.0*x + 15000000.0*x**3 - 2.5*exp(-80.0*x) - 0.25");
  EXPECT_EQ(rcm::format_expression(e, ExpressionFormat::plain),
            "400.0*x + 15000000.0*x^3 - 2.5*exp(-80.0*x) - 0.25");
  EXPECT_EQ(rcm::format_expression(e, ExpressionFormat::latex),
            "400.0 x + 15000000.0 x^{3} - 2.5 e^{-80.0 x} - 0.25");
  const auto s = expr({term(TissueTermKind::sin_scaled, 30.0, 50.0)});
  EXPECT_EQ(rcm::format_expression(s, ExpressionFormat::sympy), "30.0*sin(50.0*x)");
  EXPECT_EQ(rcm::format_expression(s, ExpressionFormat::latex), "30.0 \\sin\\left(50.0 x\\right)");
  // Rounded display and exponent notation in LaTeX.
  const auto tiny = expr({term(TissueTermKind::cube, 1.23456789e-7)});
  EXPECT_EQ(rcm::format_expression(tiny, ExpressionFormat::sympy, 3), "1.23e-07*x**3");
  EXPECT_EQ(rcm::format_expression(tiny, ExpressionFormat::latex, 3), "1.23 \\cdot 10^{-7} x^{3}");
  // Exact export: every constant reads back to the same double.
  const auto odd = expr({term(TissueTermKind::x, 0.1 + 0.2)});
  EXPECT_EQ(rcm::format_expression(odd, ExpressionFormat::sympy), "0.30000000000000004*x");
}

TEST(TissueExpression, SkeletonNamesTheFamily) {
  EXPECT_EQ(expr({term(TissueTermKind::exp_scaled, 2.0, 80.0)}, true, -2.0).get_skeleton(),
            "C*exp(C*x) + C");
  EXPECT_EQ(expr({term(TissueTermKind::x, 1.0), term(TissueTermKind::cube, 1.0)}).get_skeleton(),
            "C*x + C*x^3");
}

// Every derivative against central differences, tolerance from the step:
// truncation ~ h^2 |g'''| / 6 and rounding ~ eps |g| / h.
TEST(TissueExpression, DerivativeMatchesFiniteDifferences) {
  for (int k = 0; k < rcm::kNumTissueTermKinds; ++k) {
    const auto kind = static_cast<TissueTermKind>(k);
    const auto e = expr({term(kind, 3.7, -23.0)}, true, 0.4);
    for (double x : {-0.03, -0.004, 0.0, 0.011, 0.029}) {
      const double h = 1e-6;
      const double fd = (e.evaluate(x + h) - e.evaluate(x - h)) / (2 * h);
      const double scale = std::fabs(e.evaluate(x)) + 1.0;
      const double tol = 1e-16 * scale / h + h * h * 3.7 * std::pow(23.0, 3) + 1e-9;
      EXPECT_NEAR(e.derivative(x), fd, tol) << rcm::to_string(kind) << " at x = " << x;
    }
  }
}

// ---------------------------------------------------------------------------
// PySR selection, by hand

TEST(TissueSelection, ReproducesHandComputedFront) {
  // Best loss per complexity (unordered on purpose).
  const std::vector<int> complexity = {5, 1, 3, 8, 10, 6, 12};
  const std::vector<double> loss = {9.0, 100.0, 10.0, 1.0, 0.9, 9.5, 0.95};
  // Front by complexity: 1 (100), 3 (10), 5 (9), 8 (1), 10 (0.9). 6 (9.5) and
  // 12 (0.95) are not lower than a simpler entry.
  // Scores: 0; ln(100/10)/2 = 1.1513; ln(10/9)/2 = 0.0527; ln(9/1)/3 = 0.7324;
  // ln(1/0.9)/2 = 0.0527. min loss 0.9, 1.5 x = 1.35: candidates 8 and 10 ->
  // best is complexity 8 (score 0.7324), not 3 (higher score but loss 10).
  const rcm::TissueSelection s = rcm::compute_tissue_selection(complexity, loss, 1e-10, 1.5);
  ASSERT_EQ(s.front.size(), 5u);
  const std::vector<int> expected_c = {1, 3, 5, 8, 10};
  for (std::size_t k = 0; k < 5; ++k) EXPECT_EQ(complexity[s.front[k]], expected_c[k]);
  EXPECT_DOUBLE_EQ(s.scores[0], 0.0);
  EXPECT_NEAR(s.scores[1], std::log(10.0) / 2.0, 1e-15);
  EXPECT_NEAR(s.scores[2], std::log(10.0 / 9.0) / 2.0, 1e-15);
  EXPECT_NEAR(s.scores[3], std::log(9.0) / 3.0, 1e-15);
  EXPECT_NEAR(s.scores[4], std::log(1.0 / 0.9) / 2.0, 1e-15);
  EXPECT_EQ(complexity[s.front[s.best]], 8);

  // With a looser factor the globally highest score wins.
  const rcm::TissueSelection loose = rcm::compute_tissue_selection(complexity, loss, 1e-10, 20.0);
  EXPECT_EQ(complexity[loose.front[loose.best]], 3);
}

TEST(TissueSelection, FloatTiesAreNotImprovements) {
  const std::vector<int> complexity = {3, 5, 8};
  const std::vector<double> loss = {2.0, 2.0 * (1 - 1e-14), 1.0};
  const auto s = rcm::compute_tissue_selection(complexity, loss, 1e-10, 1.5);
  ASSERT_EQ(s.front.size(), 2u);
  EXPECT_EQ(complexity[s.front[1]], 8);
  EXPECT_NEAR(s.scores[1], std::log(2.0) / 5.0, 1e-15);
}

TEST(TissueSelection, ZeroLossScoresInfinity) {
  const auto s = rcm::compute_tissue_selection({1, 3}, {4.0, 0.0}, 1e-10, 1.5);
  EXPECT_TRUE(std::isinf(s.scores[1]));
  EXPECT_EQ(s.best, 1u);
}

TEST(TissueSelection, EqualScoresPickTheSimplest) {
  // Both steps halve the loss per unit complexity: PySR's idxmax takes the first.
  const auto s = rcm::compute_tissue_selection({1, 2, 3}, {4.0, 2.0, 1.0}, 1e-10, 10.0);
  EXPECT_EQ(s.best, 1u);
}

// ---------------------------------------------------------------------------
// Engine

struct Law {
  const char* name;
  std::function<double(double)> g;
  const char* skeleton;
};

// Physically scaled like the paper's calibration: D* = 30 mm, theta up to 45
// degrees, so x = D* tan(theta) in [2, 30] mm and forces of tens of newtons.
std::vector<Law> synthetic_laws() {
  return {
      {"linear", [](double x) { return 788.0 * x; }, "C*x"},
      // Cubic part 4x the linear one at 30 mm: weaker stiffening is, at 5 % noise,
      // legitimately explained by the simpler a*x^2 + c under PySR's rule.
      {"cubic stiffening", [](double x) { return 200.0 * x + 8.9e5 * x * x * x; }, "C*x + C*x^3"},
      {"a sin(b x)", [](double x) { return 30.0 * std::sin(50.0 * x); }, "C*sin(C*x)"},
      {"a (exp(b x) - 1)", [](double x) { return 2.0 * (std::exp(80.0 * x) - 1.0); },
       "C*exp(C*x) + C"},
  };
}

// 5 % noise: Gaussian with standard deviation 0.05 x rms(g) over the sample.
rcm::TissuePairs make_pairs(const Law& law, unsigned seed, int n = 500) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(0.002, 0.030);
  rcm::TissuePairs pairs;
  pairs.source = law.name;
  pairs.x.resize(n);
  pairs.y.resize(n);
  double ms = 0.0;
  for (int i = 0; i < n; ++i) {
    pairs.x[i] = ux(rng);
    pairs.y[i] = law.g(pairs.x[i]);
    ms += pairs.y[i] * pairs.y[i];
  }
  const double sigma = 0.05 * std::sqrt(ms / n);
  std::normal_distribution<double> noise(0.0, sigma);
  for (int i = 0; i < n; ++i) pairs.y[i] += noise(rng);
  return pairs;
}

TEST(TissueFit, ExactLinearDataGivesThePaperLaw) {
  rcm::TissuePairs pairs;
  pairs.source = "exact";
  pairs.x = Eigen::VectorXd::LinSpaced(200, 0.001, 0.03);
  pairs.y = 788.0 * pairs.x;
  const auto fit = rcm::fit_tissue_law(pairs);
  EXPECT_EQ(fit.best().complexity, 3);
  EXPECT_EQ(fit.best().expression.get_skeleton(), "C*x");
  EXPECT_NEAR(fit.best().expression.get_leading_coefficient(), 788.0, 1e-9);
  EXPECT_LT(fit.best().loss, 1e-20);
  ASSERT_TRUE(fit.law.has_value());
  EXPECT_DOUBLE_EQ(fit.law->x_min(), 0.001);
  EXPECT_DOUBLE_EQ(fit.law->x_max(), 0.03);
}

TEST(TissueFit, FrontFollowsPySRRulesOnRealFits) {
  const auto laws = synthetic_laws();
  const auto fit = rcm::fit_tissue_law(make_pairs(laws[1], 7));
  // Front strictly decreasing in loss, increasing in complexity, scores as defined.
  ASSERT_GE(fit.front.size(), 2u);
  EXPECT_EQ(fit.front[0].score, 0.0);
  for (std::size_t k = 1; k < fit.front.size(); ++k) {
    EXPECT_GT(fit.front[k].complexity, fit.front[k - 1].complexity);
    EXPECT_LT(fit.front[k].loss, fit.front[k - 1].loss);
    EXPECT_NEAR(fit.front[k].score,
                -std::log(fit.front[k].loss / fit.front[k - 1].loss) /
                    (fit.front[k].complexity - fit.front[k - 1].complexity),
                1e-12);
  }
  // Every hall-of-fame entry not on the front is dominated by a simpler front entry.
  for (const auto& h : fit.hall_of_fame) {
    bool on_front = false, dominated = false;
    for (const auto& f : fit.front) {
      if (f.complexity == h.complexity) on_front = true;
      if (f.complexity < h.complexity && f.loss <= h.loss) dominated = true;
    }
    EXPECT_TRUE(on_front || dominated) << h.complexity;
    // Reported loss is the MSE of the reported expression.
  }
  // Best: loss within best_loss_factor x min and highest score among those.
  const double factor = rcm::TissueFitOptions{}.best_loss_factor;
  double min_loss = fit.front.back().loss;
  for (const auto& f : fit.front) min_loss = std::min(min_loss, f.loss);
  for (const auto& f : fit.front) {
    if (f.loss <= factor * min_loss) EXPECT_LE(f.score, fit.best().score);
  }
  EXPECT_LE(fit.best().loss, factor * min_loss);
  // BIC = n ln(loss) + k ln(n).
  const double n = 500.0;
  EXPECT_NEAR(fit.best().bic,
              n * std::log(fit.best().loss) + fit.best().expression.num_constants() * std::log(n),
              1e-9);
}

TEST(TissueFit, ReportedLossIsTheMeanSquaredErrorOfTheExpression) {
  const auto laws = synthetic_laws();
  const auto pairs = make_pairs(laws[3], 3);
  const auto fit = rcm::fit_tissue_law(pairs);
  for (const auto& entry : fit.hall_of_fame) {
    double mse = 0.0;
    for (Eigen::Index i = 0; i < pairs.x.size(); ++i) {
      const double r = entry.expression.evaluate(pairs.x[i]) - pairs.y[i];
      mse += r * r;
    }
    mse /= static_cast<double>(pairs.size());
    EXPECT_NEAR(entry.loss, mse, 1e-9 * mse) << entry.complexity;
    EXPECT_EQ(entry.expression.complexity(), entry.complexity);
  }
}

TEST(TissueFit, RecoversTheTrueFamilyIn95PercentOf40Seeds) {
  RCM_STATISTICAL_TEST();
  for (const Law& law : synthetic_laws()) {
    int hits = 0;
    std::string misses;
    for (unsigned seed = 1; seed <= 40; ++seed) {
      const auto fit = rcm::fit_tissue_law(make_pairs(law, 1000 + seed));
      const std::string got = fit.best().expression.get_skeleton();
      if (got == law.skeleton) {
        ++hits;
      } else {
        misses += " seed " + std::to_string(seed) + ": " +
                  rcm::format_expression(fit.best().expression, ExpressionFormat::sympy, 4) + ";";
      }
    }
    std::printf("[ family ] %-18s %d / 40\n", law.name, hits);
    EXPECT_GE(hits, 38) << law.name << " missed:" << misses;
  }
}

// A calibration's thousands of pairs through stiffening tissue (the bench's
// 12 N at 20 mm, 35 N at 40 mm, swept to 24 mm) with 0.6 N of noise: a line
// with an offset explains them within 1.5 of the cubic's loss, not within 1.2.
TEST(TissueFit, ThousandsOfPairsOfStiffeningTissueAreNotTakenForALine) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> ux(0.001, 0.024);
  std::normal_distribution<double> noise(0.0, 0.6);
  rcm::TissuePairs pairs;
  pairs.source = "stiffening";
  pairs.x.resize(3000);
  pairs.y.resize(3000);
  for (int i = 0; i < 3000; ++i) {
    pairs.x[i] = ux(rng);
    pairs.y[i] = 508.33 * pairs.x[i] + 2.2917e5 * std::pow(pairs.x[i], 3) + noise(rng);
  }
  const auto fit = rcm::fit_tissue_law(pairs);
  const std::string got = fit.best().expression.get_skeleton();
  EXPECT_NE(got, "C*x");
  EXPECT_NE(got, "C*x + C");
  EXPECT_GT(fit.best().expression.evaluate(0.04) / 35.0, 0.9) << got;  // extrapolated to 40 mm
}

// The front of a simulated calibration through stiffening tissue (seed 1 of the
// bench, 11947 pairs): PySR's 1.5 took the line with an offset (complexity 5);
// the default keeps the cubic (8, 517 x + 2.08e5 x^3).
TEST(TissueSelection, TheDefaultFactorKeepsTheCubicOfABenchCalibration) {
  const std::vector<int> complexity = {1, 3, 5, 6, 8, 10, 11, 12, 13, 15};
  const std::vector<double> loss = {9.4561, 0.37501, 0.27337, 0.26911, 0.21389,
                                    0.21384, 0.21378, 0.21363, 0.21308, 0.21298};
  const rcm::TissueFitOptions defaults;
  const auto s = rcm::compute_tissue_selection(complexity, loss, defaults.tie_relative_tolerance,
                                               defaults.best_loss_factor);
  EXPECT_EQ(complexity[s.front[s.best]], 8);
  const auto pysr = rcm::compute_tissue_selection(complexity, loss, defaults.tie_relative_tolerance, 1.5);
  EXPECT_EQ(complexity[pysr.front[pysr.best]], 5);
}

TEST(TissueFit, RecoversConstantsOfTheTrueLaw) {
  const auto laws = synthetic_laws();
  const auto sin_fit = rcm::fit_tissue_law(make_pairs(laws[2], 11, 2000));
  ASSERT_EQ(sin_fit.best().expression.get_skeleton(), "C*sin(C*x)");
  EXPECT_NEAR(sin_fit.best().expression.terms[0].coefficient, 30.0, 1.5);
  EXPECT_NEAR(sin_fit.best().expression.terms[0].scale, 50.0, 2.5);
  const auto exp_fit = rcm::fit_tissue_law(make_pairs(laws[3], 11, 2000));
  ASSERT_EQ(exp_fit.best().expression.get_skeleton(), "C*exp(C*x) + C");
  EXPECT_NEAR(exp_fit.best().expression.terms[0].scale, 80.0, 4.0);
  EXPECT_NEAR(exp_fit.best().expression.terms[0].coefficient, 2.0, 0.3);
  EXPECT_NEAR(exp_fit.best().expression.intercept, -2.0, 0.3);
}

TEST(TissueFit, IsDeterministic) {
  const auto laws = synthetic_laws();
  const auto pairs = make_pairs(laws[2], 5, 3000);  // above search_subsample: both stages
  const auto a = rcm::fit_tissue_law(pairs);
  const auto b = rcm::fit_tissue_law(pairs);
  ASSERT_EQ(a.hall_of_fame.size(), b.hall_of_fame.size());
  for (std::size_t k = 0; k < a.hall_of_fame.size(); ++k) {
    EXPECT_EQ(a.hall_of_fame[k].loss, b.hall_of_fame[k].loss);  // bit for bit
    EXPECT_EQ(rcm::format_expression(a.hall_of_fame[k].expression, ExpressionFormat::sympy),
              rcm::format_expression(b.hall_of_fame[k].expression, ExpressionFormat::sympy));
  }
  EXPECT_EQ(a.best_index, b.best_index);
}

TEST(TissueFit, MaxComplexityAndLibraryAreHonoured) {
  const auto laws = synthetic_laws();
  const auto pairs = make_pairs(laws[3], 9);
  rcm::TissueFitOptions options;
  options.max_complexity = 6;
  options.terms = {TissueTermKind::x, TissueTermKind::square};
  const auto fit = rcm::fit_tissue_law(pairs, options);
  for (const auto& h : fit.hall_of_fame) {
    EXPECT_LE(h.complexity, 6);
    for (const auto& t : h.expression.terms) {
      EXPECT_TRUE(t.kind == TissueTermKind::x || t.kind == TissueTermKind::square);
    }
  }
}

TEST(TissueFit, BinningFitsBinMeans) {
  const auto laws = synthetic_laws();
  const auto pairs = make_pairs(laws[0], 2, 1000);
  rcm::TissueFitOptions options;
  options.bins = 50;
  options.best_loss_factor = 1.5;  // a few noisy bin means: PySR's factor
  const auto fit = rcm::fit_tissue_law(pairs, options);
  EXPECT_EQ(fit.summary.num_pairs, 50u);
  EXPECT_EQ(fit.best().expression.get_skeleton(), "C*x");
  EXPECT_NEAR(fit.best().expression.get_leading_coefficient(), 788.0, 15.0);
}

TEST(TissueFit, RejectsBadInputAndOptions) {
  rcm::TissuePairs pairs;
  pairs.source = "p.csv";
  pairs.x = Eigen::VectorXd::LinSpaced(10, 0.0, 0.01);
  pairs.y = pairs.x;
  pairs.origin = {2, 3, 4, 5, 6, 7, 8, 9, 10, 11};
  pairs.y[4] = std::numeric_limits<double>::quiet_NaN();
  try {
    rcm::fit_tissue_law(pairs);
    FAIL() << "NaN accepted";
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().line, 6u);
    EXPECT_EQ(e.where().field, "y");
  }
  pairs.y = pairs.x;
  pairs.x.setConstant(0.01);
  EXPECT_THROW(rcm::fit_tissue_law(pairs), rcm::InputError);
  pairs.x = Eigen::VectorXd::LinSpaced(10, 0.0, 0.01);
  rcm::TissueFitOptions options;
  options.max_complexity = 0;
  EXPECT_THROW(rcm::fit_tissue_law(pairs, options), std::invalid_argument);
  options = {};
  options.terms = {TissueTermKind::x, TissueTermKind::x};
  EXPECT_THROW(rcm::fit_tissue_law(pairs, options), std::invalid_argument);
}

TEST(TissueSensitivity, ReportsTheLeadingCoefficientRange) {
  // Linear law in x = D tan(theta): with the same forces, assuming D* -+ delta
  // rescales x, so the multiplier goes as D* / D.
  rcm::TissuePairs base;
  base.source = "linear";
  base.x = Eigen::VectorXd::LinSpaced(100, 0.002, 0.03);
  base.y = 788.0 * base.x;
  const double D = 0.030, delta = 0.003;
  const auto sens = rcm::fit_tissue_sensitivity(
      [&](double d) { return rcm::compute_rescaled_pairs(base, D, d); }, D, delta, 3);
  ASSERT_EQ(sens.entries.size(), 3u);
  EXPECT_TRUE(sens.same_family);
  EXPECT_DOUBLE_EQ(sens.entries[1].offset_m, D);
  EXPECT_NEAR(sens.leading_min, 788.0 * D / (D + delta), 1e-6);
  EXPECT_NEAR(sens.leading_max, 788.0 * D / (D - delta), 1e-6);
}

// ---------------------------------------------------------------------------
// g^-1

TEST(TissueLaw, InverseOfLinearAndNonlinearLaws) {
  const rcm::TissueLaw linear(expr({term(TissueTermKind::x, 788.0)}), 0.0, 0.03);
  EXPECT_EQ(linear.monotonicity(), rcm::Monotonicity::increasing);
  EXPECT_NEAR(linear.inverse(788.0 * 0.0123), 0.0123, 1e-15);

  const rcm::TissueLaw stiff(
      expr({term(TissueTermKind::exp_scaled, 2.0, 80.0)}, true, -2.0), 0.002, 0.03);
  for (double x : {0.002, 0.0031, 0.017, 0.0299, 0.03}) {
    const auto r = stiff.compute_inverse(stiff.evaluate(x));
    ASSERT_EQ(r.status, rcm::TissueInverseStatus::ok) << r.message;
    EXPECT_NEAR(r.x, x, 1e-14);
    EXPECT_LT(r.iterations, 20);
  }
  // Decreasing laws invert too.
  const rcm::TissueLaw down(expr({term(TissueTermKind::x, -5.0)}, true, 1.0), -1.0, 1.0);
  EXPECT_EQ(down.monotonicity(), rcm::Monotonicity::decreasing);
  EXPECT_NEAR(down.inverse(3.0), -0.4, 1e-14);
}

TEST(TissueLaw, InverseFailsClearlyWhenNotMonotoneOrOutOfRange) {
  // 30 sin(150 x) turns over at x = pi/300 ~ 0.0105 inside [0, 0.03].
  const rcm::TissueLaw wave(expr({term(TissueTermKind::sin_scaled, 30.0, 150.0)}), 0.0, 0.03);
  EXPECT_EQ(wave.monotonicity(), rcm::Monotonicity::not_monotone);
  const auto r = wave.compute_inverse(10.0);
  EXPECT_EQ(r.status, rcm::TissueInverseStatus::not_monotone);
  EXPECT_TRUE(std::isnan(r.x));
  try {
    (void)wave.inverse(10.0);
    FAIL();
  } catch (const std::domain_error& e) {
    EXPECT_NE(std::string(e.what()).find("not monotone"), std::string::npos) << e.what();
  }
  const rcm::TissueLaw linear(expr({term(TissueTermKind::x, 788.0)}), 0.002, 0.03);
  EXPECT_EQ(linear.compute_inverse(100.0).status, rcm::TissueInverseStatus::out_of_range);
  EXPECT_EQ(linear.compute_inverse(0.0).status, rcm::TissueInverseStatus::out_of_range);
  EXPECT_THROW((void)linear.inverse(100.0), std::domain_error);
  // A constant law has no inverse.
  const rcm::TissueLaw flat(expr({}, true, 3.0), 0.0, 0.03);
  EXPECT_EQ(flat.monotonicity(), rcm::Monotonicity::not_monotone);
}

TEST(TissueLaw, JsonRoundTripIsExact) {
  const rcm::TissueLaw law(expr({term(TissueTermKind::x, 0.1 + 0.2),
                                 term(TissueTermKind::exp_scaled, 1.0 / 3.0, 77.7)},
                                true, -1e-7),
                           0.002, 0.031);
  const auto path = rcm::test::get_process_temp_dir() / "rcm_test_tissue_law.json";
  rcm::save_tissue_law(path, law);
  const rcm::TissueLaw back = rcm::load_tissue_law(path);
  std::filesystem::remove(path);
  EXPECT_EQ(back.to_string(), law.to_string());
  for (double x : {0.002, 0.01, 0.031}) EXPECT_EQ(back.evaluate(x), law.evaluate(x));
  EXPECT_EQ(back.x_max(), 0.031);
  // Located errors for a bad file.
  nlohmann::json bad = rcm::to_json(law);
  bad["model"]["terms"][1]["kind"] = "tanh";
  try {
    rcm::tissue_law_from_json(bad, "law.json");
    FAIL();
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().field, "model.terms[1].kind");
  }
}

}  // namespace
