#pragma once
// One declaration of an options struct: its field table.
//
// Every options struct the programs expose (StudyOptions and the structs it
// holds, OnlineEstimatorOptions, CorrectionOptions, ...) has one OptionTable,
// built in the struct's .cpp, that lists each member once: its name (the JSON
// key, the Python attribute and keyword, the stem of a command-line flag), a
// line of help, its unit and what it accepts (a range, or words). The default
// is the member's initialiser and nowhere else. From the table come
//
//   - JSON both ways: options_to_json, apply_options_json (an unknown key or a
//     wrong type is an InputError naming the source and the JSON path);
//   - validation: check_options, an InputError naming the field;
//   - help: describe_options (path, type, default, unit, limits, help), which
//     `rcm run --help` prints for its --options file;
//   - the CLI's flags (apps/rcm/cli_options.hpp: help, default and checks of a
//     flag come from its field) and the Python attributes and keyword arguments
//     (python/src/options.hpp).
//
//   const OptionTable<CorrectionOptions>& get_option_table(OptionTag<CorrectionOptions>) {
//     static const auto table = OptionTable<CorrectionOptions>("CorrectionOptions")
//         .add("tolerance_m", &CorrectionOptions::tolerance_m, "aligned within this distance: hold", "m",
//              OptionLimits::above(0))
//         ...;
//     return table;
//   }
//
// Values of these types are supported: bool, int, unsigned, std::size_t,
// std::uint64_t, double, std::string, std::filesystem::path, Eigen::Vector3d,
// an enum with get_option_choices (rcm/common/options_fwd.hpp), a std::optional
// or std::vector of those, and a nested options struct with its own table
// (add_section).

#include <Eigen/Core>
#include <any>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/common/options_fwd.hpp"

namespace rcm {

// The range a number (or every number of a list) must lie in.
struct OptionLimits {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_open = false, max_open = false;  // open: the bound itself is refused

  static OptionLimits at_least(double v) { return {v, std::numeric_limits<double>::infinity(), false, false}; }
  static OptionLimits above(double v) { return {v, std::numeric_limits<double>::infinity(), true, false}; }
  static OptionLimits within(double lo, double hi) { return {lo, hi, false, false}; }
  static OptionLimits above_up_to(double lo, double hi) { return {lo, hi, true, false}; }
  static OptionLimits from_below(double lo, double hi) { return {lo, hi, false, true}; }

