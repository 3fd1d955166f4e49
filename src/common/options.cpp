#include "rcm/common/options.hpp"

#include <cmath>
#include <sstream>

namespace rcm {

namespace {

std::string format_number(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace

bool OptionLimits::empty() const { return std::isinf(min) && min < 0 && std::isinf(max) && max > 0; }

bool OptionLimits::contains(double v) const {
  if (!std::isfinite(v)) return false;
  if (min_open ? !(v > min) : !(v >= min)) return false;
  if (max_open ? !(v < max) : !(v <= max)) return false;
  return true;
}

std::string OptionLimits::to_text() const {
  const bool has_min = std::isfinite(min), has_max = std::isfinite(max);
  if (has_min && has_max)
    return std::string("in ") + (min_open ? "(" : "[") + format_number(min) + ", " + format_number(max) +
           (max_open ? ")" : "]");
  if (has_min) return (min_open ? "> " : ">= ") + format_number(min);
  if (has_max) return (max_open ? "< " : "<= ") + format_number(max);
  return "";
}

InputLocation OptionSource::at(const std::string& path) const {
  if (!flag.empty()) return InputLocation::plain(source, flag);
  InputLocation where;
  where.file = source;
  where.field = path;
  where.kind = InputLocation::Kind::json_field;
  return where;
}

std::string format_option_docs(const std::vector<OptionDoc>& docs) {
  std::size_t width = 0;
  for (const auto& d : docs) width = std::max(width, d.path.size());
  std::string out;
  for (const auto& d : docs) {
    std::string detail = d.unit;
    if (!d.limits.empty()) detail += (detail.empty() ? "" : "; ") + d.limits;
    out += "  " + d.path + std::string(width - d.path.size() + 2, ' ') + d.help;
    if (!detail.empty()) out += " (" + detail + ")";
    out += " [" + d.type + ", default " + d.value + "]\n";
  }
  return out;
}

namespace detail {

void fail_option(const OptionSource& source, const std::string& path, const std::string& what) {
  throw InputError(source.at(path), what);
}

std::string json_type_name(const nlohmann::json& j) { return j.type_name(); }

std::string join_words(const std::vector<std::string>& words, const std::string& separator) {
  std::string out;
  for (const auto& w : words) out += (out.empty() ? "" : separator) + w;
  return out;
}

double read_option_number(const nlohmann::json& j, const OptionSource& source, const std::string& path) {
  if (!j.is_number()) fail_option(source, path, "expected a number, got " + json_type_name(j));
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail_option(source, path, "expected a finite number");
  return v;
}

long long read_option_integer(const nlohmann::json& j, long long min, unsigned long long max,
                              const OptionSource& source, const std::string& path) {
  if (!j.is_number_integer()) fail_option(source, path, "expected an integer, got " + j.dump());
  if (j.is_number_unsigned()) {
    const auto u = j.get<unsigned long long>();
    if (u > max || u > static_cast<unsigned long long>(std::numeric_limits<long long>::max()))
      fail_option(source, path, "expected an integer up to " + std::to_string(max) + ", got " + j.dump());
    return static_cast<long long>(u);
  }
  const auto v = j.get<long long>();
  if (v < min) fail_option(source, path, "expected an integer >= " + std::to_string(min) + ", got " + j.dump());
  return v;
}

void check_option_number(double value, const OptionLimits& limits, const OptionSource& source,
                         const std::string& path) {
  if (!std::isfinite(value)) fail_option(source, path, "expected a finite number");
  if (!limits.contains(value)) fail_option(source, path, "expected " + limits.to_text() + ", got " + format_number(value));
}

std::size_t read_option_word(const nlohmann::json& j, const std::vector<std::string>& words,
                             const OptionSource& source, const std::string& path) {
  const std::string expected = "expected " + join_words(words, ", ");
  if (!j.is_string()) fail_option(source, path, expected + "; got " + json_type_name(j));
  const std::string text = j.get<std::string>();
  for (std::size_t k = 0; k < words.size(); ++k)
    if (words[k] == text) return k;
  fail_option(source, path, expected + "; got " + quote_token(text));
}

}  // namespace detail

}  // namespace rcm
