#pragma once
// Closed-form candidates for the tissue law g: x -> y (paper III-C step 2, Eq. 11).
//
// The search space is the linear span of the paper's library {1, x, x^2, x^3,
// sin x, cos x, exp x}, where each of sin, cos and exp may also carry an inner
// scale constant (sin(b*x)), and every term carries an outer constant:
//
//   g(x) = [c] + sum_k a_k * phi_k(x),   phi_k in {x, x^2, x^3, sin(x), cos(x),
//          exp(x), sin(b x), cos(b x), exp(b x)}, each kind at most once.
//
// Complexity is the node count of the expression tree exactly as PySR counts it
// with binary operators {+, -, *, /} and unary operators {square, cube, sin,
// cos, exp}: every constant, every x and every operator is one node. So
// 788.0*x is 3, a*sin(b*x) is 6, a*exp(b*x) + c is 8 and a full cubic
// a*x^3 + b*x^2 + c*x + d is 15.

#include <string>
#include <vector>

#include "rcm/common/options_fwd.hpp"

namespace rcm {

// Canonical order of the terms in an expression is the order of this enum.
enum class TissueTermKind : int {
  x = 0,
  square,      // x^2
  cube,        // x^3
  sin,         // sin(x)
  cos,         // cos(x)
  exp,         // exp(x)
  sin_scaled,  // sin(b*x), b > 0 (the sign goes into the outer constant)
  cos_scaled,  // cos(b*x), b > 0 (cos is even)
  exp_scaled,  // exp(b*x), b of either sign
};
inline constexpr int kNumTissueTermKinds = 9;

const char* to_string(TissueTermKind kind);
// The kinds' words (to_string), for options tables (rcm/common/options.hpp).
const OptionChoices<TissueTermKind>& get_option_choices(OptionTag<TissueTermKind>);
bool has_inner_constant(TissueTermKind kind);
// Node count of phi_k alone (x: 1, square(x): 2, sin(b*x): 4).
int get_basis_complexity(TissueTermKind kind);

struct TissueTerm {
  TissueTermKind kind = TissueTermKind::x;
  double coefficient = 0.0;  // outer constant a
  double scale = 1.0;        // inner constant b; used only by *_scaled kinds
};

// One candidate g. Plain data; `terms` must be in canonical order with each kind
// at most once (check with is_canonical()).
struct TissueExpression {
  bool has_intercept = false;
  double intercept = 0.0;
  std::vector<TissueTerm> terms;

  bool empty() const { return !has_intercept && terms.empty(); }
  bool is_canonical() const;
  int complexity() const;     // PySR node count
  int num_constants() const;  // fitted constants (for BIC)
  double evaluate(double x) const;
  double derivative(double x) const;  // dg/dx
  // The leading coefficient: outer constant of the first term in canonical order
  // (788 for 788.0*x); the intercept for a constant-only law.
  double get_leading_coefficient() const;
  // Structure without numbers, e.g. "C*x + C*x^3" or "C*exp(C*x) + C": two
  // expressions belong to the same family when their skeletons are equal.
  std::string get_skeleton() const;
};

enum class ExpressionFormat {
  plain,  // 788.0*x + 3.1*x^3 - 0.2
  sympy,  // 788.0*x + 3.1*x**3 - 0.2 (sympy.sympify / Python eval with math)
  latex,  // 788.0 x + 3.1 x^{3} - 0.2
};

// significant_digits = 0 prints every constant with the shortest decimal that
// reads back to the same double (exact export); > 0 rounds for display.
std::string format_expression(const TissueExpression& expression, ExpressionFormat format,
                              int significant_digits = 0);

// Number formatting shared by the tissue code: shortest round-trip decimal
// (significant_digits = 0) or rounded, always with a '.' or exponent so that
// sympy reads it as a float.
std::string format_constant(double value, int significant_digits = 0);

}  // namespace rcm
