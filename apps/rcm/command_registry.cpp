#include "command_registry.hpp"

namespace rcm::cli {
namespace {
std::vector<CommandRegistration>& registry() {
  static std::vector<CommandRegistration> commands;  // function-local: safe across TUs
  return commands;
}
}  // namespace

bool register_command(CommandRegistration registration) {
  registry().push_back(std::move(registration));
  return true;
}

const std::vector<CommandRegistration>& get_registered_commands() { return registry(); }

}  // namespace rcm::cli