  bool empty() const;
  bool contains(double value) const;
  std::string to_text() const;  // "> 0", ">= 1", "in [0, 1]", "in (0, 1]", "" when empty
};

// What a field accepts beyond its type.
struct OptionSpec {
  std::string unit;                   // "m", "N m, N m, N", "" for none
  OptionLimits limits;                // numbers: each value
  std::vector<std::string> choices;   // text: the accepted words (enums: from get_option_choices)
};

// Where option values come from, for located errors: a JSON path inside
// `source` (a file, "StudyOptions", "rcm.StudyOptions"), or, when `flag` is
// set, a command-line flag, which every error then names instead.
struct OptionSource {
  std::string source;
  std::string flag;
  InputLocation at(const std::string& path) const;
};

// One row of help: describe_options.
struct OptionDoc {
  std::string path;    // "joint.huber_scale"
  std::string type;    // "number", "integer", "true|false", "text", "path", "numbers", "[x, y, z]", "joint|three-step"
  std::string value;   // the value as JSON ("null": unset)
  std::string unit;
  std::string limits;  // "> 0", "in [0, 1]"
  std::string help;
};

// Help rows as text, one field per line: "  path  help (unit; limits) [type, default value]".
std::string format_option_docs(const std::vector<OptionDoc>& docs);

template <class T>
struct OptionField {
  std::string name, help;
  OptionSpec spec;
  std::string type;          // as OptionDoc::type
  bool section = false;      // a nested options struct with its own table
  std::any member;           // the pointer to member, M T::*: Python binds it as it is
  std::function<nlohmann::json(const T&)> get;
  // Sets the field from JSON; a wrong type or a value outside the field's
  // limits or words is an InputError at source.at(path).
  std::function<void(T&, const nlohmann::json&, const OptionSource&, const std::string& path)> set;
  // The current value against the limits and words (sections: every field).
  std::function<void(const T&, const OptionSource&, const std::string& path)> check;
  // Help rows: one for a field, one per field of a section.
  std::function<void(const T&, const std::string& path, std::vector<OptionDoc>&)> describe;
};

template <class T>
const OptionTable<T>& get_option_table() {
  return get_option_table(OptionTag<T>{});
}

namespace detail {

template <class M>
struct is_optional : std::false_type {};
template <class M>
struct is_optional<std::optional<M>> : std::true_type {};
template <class M>
struct is_vector : std::false_type {};
template <class M, class A>
struct is_vector<std::vector<M, A>> : std::true_type {};

[[noreturn]] void fail_option(const OptionSource& source, const std::string& path, const std::string& what);
double read_option_number(const nlohmann::json& j, const OptionSource& source, const std::string& path);
long long read_option_integer(const nlohmann::json& j, long long min, unsigned long long max,
                              const OptionSource& source, const std::string& path);
void check_option_number(double value, const OptionLimits& limits, const OptionSource& source,
                         const std::string& path);
// The index of j's word among `words`; an InputError listing them otherwise.
std::size_t read_option_word(const nlohmann::json& j, const std::vector<std::string>& words,
                             const OptionSource& source, const std::string& path);
std::string join_words(const std::vector<std::string>& words, const std::string& separator);
std::string json_type_name(const nlohmann::json& j);

template <class E>
std::vector<std::string> choice_words() {
  std::vector<std::string> words;
  for (const auto& [word, value] : get_option_choices(OptionTag<E>{})) words.push_back(word);
  return words;
}

// JSON, reading, checking and the type's name for a member of type M.
template <class M>
struct OptionValue {
  static nlohmann::json to_json(const M& v) {
    if constexpr (std::is_same_v<M, bool> || std::is_integral_v<M> || std::is_floating_point_v<M> ||
                  std::is_same_v<M, std::string>) {
      return v;
    } else if constexpr (std::is_same_v<M, std::filesystem::path>) {
      return v.string();
    } else if constexpr (std::is_same_v<M, Eigen::Vector3d>) {
      return nlohmann::json::array({v[0], v[1], v[2]});
    } else if constexpr (std::is_enum_v<M>) {
      for (const auto& [word, value] : get_option_choices(OptionTag<M>{}))
        if (value == v) return word;
      return nullptr;
    } else if constexpr (is_optional<M>::value) {
      return v ? OptionValue<typename M::value_type>::to_json(*v) : nlohmann::json(nullptr);
    } else if constexpr (is_vector<M>::value) {
      nlohmann::json a = nlohmann::json::array();
      for (const auto& e : v) a.push_back(OptionValue<typename M::value_type>::to_json(e));
      return a;
    } else {
      static_assert(sizeof(M) == 0, "OptionTable: a member of this type has no JSON form");
    }
  }

