#include "rcm/tissue/expression.hpp"

#include <fmt/format.h>

#include <cassert>
#include <cmath>
#include <string>

#include "rcm/common/options.hpp"

namespace rcm {

const char* to_string(TissueTermKind kind) {
  switch (kind) {
    case TissueTermKind::x: return "x";
    case TissueTermKind::square: return "x^2";
    case TissueTermKind::cube: return "x^3";
    case TissueTermKind::sin: return "sin(x)";
    case TissueTermKind::cos: return "cos(x)";
    case TissueTermKind::exp: return "exp(x)";
    case TissueTermKind::sin_scaled: return "sin(b*x)";
    case TissueTermKind::cos_scaled: return "cos(b*x)";
    case TissueTermKind::exp_scaled: return "exp(b*x)";
  }
  return "?";
}

bool has_inner_constant(TissueTermKind kind) {
  return kind == TissueTermKind::sin_scaled || kind == TissueTermKind::cos_scaled ||
         kind == TissueTermKind::exp_scaled;
}

int get_basis_complexity(TissueTermKind kind) {
  switch (kind) {
    case TissueTermKind::x: return 1;                 // x
    case TissueTermKind::square:                      // square(x)
    case TissueTermKind::cube:                        // cube(x)
    case TissueTermKind::sin:                         // sin(x)
    case TissueTermKind::cos:                         // cos(x)
    case TissueTermKind::exp: return 2;               // exp(x)
    case TissueTermKind::sin_scaled:                  // sin(*(b, x))
    case TissueTermKind::cos_scaled:
    case TissueTermKind::exp_scaled: return 4;
  }
  return 0;
}

bool TissueExpression::is_canonical() const {
  for (std::size_t k = 1; k < terms.size(); ++k) {
    if (static_cast<int>(terms[k - 1].kind) >= static_cast<int>(terms[k].kind)) return false;
  }
  return true;
}

int TissueExpression::complexity() const {
  int nodes = 0;
  int parts = 0;
  if (has_intercept) {
    nodes += 1;
    ++parts;
  }
  for (const auto& term : terms) {
    nodes += get_basis_complexity(term.kind) + 2;  // '*' and the outer constant
    ++parts;
  }
  if (parts > 1) nodes += parts - 1;  // the '+' / '-' nodes joining the parts
  return nodes;
}

int TissueExpression::num_constants() const {
  int n = has_intercept ? 1 : 0;
  for (const auto& term : terms) n += has_inner_constant(term.kind) ? 2 : 1;
  return n;
}

namespace {

double evaluate_basis(const TissueTerm& term, double x) {
  switch (term.kind) {
    case TissueTermKind::x: return x;
    case TissueTermKind::square: return x * x;
    case TissueTermKind::cube: return x * x * x;
    case TissueTermKind::sin: return std::sin(x);
    case TissueTermKind::cos: return std::cos(x);
    case TissueTermKind::exp: return std::exp(x);
    case TissueTermKind::sin_scaled: return std::sin(term.scale * x);
    case TissueTermKind::cos_scaled: return std::cos(term.scale * x);
    case TissueTermKind::exp_scaled: return std::exp(term.scale * x);
  }
  return 0.0;
}

double differentiate_basis(const TissueTerm& term, double x) {
  const double b = term.scale;
  switch (term.kind) {
    case TissueTermKind::x: return 1.0;
    case TissueTermKind::square: return 2.0 * x;
    case TissueTermKind::cube: return 3.0 * x * x;
    case TissueTermKind::sin: return std::cos(x);
    case TissueTermKind::cos: return -std::sin(x);
    case TissueTermKind::exp: return std::exp(x);
    case TissueTermKind::sin_scaled: return b * std::cos(b * x);
    case TissueTermKind::cos_scaled: return -b * std::sin(b * x);
    case TissueTermKind::exp_scaled: return b * std::exp(b * x);
  }
  return 0.0;
}

}  // namespace

double TissueExpression::evaluate(double x) const {
  double y = has_intercept ? intercept : 0.0;
  for (const auto& term : terms) y += term.coefficient * evaluate_basis(term, x);
  return y;
}

double TissueExpression::derivative(double x) const {
  double dy = 0.0;
  for (const auto& term : terms) dy += term.coefficient * differentiate_basis(term, x);
  return dy;
}

double TissueExpression::get_leading_coefficient() const {
  if (!terms.empty()) return terms.front().coefficient;
  return has_intercept ? intercept : 0.0;
}

std::string format_constant(double value, int significant_digits) {
  if (!std::isfinite(value)) return std::isnan(value) ? "nan" : (value > 0 ? "inf" : "-inf");
  std::string text = significant_digits > 0 ? fmt::format("{:.{}g}", value, significant_digits)
                                            : fmt::format("{}", value);
  if (text.find_first_of(".eE") == std::string::npos) text += ".0";
  return text;
}

namespace {

// Basis function text with `b` already formatted (or empty for unscaled kinds).
std::string format_basis(TissueTermKind kind, const std::string& b, ExpressionFormat format) {
  const bool latex = format == ExpressionFormat::latex;
  const char* pow_op = format == ExpressionFormat::sympy ? "**" : "^";
  auto call = [&](const char* fn, const std::string& arg) {
    if (latex) return fmt::format("\\{}\\left({}\\right)", fn, arg);
    return fmt::format("{}({})", fn, arg);
  };
  const std::string scaled_x = latex ? b + " x" : b + "*x";
  switch (kind) {
    case TissueTermKind::x: return "x";
    case TissueTermKind::square: return latex ? "x^{2}" : fmt::format("x{}2", pow_op);
    case TissueTermKind::cube: return latex ? "x^{3}" : fmt::format("x{}3", pow_op);
    case TissueTermKind::sin: return call("sin", "x");
    case TissueTermKind::cos: return call("cos", "x");
    case TissueTermKind::exp: return latex ? "e^{x}" : "exp(x)";
    case TissueTermKind::sin_scaled: return call("sin", scaled_x);
    case TissueTermKind::cos_scaled: return call("cos", scaled_x);
    case TissueTermKind::exp_scaled: return latex ? "e^{" + scaled_x + "}" : "exp(" + scaled_x + ")";
  }
  return "?";
}

// 1.5e+07 -> 1.5 \cdot 10^{7} for LaTeX.
std::string latex_number(const std::string& text) {
  const auto e = text.find_first_of("eE");
  if (e == std::string::npos) return text;
  std::string mantissa = text.substr(0, e);
  std::string exponent = text.substr(e + 1);
  if (!exponent.empty() && exponent[0] == '+') exponent.erase(0, 1);
  while (exponent.size() > 1 && exponent[0] == '0') exponent.erase(0, 1);
  if (exponent.size() > 2 && exponent[0] == '-' && exponent[1] == '0') exponent.erase(1, 1);
  return mantissa + " \\cdot 10^{" + exponent + "}";
}

}  // namespace

std::string format_expression(const TissueExpression& expression, ExpressionFormat format,
                              int significant_digits) {
  if (expression.empty()) return "0.0";
  const bool latex = format == ExpressionFormat::latex;
  auto number = [&](double v) {
    std::string text = format_constant(v, significant_digits);
    return latex ? latex_number(text) : text;
  };
  std::string out;
  auto append = [&](double signed_value, const std::string& rest) {
    // rest empty: a bare constant. The sign of each part goes into the joining
    // operator so that the text reads like PySR's (a*x - c, not a*x + -c).
    const bool negative = std::signbit(signed_value);
    const double magnitude = std::fabs(signed_value);
    if (out.empty()) {
      out = negative ? "-" : "";
    } else {
      out += negative ? " - " : " + ";
    }
    out += number(magnitude);
    if (!rest.empty()) out += (latex ? " " : "*") + rest;
  };
  for (const auto& term : expression.terms) {
    const std::string b = has_inner_constant(term.kind) ? number(term.scale) : std::string();
    append(term.coefficient, format_basis(term.kind, b, format));
  }
  if (expression.has_intercept) append(expression.intercept, "");
  return out;
}

std::string TissueExpression::get_skeleton() const {
  std::string out;
  auto add = [&](const std::string& part) {
    if (!out.empty()) out += " + ";
    out += part;
  };
  for (const auto& term : terms) {
    switch (term.kind) {
      case TissueTermKind::sin_scaled: add("C*sin(C*x)"); break;
      case TissueTermKind::cos_scaled: add("C*cos(C*x)"); break;
      case TissueTermKind::exp_scaled: add("C*exp(C*x)"); break;
      default: add(std::string("C*") + to_string(term.kind)); break;
    }
  }
  if (has_intercept) add("C");
  return out;
}

const OptionChoices<TissueTermKind>& get_option_choices(OptionTag<TissueTermKind>) {
  static const OptionChoices<TissueTermKind> choices = [] {
    OptionChoices<TissueTermKind> c;
    for (int k = 0; k < kNumTissueTermKinds; ++k) {
      const auto kind = static_cast<TissueTermKind>(k);
      c.emplace_back(to_string(kind), kind);
    }
    return c;
  }();
  return choices;
}

}  // namespace rcm
