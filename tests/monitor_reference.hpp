#pragma once
// Shared by the live nodes' end-to-end tests (ROS 1, DDS): what `rcm monitor
// --json` on the same recording says the node's latched topics must go
// through, and the node's own log lines worth showing in the test output.

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>

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

// The advice topic: the hold before any sample, then each change rcm monitor saw.
inline std::vector<std::string> get_expected_advice(const nlohmann::json& monitor) {
  std::vector<std::string> advice = {"hold: no misalignment detected"};
  for (const auto& c : monitor["correction"]["changes"]) advice.push_back(c["advice"].get<std::string>());
  return advice;
}

// The correction topic's last vector: rcm monitor's final move, base frame.
inline void expect_final_correction(const nlohmann::json& monitor, const double (&move_base)[3]) {
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(move_base[i], monitor["correction"]["move_base_m"][i].get<double>(), 1e-9) << "correction " << i;
}

// The samples `rcm monitor` estimated: all but those of the model's delay at
// the end (its "estimates"); the first that many were.
inline std::size_t get_expected_estimates(const nlohmann::json& monitor) {
  return monitor["estimates"].get<std::size_t>();
}

// Every one of the `samples` accepted, each estimate answered once on the three
// estimate topics (as many as `rcm monitor` estimated), the `injected` bad
// messages counted on rejected_samples and in the exit summary, none missing.
inline void expect_every_sample_answered(const std::string& log, const nlohmann::json& monitor, std::size_t samples,
                                         std::size_t injected, std::size_t estimates, std::size_t sds,
                                         std::size_t forces, std::uint64_t rejected) {
  const std::size_t expected = get_expected_estimates(monitor);
  EXPECT_EQ(estimates, expected);
  EXPECT_EQ(sds, expected);
  EXPECT_EQ(forces, expected);
  EXPECT_EQ(rejected, injected);
  EXPECT_NE(log.find(std::to_string(samples) + " samples accepted, " + std::to_string(injected) + " rejected"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("; 0 missing in 0 gap(s)"), std::string::npos) << log;  // none lost on the way
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