  static void from_json(M& v, const nlohmann::json& j, const OptionSpec& spec, const OptionSource& source,
                        const std::string& path) {
    if constexpr (std::is_same_v<M, bool>) {
      if (!j.is_boolean()) fail_option(source, path, "expected true or false, got " + json_type_name(j));
      v = j.get<bool>();
    } else if constexpr (std::is_integral_v<M>) {
      const long long min = static_cast<long long>(std::numeric_limits<M>::min());
      const auto max = static_cast<unsigned long long>(std::numeric_limits<M>::max());
      const long long value = read_option_integer(j, min, max, source, path);
      check_option_number(static_cast<double>(value), spec.limits, source, path);
      v = static_cast<M>(value);
    } else if constexpr (std::is_floating_point_v<M>) {
      const double value = read_option_number(j, source, path);
      check_option_number(value, spec.limits, source, path);
      v = static_cast<M>(value);
    } else if constexpr (std::is_same_v<M, std::string> || std::is_same_v<M, std::filesystem::path>) {
      if (!j.is_string()) fail_option(source, path, "expected a string, got " + json_type_name(j));
      if (!spec.choices.empty()) read_option_word(j, spec.choices, source, path);
      v = j.get<std::string>();
    } else if constexpr (std::is_same_v<M, Eigen::Vector3d>) {
      if (!j.is_array() || j.size() != 3) fail_option(source, path, "expected an array of 3 numbers, got " + j.dump());
      for (int k = 0; k < 3; ++k) {
        const std::string at = path + "[" + std::to_string(k) + "]";
        v[k] = read_option_number(j[static_cast<std::size_t>(k)], source, at);
        check_option_number(v[k], spec.limits, source, at);
      }
    } else if constexpr (std::is_enum_v<M>) {
      const auto& choices = get_option_choices(OptionTag<M>{});
      v = choices[read_option_word(j, choice_words<M>(), source, path)].second;
    } else if constexpr (is_optional<M>::value) {
      if (j.is_null()) {
        v.reset();
      } else {
        typename M::value_type inner{};
        OptionValue<typename M::value_type>::from_json(inner, j, spec, source, path);
        v = std::move(inner);
      }
    } else if constexpr (is_vector<M>::value) {
      if (!j.is_array()) fail_option(source, path, "expected an array, got " + json_type_name(j));
      M out;
      for (std::size_t k = 0; k < j.size(); ++k) {
        typename M::value_type e{};
        OptionValue<typename M::value_type>::from_json(e, j[k], spec, source, path + "[" + std::to_string(k) + "]");
        out.push_back(std::move(e));
      }
      v = std::move(out);
    } else {
      static_assert(sizeof(M) == 0, "OptionTable: a member of this type cannot be read from JSON");
    }
  }

  static void check(const M& v, const OptionSpec& spec, const OptionSource& source, const std::string& path) {
    if constexpr (std::is_same_v<M, bool> || std::is_enum_v<M>) {
      (void)v, (void)spec, (void)source, (void)path;
    } else if constexpr (std::is_integral_v<M> || std::is_floating_point_v<M>) {
      check_option_number(static_cast<double>(v), spec.limits, source, path);
    } else if constexpr (std::is_same_v<M, std::string>) {
      if (!spec.choices.empty()) read_option_word(v, spec.choices, source, path);
    } else if constexpr (std::is_same_v<M, std::filesystem::path>) {
      (void)v, (void)spec, (void)source, (void)path;
    } else if constexpr (std::is_same_v<M, Eigen::Vector3d>) {
      for (int k = 0; k < 3; ++k) check_option_number(v[k], spec.limits, source, path + "[" + std::to_string(k) + "]");
    } else if constexpr (is_optional<M>::value) {
      if (v) OptionValue<typename M::value_type>::check(*v, spec, source, path);
    } else if constexpr (is_vector<M>::value) {
      for (std::size_t k = 0; k < v.size(); ++k)
        OptionValue<typename M::value_type>::check(v[k], spec, source, path + "[" + std::to_string(k) + "]");
    }
  }

