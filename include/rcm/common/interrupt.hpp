#pragma once
// Cooperative cancellation of long computations (the study's steps, network
// training epochs, Ceres solves, simulated recordings). An application that
// wants Ctrl-C to stop them cleanly installs the handlers; the long loops ask
// is_interrupt_requested() and end early, keeping what they finished, or throw
// Interrupted when nothing usable is left. Without the handlers (and without
// request_interrupt) the flag never becomes true, so library users who do not
// opt in see no change.

#include <stdexcept>
#include <string>

namespace rcm {

// SIGINT and SIGTERM set the flag (an async-signal-safe store) and restore the
// default action, so that a second signal ends the process at once.
void install_interrupt_handlers();

bool is_interrupt_requested() noexcept;
// SIGINT, SIGTERM (or what request_interrupt was given); 0 when not interrupted.
int get_interrupt_signal() noexcept;
// What the signal handler does; also for an embedding application's stop button and for tests.
void request_interrupt(int signal_number) noexcept;
void clear_interrupt() noexcept;

// Thrown where an interrupted computation has nothing usable to return. The
// message says what was stopped ("interrupted while fitting the free-space model").
class Interrupted : public std::runtime_error {
 public:
  explicit Interrupted(const std::string& what) : std::runtime_error(what) {}
};

// Throws Interrupted("interrupted while " + doing) when an interrupt was requested.
void throw_if_interrupted(const std::string& doing);

// "SIGINT", "SIGTERM", or "signal N".
std::string get_signal_name(int signal_number);

}  // namespace rcm
