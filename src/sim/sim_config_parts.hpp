#pragma once
// Internal to the sim layer: what the files of the simulator's configuration
// share (sim_config.cpp: the field table, JSON and help; sim_presets.cpp: the
// defaults and presets; sim_config_check.cpp: validate_config).

#include <string>

namespace rcm::sim::detail {

// The JSON keys of the three friction joints.
inline const char* const kJointKeys[3] = {"yaw", "pitch", "insertion"};

// Throws InputError at `source`, JSON field `field`.
[[noreturn]] void fail_config_field(const std::string& source, const std::string& field, const std::string& what);

}  // namespace rcm::sim::detail