  static std::string type(const OptionSpec& spec) {
    if constexpr (std::is_same_v<M, bool>) {
      return "true|false";
    } else if constexpr (std::is_integral_v<M>) {
      return "integer";
    } else if constexpr (std::is_floating_point_v<M>) {
      return "number";
    } else if constexpr (std::is_same_v<M, std::string>) {
      return spec.choices.empty() ? "text" : join_words(spec.choices, "|");
    } else if constexpr (std::is_same_v<M, std::filesystem::path>) {
      return "path";
    } else if constexpr (std::is_same_v<M, Eigen::Vector3d>) {
      return "[x, y, z]";
    } else if constexpr (std::is_enum_v<M>) {
      return join_words(choice_words<M>(), "|");
    } else if constexpr (is_optional<M>::value) {
      return OptionValue<typename M::value_type>::type(spec) + " or null";
    } else if constexpr (is_vector<M>::value) {
      const std::string inner = OptionValue<typename M::value_type>::type(spec);
      return inner == "number" ? std::string("numbers") : "[" + inner + ", ...]";
    } else {
      return "value";
    }
  }
};

}  // namespace detail

template <class T>
class OptionTable {
 public:
  // `name` names the struct in messages ("StudyOptions").
  explicit OptionTable(std::string name) : name_(std::move(name)) {}

  // A member with its help line, unit, limits and words. Enums take their words
  // from get_option_choices.
  template <class M>
  OptionTable& add(std::string name, M T::*member, std::string help, std::string unit = "",
                   OptionLimits limits = {}, std::vector<std::string> choices = {}) {
    using Value = detail::OptionValue<M>;
    OptionField<T> f;
    f.name = std::move(name);
    f.help = std::move(help);
    f.spec = OptionSpec{std::move(unit), limits, std::move(choices)};
    f.type = Value::type(f.spec);
    f.member = member;
    f.get = [member](const T& o) { return Value::to_json(o.*member); };
    const OptionSpec spec = f.spec;
    f.set = [member, spec](T& o, const nlohmann::json& j, const OptionSource& source, const std::string& path) {
      Value::from_json(o.*member, j, spec, source, path);
    };
    f.check = [member, spec](const T& o, const OptionSource& source, const std::string& path) {
      Value::check(o.*member, spec, source, path);
    };
    const std::string type = f.type, help_line = f.help;
    f.describe = [member, spec, type, help_line](const T& o, const std::string& path, std::vector<OptionDoc>& out) {
      out.push_back({path, type, Value::to_json(o.*member).dump(), spec.unit, spec.limits.to_text(), help_line});
    };
    fields_.push_back(std::move(f));
    return *this;
  }

  // A nested options struct, with the table get_option_table<S>() declares.
  template <class S>
  OptionTable& add_section(std::string name, S T::*member, std::string help) {
    OptionField<T> f;
    f.name = std::move(name);
    f.help = std::move(help);
    f.type = "object";
    f.section = true;
    f.member = member;
    f.get = [member](const T& o) { return get_option_table<S>().to_json(o.*member); };
    f.set = [member](T& o, const nlohmann::json& j, const OptionSource& source, const std::string& path) {
      get_option_table<S>().apply_json(o.*member, j, source, path);
    };
    f.check = [member](const T& o, const OptionSource& source, const std::string& path) {
      get_option_table<S>().check(o.*member, source, path);
    };
    f.describe = [member](const T& o, const std::string& path, std::vector<OptionDoc>& out) {
      get_option_table<S>().describe(o.*member, path, out);
    };
    fields_.push_back(std::move(f));
    return *this;
  }

  // A check across fields (D_min below D_max, ...): `check` throws
  // std::invalid_argument or InputError; check() reports it at the source.
  OptionTable& add_check(std::function<void(const T&)> check) {
    cross_checks_.push_back(std::move(check));
    return *this;
  }

  const std::string& name() const { return name_; }
  const std::vector<OptionField<T>>& fields() const { return fields_; }
  const OptionField<T>* find(const std::string& name) const {
    for (const auto& f : fields_)
      if (f.name == name) return &f;
    return nullptr;
  }

  nlohmann::json to_json(const T& options) const {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& f : fields_) j[f.name] = f.get(options);
    return j;
  }

