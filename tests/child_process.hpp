#pragma once
// Child processes and waits for the end-to-end node tests (ROS 1 and DDS):
// every process is stopped on every path (RAII, and PR_SET_PDEATHSIG should
// the test itself die); every wait has a timeout.

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace rcm::test {

// Every wait below is a bound that only stops a hung test, never a speed
// requirement (benchmarks measure speed). Built with AddressSanitizer, rcm's
// own programs run several times slower (the node's start-up tissue
// identification: 5 s -> about 25 s), so the bounds stretch with them.
#if defined(__SANITIZE_ADDRESS__)
inline constexpr int kWaitScale = 6;
#else
inline constexpr int kWaitScale = 1;
#endif

std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A child process in its own process group, output to a log file, stopped
// (SIGINT, then SIGKILL after a grace period) when this object goes away.
class ChildProcess {
 public:
  ChildProcess(const std::vector<std::string>& args, const std::filesystem::path& log) : log_(log) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    const std::string log_path = log.string();
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ == 0) {  // only async-signal-safe calls until exec
      ::setpgid(0, 0);
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (::getppid() != parent) ::_exit(127);
      const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) {
        ::dup2(fd, 1);
        ::dup2(fd, 2);
      }
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    if (pid_ > 0) ::setpgid(pid_, pid_);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;
  ~ChildProcess() { stop(std::chrono::seconds(2)); }

  bool started() const { return pid_ > 0; }
  bool alive() {
    if (pid_ <= 0 || exited_) return false;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      status_ = status;
      return false;
    }
    return true;
  }
  // SIGINT to the group, SIGKILL after `grace`; the exit code, or -signal.
  int stop(std::chrono::milliseconds grace) {
    if (pid_ <= 0) return -1;
    if (alive()) {
      ::kill(-pid_, SIGINT);
      const auto deadline = std::chrono::steady_clock::now() + grace * kWaitScale;
      while (alive() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
      if (alive()) {
        ::kill(-pid_, SIGKILL);
        ::waitpid(pid_, &status_, 0);
        exited_ = true;
      }
    }
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : -WTERMSIG(status_);
  }
  std::string log() const { return read_text(log_); }
  // Sends a signal to the child alone, or to its group (the programs it started too).
  void send(int signal_number, bool group = false) {
    if (alive()) ::kill(group ? -pid_ : pid_, signal_number);
  }
  // The exit code (or -signal) once the child has ended within `timeout`; -1000 while it runs.
  int wait(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout * kWaitScale;
    while (alive() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (alive()) return kStillRunning;
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : -WTERMSIG(status_);
  }
  static constexpr int kStillRunning = -1000;

 private:
  std::filesystem::path log_;
  pid_t pid_ = -1;
  bool exited_ = false;
  int status_ = 0;
};

bool wait_for(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout * kWaitScale;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}


}  // namespace rcm::test
