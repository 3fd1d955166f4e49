#pragma once
// `rcm` run from a test as a user runs it: its exit status and what it printed.

#include <sys/wait.h>

#include <cstdio>
#include <memory>
#include <string>

namespace rcm::test {

enum class CliOutput { stdout_and_stderr, stdout_only };

// RCM_CLI_PATH with `args` (a shell command line); `out` receives the output.
inline int run_cli(const std::string& args, std::string& out, CliOutput which = CliOutput::stdout_and_stderr) {
  const std::string cmd =
      std::string(RCM_CLI_PATH) + " " + args + (which == CliOutput::stdout_only ? " 2>/dev/null" : " 2>&1");
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  out.clear();
  char buf[4096];
  while (std::size_t n = fread(buf, 1, sizeof buf, pipe.get())) out.append(buf, n);
  const int status = pclose(pipe.release());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace rcm::test
