#pragma once
// The identified tissue law g: x = D tan(theta) [m] -> |f_inc| [N] (paper Eq. 11),
// immutable once fitted, with its derivative and its inverse on the fitted range
// (needed for the radial recovery, Eq. 19).

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "rcm/tissue/expression.hpp"

namespace rcm {

enum class Monotonicity { increasing, decreasing, not_monotone };
const char* to_string(Monotonicity monotonicity);

enum class TissueInverseStatus {
  ok,
  not_monotone,   // g is not monotone on the domain: g^{-1} is not a function there
  out_of_range,   // y lies outside g(domain)
  not_converged,  // safeguarded Newton ran out of iterations (should not happen)
};
const char* to_string(TissueInverseStatus status);

struct TissueInverseResult {
  double x = 0.0;  // NaN unless status == ok
  TissueInverseStatus status = TissueInverseStatus::ok;
  int iterations = 0;
  std::string message;
};

class TissueLaw {
 public:
  // `x_min` < `x_max`: the range of x the law was fitted on. Monotonicity on that
  // range is established here, once: g' is sampled on a dense grid
  // (monotonicity_samples points) and g must be strictly monotone between them.
  TissueLaw(TissueExpression expression, double x_min, double x_max,
            int monotonicity_samples = 2048);

  const TissueExpression& expression() const { return expression_; }
  double x_min() const { return x_min_; }
  double x_max() const { return x_max_; }
  int complexity() const { return expression_.complexity(); }
  Monotonicity monotonicity() const { return monotonicity_; }

  double evaluate(double x) const { return expression_.evaluate(x); }
  double derivative(double x) const { return expression_.derivative(x); }

  // g^{-1}(y) on [x_min, x_max]: bracketing plus safeguarded Newton (a Newton
  // step that leaves the bracket becomes a bisection step). Converges to
  // |dx| <= 1e-14 (|x| + x_max - x_min). Never throws.
  TissueInverseResult compute_inverse(double y) const;
  // Same, but throws std::domain_error with the reason when status != ok.
  double inverse(double y) const;

  std::string to_string(ExpressionFormat format = ExpressionFormat::sympy,
                        int significant_digits = 0) const {
    return format_expression(expression_, format, significant_digits);
  }

 private:
  TissueExpression expression_;
  double x_min_ = 0.0, x_max_ = 0.0;
  Monotonicity monotonicity_ = Monotonicity::not_monotone;
  double y_at_min_ = 0.0, y_at_max_ = 0.0;
};

// JSON form ("rcm-tissue-law/1"): the expression both as structured terms (exact
// doubles) and as sympy / LaTeX text, plus the fitted range.
nlohmann::json to_json(const TissueExpression& expression);
nlohmann::json to_json(const TissueLaw& law);
// Throws InputError naming `source` and the field for any defect.
TissueExpression tissue_expression_from_json(const nlohmann::json& value, const std::string& source,
                                             const std::string& field = "expression");
TissueLaw tissue_law_from_json(const nlohmann::json& value, const std::string& source);
void save_tissue_law(const std::filesystem::path& path, const TissueLaw& law);
TissueLaw load_tissue_law(const std::filesystem::path& path);

}  // namespace rcm
