// rcm: sensorless RCM misalignment estimation for the dVRK PSM.
// Subcommands register themselves (command_registry.hpp); main only orders
// them, runs CLI11, and turns exceptions into messages and exit codes:
// 0 success, 2 bad input (located message), 1 anything else.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <iostream>

#include "command_registry.hpp"
#include "rcm/common/error.hpp"

int main(int argc, char** argv) {
  CLI::App app{"rcm " RCM_VERSION
               " -- how far the remote center of motion of a dVRK PSM has drifted from the "
               "incision, from joint torques alone (Yang et al., Sensorless RCM Misalignment Estimation)"};
  app.set_version_flag("--version", std::string("rcm ") + RCM_VERSION);
  app.require_subcommand(1);
  app.fallthrough(false);

  std::vector<rcm::cli::CommandRegistration> commands = rcm::cli::get_registered_commands();
  std::stable_sort(commands.begin(), commands.end(),
                   [](const auto& a, const auto& b) { return a.order < b.order; });
  for (const auto& command : commands) command.add(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const rcm::InputError& e) {
    std::cerr << "rcm: error: " << e.what() << std::endl;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "rcm: error: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
