#pragma once
// The exit status of a command line the parser refuses, one rule for every
// rcm program: bad input like any other (status 2, docs/reliability.md), not
// the parser's own codes; --help and --version still exit 0. Header-only, for
// the programs (the library does not parse command lines).
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"

namespace rcm {

inline int exit_on_parse_error(const CLI::App& app, const CLI::ParseError& e) {
  const int code = app.exit(e);  // prints the message or the help
  return code == 0 ? 0 : 2;
}

// The flag of an options field: "stall_s" -> "--stall-s".
inline std::string get_flag_name(const std::string& field) {
  std::string f = "--" + field;
  for (char& c : f)
    if (c == '_') c = '-';
  return f;
}

// A flag's comma-separated numbers ("0.05,0.05,0.005"): InputError at
// `where` for an empty cell, a cell that is not a whole number, or NaN/inf.
inline std::vector<double> parse_number_list(const std::string& text, const InputLocation& where) {
  std::vector<double> v;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find(',', start);
    if (end == std::string::npos) end = text.size();
    const std::string cell = text.substr(start, end - start);
    char* stop = nullptr;
    const double x = std::strtod(cell.c_str(), &stop);
    if (cell.empty() || !stop || *stop != '\0' || !std::isfinite(x))
      throw InputError(where, "expected numbers separated by commas, got '" + text + "'");
    v.push_back(x);
    start = end + 1;
  }
  return v;
}

}  // namespace rcm
