#pragma once
// Shared by the DDS tests: the fixture's simulated session (CTest fixture
// live_test_session) and running the rcm CLI for the reference answers.

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

// The node logs this line once its subscription has matched a writer of the
// joint states. A writer's own "matched" status says only that it has found the
// node's reader: discovery runs both ways on its own, and until the node has
// found the writer, the reliable reader drops what the writer sends (seconds
// of samples on an instrumented build). Publish only once both sides have
// matched.
inline bool node_matched_joint_states(const std::string& node_log) {
  return node_log.find("1 publisher(s) matched on rt/PSM1/measured_js") != std::string::npos;
}

}  // namespace rcm::test
