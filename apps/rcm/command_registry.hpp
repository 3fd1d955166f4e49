#pragma once
// Each `rcm` subcommand lives in its own apps/rcm/cmd_*.cpp and registers itself
// at static-initialization time, so adding a command touches no shared file:
//
//   static const bool registered = rcm::cli::register_command(
//       {"simulate", 20, [](CLI::App& app) { auto* cmd = app.add_subcommand(...); ... }});
//
// The callback a command installs may throw rcm::InputError (exit 2, located
// message) or any std::exception (exit 1). Results go to stdout, progress to stderr.

#include <CLI/CLI.hpp>
#include <functional>
#include <string>
#include <vector>

namespace rcm::cli {

struct CommandRegistration {
  std::string name;
  int order = 100;  // position in `rcm --help`; each command its own (ties fall back to the name)
  std::function<void(CLI::App& root)> add;
};

bool register_command(CommandRegistration registration);
const std::vector<CommandRegistration>& get_registered_commands();

}  // namespace rcm::cli
