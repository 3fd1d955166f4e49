#pragma once
// The exit status of a command line the parser refuses, one rule for every
// rcm program: bad input like any other (status 2, docs/reliability.md), not
// the parser's own codes; --help and --version still exit 0. Header-only, for
// the programs (the library does not parse command lines).
#include <CLI/CLI.hpp>

namespace rcm {

inline int exit_on_parse_error(const CLI::App& app, const CLI::ParseError& e) {
  const int code = app.exit(e);  // prints the message or the help
  return code == 0 ? 0 : 2;
}

}  // namespace rcm
