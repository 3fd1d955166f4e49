// rcm: sensorless RCM misalignment estimation for the dVRK PSM.
// Subcommands register themselves (command_registry.hpp); main only orders
// them, runs CLI11, and turns exceptions into messages and exit codes:
// 0 success, 2 bad input (located message), 3 a check that found the arm not
// ready (`rcm setup`), 1 anything else, 128 + the
// signal (130 SIGINT, 143 SIGTERM) when a command that installs the interrupt
// handlers (run, dynamics fit, simulate, demo) was stopped by one.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <csignal>
#include <iostream>
#include <tuple>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/command_line.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"

int main(int argc, char** argv) {
  CLI::App app{"rcm " RCM_VERSION
               " -- how far the remote center of motion of a dVRK PSM has drifted from the "
               "incision, from joint torques alone (Yang et al., Sensorless RCM Misalignment Estimation)"};
  app.set_version_flag("--version", std::string("rcm ") + RCM_VERSION);
  app.require_subcommand(1);
  app.fallthrough(false);

  std::vector<rcm::cli::CommandRegistration> commands = rcm::cli::get_registered_commands();
  // Static initialization runs in a different order in a unity build: the name
  // breaks ties so `rcm --help` and the generated reference never depend on it.
  std::sort(commands.begin(), commands.end(), [](const auto& a, const auto& b) {
    return std::tie(a.order, a.name) < std::tie(b.order, b.name);
  });
  for (const auto& command : commands) command.add(app);

  // The interrupted command's message says what it saved and what it did not.
  auto interrupted = [](const std::string& what) {
    const int signal_number = rcm::get_interrupt_signal() != 0 ? rcm::get_interrupt_signal() : SIGINT;
    std::cerr << "rcm: " << rcm::get_signal_name(signal_number) << ": " << what << std::endl;
    return 128 + signal_number;
  };
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return rcm::exit_on_parse_error(app, e);
  } catch (const rcm::Interrupted& e) {
    return interrupted(e.what());
  } catch (const rcm::cli::ExitStatus& e) {
    return e.code;
  } catch (const rcm::InputError& e) {
    std::cerr << "rcm: error: " << e.what() << std::endl;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "rcm: error: " << e.what() << std::endl;
    return 1;
  }
  if (rcm::is_interrupt_requested()) return interrupted("received after the work was done; the outputs were written whole");
  return 0;
}
