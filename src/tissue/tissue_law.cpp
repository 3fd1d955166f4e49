#include "rcm/tissue/tissue_law.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"

namespace rcm {

const char* to_string(Monotonicity monotonicity) {
  switch (monotonicity) {
    case Monotonicity::increasing: return "increasing";
    case Monotonicity::decreasing: return "decreasing";
    case Monotonicity::not_monotone: return "not_monotone";
  }
  return "?";
}

const char* to_string(TissueInverseStatus status) {
  switch (status) {
    case TissueInverseStatus::ok: return "ok";
    case TissueInverseStatus::not_monotone: return "not_monotone";
    case TissueInverseStatus::out_of_range: return "out_of_range";
    case TissueInverseStatus::not_converged: return "not_converged";
  }
  return "?";
}

TissueLaw::TissueLaw(TissueExpression expression, double x_min, double x_max,
                     int monotonicity_samples)
    : expression_(std::move(expression)), x_min_(x_min), x_max_(x_max) {
  if (!(std::isfinite(x_min) && std::isfinite(x_max) && x_min < x_max)) {
    throw std::invalid_argument(
        fmt::format("TissueLaw: fitted range must satisfy x_min < x_max, got [{}, {}]", x_min, x_max));
  }
  if (!expression_.is_canonical()) {
    throw std::invalid_argument("TissueLaw: expression terms are not in canonical order");
  }
  if (monotonicity_samples < 2) monotonicity_samples = 2;
  y_at_min_ = evaluate(x_min_);
  y_at_max_ = evaluate(x_max_);

  // Strict monotonicity of the samples and a derivative that never has the
  // opposite sign: a wiggle narrower than the grid spacing would need g'' of
  // order |g'| / spacing^2, which none of the library's terms reaches at 2048
  // samples unless an inner constant makes sin/cos oscillate (then the sampled
  // values already fail).
  const int sign = y_at_max_ > y_at_min_ ? 1 : (y_at_max_ < y_at_min_ ? -1 : 0);
  bool monotone = sign != 0 && std::isfinite(y_at_min_) && std::isfinite(y_at_max_);
  double previous = y_at_min_;
  const double scale = std::fabs(y_at_max_ - y_at_min_) / (x_max_ - x_min_);
  for (int i = 0; monotone && i < monotonicity_samples; ++i) {
    const double x = x_min_ + (x_max_ - x_min_) * i / (monotonicity_samples - 1);
    const double y = evaluate(x);
    const double dy = derivative(x);
    if (!std::isfinite(y) || !std::isfinite(dy)) monotone = false;
    if (i > 0 && sign * (y - previous) <= 0.0) monotone = false;
    if (sign * dy < -1e-12 * scale) monotone = false;
    previous = y;
  }
  monotonicity_ = !monotone ? Monotonicity::not_monotone
                            : (sign > 0 ? Monotonicity::increasing : Monotonicity::decreasing);
}

TissueInverseResult TissueLaw::compute_inverse(double y) const {
  TissueInverseResult result;
  result.x = std::numeric_limits<double>::quiet_NaN();
  if (monotonicity_ == Monotonicity::not_monotone) {
    result.status = TissueInverseStatus::not_monotone;
    result.message = fmt::format(
        "g = {} is not monotone on its fitted range [{:.6g}, {:.6g}] m, so g^-1 is not a function "
        "there; refit with a monotone law (e.g. lower the maximum complexity or restrict the library)",
        to_string(ExpressionFormat::sympy, 6), x_min_, x_max_);
    return result;
  }
  const double y_lo = std::min(y_at_min_, y_at_max_);
  const double y_hi = std::max(y_at_min_, y_at_max_);
  if (!std::isfinite(y) || y < y_lo || y > y_hi) {
    result.status = TissueInverseStatus::out_of_range;
    result.message = fmt::format(
        "y = {:.6g} N lies outside g([{:.6g}, {:.6g}]) = [{:.6g}, {:.6g}] N, the range the law was "
        "fitted on; g^-1 is not extrapolated",
        y, x_min_, x_max_, y_lo, y_hi);
    return result;
  }
  // Bracket [a, b] with g(a) - y and g(b) - y of opposite signs (or zero).
  const double sign = monotonicity_ == Monotonicity::increasing ? 1.0 : -1.0;
  double a = x_min_, b = x_max_;
  const double tol = 1e-14 * (std::fabs(x_min_) + std::fabs(x_max_) + (x_max_ - x_min_));
  // Start from the secant through the ends: exact for a linear law.
  // Clamped: x_min + (x_max - x_min) * 1 can round one ulp past x_max.
  double x = y_hi > y_lo ? std::clamp(x_min_ + (x_max_ - x_min_) * (y - y_at_min_) / (y_at_max_ - y_at_min_), a, b)
                         : 0.5 * (a + b);
  for (int it = 1; it <= 200; ++it) {
    result.iterations = it;
    const double r = evaluate(x) - y;
    if (r == 0.0) {
      result.x = x;
      return result;
    }
    if (sign * r > 0.0) {
      b = x;
    } else {
      a = x;
    }
    const double dr = derivative(x);
    double next = dr != 0.0 ? x - r / dr : std::numeric_limits<double>::quiet_NaN();
    if (!(next > a && next < b)) next = 0.5 * (a + b);
    const double step = std::fabs(next - x);
    x = next;
    if (step <= tol || b - a <= tol) {
      result.x = x;
      return result;
    }
  }
  result.status = TissueInverseStatus::not_converged;
  result.message = "g^-1: safeguarded Newton did not converge in 200 iterations";
  return result;
}

double TissueLaw::inverse(double y) const {
  TissueInverseResult result = compute_inverse(y);
  if (result.status != TissueInverseStatus::ok) throw std::domain_error(result.message);
  return result.x;
}

// ---------------------------------------------------------------------------
// JSON

nlohmann::json to_json(const TissueExpression& expression) {
  nlohmann::json terms = nlohmann::json::array();
  for (const auto& term : expression.terms) {
    nlohmann::json t = {{"kind", to_string(term.kind)}, {"coefficient", term.coefficient}};
    if (has_inner_constant(term.kind)) t["scale"] = term.scale;
    terms.push_back(std::move(t));
  }
  nlohmann::json out = {{"terms", std::move(terms)}};
  if (expression.has_intercept) out["intercept"] = expression.intercept;
  return out;
}

nlohmann::json to_json(const TissueLaw& law) {
  return {{"format", "rcm-tissue-law/1"},
          {"expression", law.to_string(ExpressionFormat::sympy)},
          {"latex", law.to_string(ExpressionFormat::latex)},
          {"complexity", law.complexity()},
          {"x_range_m", {law.x_min(), law.x_max()}},
          {"monotonicity", to_string(law.monotonicity())},
          {"model", to_json(law.expression())}};
}

namespace {

double require_number(const nlohmann::json& obj, const char* key, const std::string& source,
                      const std::string& field) {
  const std::string path = field + "." + key;
  if (!obj.is_object() || !obj.contains(key)) throw InputError({source, 0, 0, path}, "missing");
  const auto& v = obj.at(key);
  if (!v.is_number()) throw InputError({source, 0, 0, path}, "expected a number, got " + v.dump());
  const double d = v.get<double>();
  if (!std::isfinite(d)) throw InputError({source, 0, 0, path}, "expected a finite number");
  return d;
}

}  // namespace

TissueExpression tissue_expression_from_json(const nlohmann::json& value, const std::string& source,
                                             const std::string& field) {
  if (!value.is_object()) throw InputError({source, 0, 0, field}, "expected an object");
  TissueExpression expression;
  if (value.contains("intercept")) {
    expression.has_intercept = true;
    expression.intercept = require_number(value, "intercept", source, field);
  }
  if (!value.contains("terms") || !value.at("terms").is_array()) {
    throw InputError({source, 0, 0, field + ".terms"}, "expected an array of terms");
  }
  const auto& terms = value.at("terms");
  for (std::size_t i = 0; i < terms.size(); ++i) {
    const std::string path = fmt::format("{}.terms[{}]", field, i);
    const auto& t = terms[i];
    if (!t.is_object() || !t.contains("kind") || !t.at("kind").is_string()) {
      throw InputError({source, 0, 0, path + ".kind"}, "expected a term kind string");
    }
    const std::string kind_name = t.at("kind").get<std::string>();
    TissueTerm term;
    bool known = false;
    std::string known_names;
    for (int k = 0; k < kNumTissueTermKinds; ++k) {
      const auto kind = static_cast<TissueTermKind>(k);
      known_names += std::string(k ? ", " : "") + to_string(kind);
      if (kind_name == to_string(kind)) {
        term.kind = kind;
        known = true;
      }
    }
    if (!known) {
      throw InputError({source, 0, 0, path + ".kind"},
                       "unknown term " + quote_token(kind_name) + "; known: " + known_names);
    }
    term.coefficient = require_number(t, "coefficient", source, path);
    if (has_inner_constant(term.kind)) term.scale = require_number(t, "scale", source, path);
    expression.terms.push_back(term);
  }
  if (!expression.is_canonical()) {
    throw InputError({source, 0, 0, field + ".terms"},
                     "terms must be in canonical order (x, x^2, x^3, sin, cos, exp, scaled) "
                     "with each kind at most once");
  }
  if (expression.empty()) throw InputError({source, 0, 0, field}, "empty expression");
  return expression;
}

TissueLaw tissue_law_from_json(const nlohmann::json& value, const std::string& source) {
  const auto format = value.is_object() ? value.find("format") : value.end();
  if (format == value.end() || !format->is_string() || format->get<std::string>() != "rcm-tissue-law/1") {
    throw InputError({source, 0, 0, "format"}, "expected \"format\": \"rcm-tissue-law/1\"");
  }
  if (!value.contains("x_range_m") || !value.at("x_range_m").is_array() ||
      value.at("x_range_m").size() != 2 || !value.at("x_range_m")[0].is_number() ||
      !value.at("x_range_m")[1].is_number()) {
    throw InputError({source, 0, 0, "x_range_m"}, "expected [x_min, x_max] in metres");
  }
  const double lo = value.at("x_range_m")[0].get<double>();
  const double hi = value.at("x_range_m")[1].get<double>();
  if (!(std::isfinite(lo) && std::isfinite(hi) && lo < hi)) {
    throw InputError({source, 0, 0, "x_range_m"}, "expected finite x_min < x_max");
  }
  if (!value.contains("model")) throw InputError({source, 0, 0, "model"}, "missing");
  return TissueLaw(tissue_expression_from_json(value.at("model"), source, "model"), lo, hi);
}

void save_tissue_law(const std::filesystem::path& path, const TissueLaw& law) {
  save_json_file(path, to_json(law));
}

TissueLaw load_tissue_law(const std::filesystem::path& path) {
  return tissue_law_from_json(load_json_file(path), path.string());
}

}  // namespace rcm
