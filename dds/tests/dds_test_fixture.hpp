#pragma once
// Shared by the DDS tests: the fixture's simulated session (CTest fixture
// dds_test_session) and running the rcm CLI for the reference answers.

#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <string>

namespace rcm::test {

inline const std::filesystem::path kFixture = RCM_DDS_TEST_DIR;
inline const std::filesystem::path kSession = kFixture / "session" / "session.json";
inline const std::filesystem::path kModel = kFixture / "model.json";
inline const std::filesystem::path kTrial = kFixture / "session" / "D30_r10_15.csv";  // a hybrid offset, forces above 10 N

struct CliResult {
  int status;
  std::string out;
};
// `rcm ARGS`, stdout only.
inline CliResult run_cli(const std::string& args) {
  FILE* p = popen((std::string(RCM_CLI_PATH) + " " + args + " 2>/dev/null").c_str(), "r");
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

}  // namespace rcm::test
