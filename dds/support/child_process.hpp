#pragma once
// The programs rcm_procedure_dds runs (rcm excite, rcm setup, rcm_monitor_dds):
// each in its own process group with its output in a log file, stopped with it
// (PR_SET_PDEATHSIG) should the procedure die.

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace rcm::dds_node {

class Child {
 public:
  // Starts `args` (args[0] a path) with stdout and stderr into `log`; throws
  // std::runtime_error when it cannot start.
  Child(const std::vector<std::string>& args, const std::filesystem::path& log);
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  ~Child();  // SIGINT, then SIGKILL after 5 s, if still running

  bool alive();
  // The exit code (or -signal) once it ended within `timeout`; kStillRunning otherwise.
  int wait(std::chrono::milliseconds timeout);
  // SIGINT, then SIGKILL after `grace`; the exit code, or -signal.
  int stop(std::chrono::milliseconds grace);
  std::string log() const;
  static constexpr int kStillRunning = -1000;

 private:
  std::filesystem::path log_;
  pid_t pid_ = -1;
  bool exited_ = false;
  int status_ = 0;
};

// Runs `args` to its end, or stops it once `interrupted()`; its exit code (or
// -signal). Its output goes to `log`.
int run_child(const std::vector<std::string>& args, const std::filesystem::path& log,
              const std::function<bool()>& interrupted);

// The directory of the running program (/proc/self/exe), where rcm's other
// programs are installed beside it.
std::filesystem::path get_program_directory();

}  // namespace rcm::dds_node
