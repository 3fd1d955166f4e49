#pragma once
// Shared by the live nodes' end-to-end tests (ROS 1, DDS): what `rcm monitor
// --json` on the same recording says the node's latched topics must go
// through, and the node's own log lines worth showing in the test output.

#include <nlohmann/json.hpp>

#include <initializer_list>
#include <iostream>
#include <string>
#include <vector>

namespace rcm::test {

// The alarm topic: false at start, then true at each alarm and false at each clearing.
inline std::vector<bool> get_expected_alarm(const nlohmann::json& monitor) {
  std::vector<bool> alarm = {false};
  for (const auto& a : monitor["alarms"]) {
    alarm.push_back(true);
    if (!a["cleared_s"].is_null()) alarm.push_back(false);
  }
  return alarm;
}

// The onset topic: false at start, true once if the monitor saw an onset.
inline std::vector<bool> get_expected_onset(const nlohmann::json& monitor) {
  return monitor["onset_s"].is_null() ? std::vector<bool>{false} : std::vector<bool>{false, true};
}

// Prints the node's log lines that contain each key ("[ node log ] ...").
inline void print_node_log_lines(const std::string& log, std::initializer_list<const char*> keys) {
  for (const char* key : keys) {
    const auto p = log.find(key);
    if (p == std::string::npos) continue;
    const auto b = log.rfind('\n', p) + 1, e = log.find('\n', p);
    std::cout << "[ node log ] " << log.substr(b, e - b) << "\n";
  }
}

}  // namespace rcm::test