  // Sets the fields `json` names, leaving the others; `prefix` is the JSON path
  // of `json` in its document ("" at the top).
  void apply_json(T& options, const nlohmann::json& json, const OptionSource& source,
                  const std::string& prefix = "") const {
    if (!json.is_object())
      detail::fail_option(source, prefix.empty() ? "(top level)" : prefix,
                          "expected an object, got " + detail::json_type_name(json));
    for (auto it = json.begin(); it != json.end(); ++it) {
      const std::string path = prefix.empty() ? it.key() : prefix + "." + it.key();
      const OptionField<T>* f = find(it.key());
      if (!f) {
        std::vector<std::string> known;
        for (const auto& g : fields_) known.push_back(g.name);
        detail::fail_option(source, path, "unknown key in " + name_ + "; known: " + detail::join_words(known, ", "));
      }
      f->set(options, it.value(), source, path);
    }
  }

  // Every field against its limits and words, then the checks across fields.
  void check(const T& options, const OptionSource& source, const std::string& prefix = "") const {
    for (const auto& f : fields_) f.check(options, source, prefix.empty() ? f.name : prefix + "." + f.name);
    for (const auto& c : cross_checks_) {
      try {
        c(options);
      } catch (const std::invalid_argument& e) {
        detail::fail_option(source, prefix.empty() ? name_ : prefix, e.what());
      }
    }
  }

  void describe(const T& options, const std::string& prefix, std::vector<OptionDoc>& out) const {
    for (const auto& f : fields_) f.describe(options, prefix.empty() ? f.name : prefix + "." + f.name, out);
  }

 private:
  std::string name_;
  std::vector<OptionField<T>> fields_;
  std::vector<std::function<void(const T&)>> cross_checks_;
};

template <class T>
nlohmann::json options_to_json(const T& options) {
  return get_option_table<T>().to_json(options);
}

// Overrides the fields `json` names; an unknown key, a wrong type or a value
// outside its limits is an InputError naming `source` and the JSON path.
template <class T>
void apply_options_json(T& options, const nlohmann::json& json, const std::string& source) {
  get_option_table<T>().apply_json(options, json, OptionSource{source, ""});
}

// Every field of `options` against its limits and words, and the struct's
// checks across fields: an InputError naming `source` and the field.
template <class T>
void check_options(const T& options, const std::string& source) {
  get_option_table<T>().check(options, OptionSource{source, ""});
}

// The defaults with `json` applied, then checked.
template <class T>
T options_from_json(const nlohmann::json& json, const std::string& source) {
  T options;
  apply_options_json(options, json, source);
  check_options(options, source);
  return options;
}

// One help row per field, sections expanded ("joint.huber_scale"), with the
// values of `options` (the defaults unless given).
template <class T>
std::vector<OptionDoc> describe_options(const T& options = T{}) {
  std::vector<OptionDoc> out;
  get_option_table<T>().describe(options, "", out);
  return out;
}

// The table's field at a dotted path through sections ("fit.seed"): sets it
// from JSON with errors at `source`.
template <class T>
void set_option(T& options, const std::string& path, const nlohmann::json& value, const OptionSource& source) {
  nlohmann::json j = value;
  std::string rest = path;
  std::vector<std::string> parts;
  for (std::size_t dot; (dot = rest.find('.')) != std::string::npos; rest = rest.substr(dot + 1))
    parts.push_back(rest.substr(0, dot));
  parts.push_back(rest);
  for (auto it = parts.rbegin(); it != parts.rend(); ++it) j = nlohmann::json{{*it, j}};
  get_option_table<T>().apply_json(options, j, source);
}

// The help row of the field at a dotted path ("fit.seed"); std::invalid_argument
// when there is none.
template <class T>
OptionDoc describe_option(const std::string& path, const T& options = T{}) {
  for (const OptionDoc& d : describe_options(options))
    if (d.path == path) return d;
  throw std::invalid_argument(get_option_table<T>().name() + " has no field " + path);
}

}  // namespace rcm
