#include "rcm/common/interrupt.hpp"

#include <atomic>
#include <csignal>
#include <cstring>

namespace rcm {
namespace {

// Lock-free, so that storing from a signal handler is async-signal-safe.
std::atomic<int> g_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the interrupt flag must be lock-free");

extern "C" void on_interrupt_signal(int signal_number) { g_signal.store(signal_number, std::memory_order_relaxed); }

}  // namespace

void install_interrupt_handlers() {
  struct sigaction action;
  std::memset(&action, 0, sizeof action);
  action.sa_handler = on_interrupt_signal;
  sigemptyset(&action.sa_mask);
  // SA_RESETHAND: a second signal takes the default action (the process ends).
  // SA_RESTART: reads and writes in progress are resumed, not failed with EINTR.
  action.sa_flags = SA_RESETHAND | SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

bool is_interrupt_requested() noexcept { return g_signal.load(std::memory_order_relaxed) != 0; }

int get_interrupt_signal() noexcept { return g_signal.load(std::memory_order_relaxed); }

void request_interrupt(int signal_number) noexcept { g_signal.store(signal_number, std::memory_order_relaxed); }

void clear_interrupt() noexcept { g_signal.store(0, std::memory_order_relaxed); }

void throw_if_interrupted(const std::string& doing) {
  if (is_interrupt_requested()) throw Interrupted("interrupted while " + doing);
}

std::string get_signal_name(int signal_number) {
  switch (signal_number) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    default: return "signal " + std::to_string(signal_number);
  }
}

}  // namespace rcm
