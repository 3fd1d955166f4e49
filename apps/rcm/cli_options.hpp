#pragma once
// Command-line flags made from the field tables of the options structs
// (rcm/common/options.hpp). A flag names one or more fields of a struct T (a
// dotted path through its sections, "fit.seed"); its help is the field's help,
// unit, limits and default, its value is read as the field's type, checked
// against the field's limits and the struct's checks across fields, and an
// error names the flag (InputError, exit status 2). Values are collected while
// CLI11 parses and applied by apply(), after an --options file, so that a flag
// overrides the file.

#include <CLI/CLI.hpp>

#include <deque>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/options.hpp"

namespace rcm::cli {

// "help (unit; limits; default value)" of the field at `path`.
template <class T>
std::string describe_flag(const std::string& path, const std::string& help = "") {
  const OptionDoc d = describe_option<T>(path);
  std::string detail = d.unit;
  if (!d.limits.empty()) detail += (detail.empty() ? "" : "; ") + d.limits;
  if (d.value != "null") detail += (detail.empty() ? "default " : "; default ") + d.value;
  return (help.empty() ? d.help : help) + (detail.empty() ? "" : " (" + detail + ")");
}

template <class T>
class OptionFlags {
 public:
  // `flag` sets every field at `paths` to its value. `help` replaces the first
  // field's help line (its unit, limits and default are still said).
  CLI::Option* add(CLI::App* cmd, const std::string& flag, std::vector<std::string> paths,
                   const std::string& help = "") {
    const OptionDoc doc = describe_option<T>(paths.front());
    Flag& f = flags_.emplace_back(Flag{flag, std::move(paths), std::nullopt});
    const std::string text = describe_flag<T>(f.paths.front(), help);
    if (doc.type == "true|false") return cmd->add_flag_function(flag, [&f](std::int64_t) { f.value = true; }, text);
    if (doc.type.rfind("number", 0) == 0 && doc.type.rfind("numbers", 0) != 0)
      return cmd->add_option_function<double>(flag, [&f](const double& v) { f.value = v; }, text);
    if (doc.type == "integer")
      return cmd->add_option_function<std::int64_t>(flag, [&f](const std::int64_t& v) { f.value = v; }, text);
    if (doc.type.rfind("numbers", 0) == 0)
      return cmd->add_option_function<std::string>(
          flag, [&f](const std::string& v) { f.value = parse_number_list(v, f.name); }, text);
    if (doc.type == "[x, y, z]")
      return cmd->add_option_function<std::string>(
          flag, [&f](const std::string& v) { f.value = to_json(parse_vector3(v, f.name)); }, text);
    return cmd->add_option_function<std::string>(flag, [&f](const std::string& v) { f.value = v; }, text);
  }

  // A switch: given, it sets the fields at `paths` to `value` (--generic-structure: rigid_body false).
  CLI::Option* add_switch(CLI::App* cmd, const std::string& flag, std::vector<std::string> paths,
                          nlohmann::json value, const std::string& help) {
    Flag& f = flags_.emplace_back(Flag{flag, std::move(paths), std::nullopt});
    return cmd->add_flag_function(flag, [&f, value](std::int64_t) { f.value = value; }, help);
  }

  bool given(const std::string& flag) const {
    for (const Flag& f : flags_)
      if (f.name == flag) return f.value.has_value();
    return false;
  }

  // Sets the fields of the flags given, in the order they were added; after
  // each, the struct is checked, so that an error names the flag that made it.
  void apply(T& options) const {
    for (const Flag& f : flags_) {
      if (!f.value) continue;
      const OptionSource source{"command line", f.name};
      for (const auto& path : f.paths) set_option(options, path, *f.value, source);
      get_option_table<T>().check(options, source);
    }
  }

 private:
  struct Flag {
    std::string name;
    std::vector<std::string> paths;
    std::optional<nlohmann::json> value;
  };
  std::deque<Flag> flags_;  // a deque: the callbacks hold references to its elements
};

// The footer of a command that reads an options file: every field of T with
// its help, unit, limits and default.
template <class T>
std::string describe_options_file(const std::string& intro) {
  return "\n" + intro + "\n" + format_option_docs(describe_options<T>());
}

}  // namespace rcm::cli
