#pragma once
// rcm_monitor_dds's parameters from a ROS 2 parameters file (YAML), read before
// the flags so that the flags override it (docs/howto-ros2.md).

#include <string>

#include "rcm/common/error.hpp"
#include "rcm/live/monitor_node.hpp"

namespace rcm::dds_node {

rcm::InputLocation param_location(const std::string& file, const std::string& name);

// A ROS 2 parameters file: `<node>:` or `/**:`, then `ros__parameters:`. Throws
// InputError naming the file and the parameter for an unknown name or a wrong type.
void read_params_file(const std::string& file, const std::string& node_name, rcm::MonitorNodeParameters& p);

// The value of `--params-file` before CLI11 parses, so that the file's values
// become the flags' defaults and every flag given overrides them.
std::string find_params_file(int argc, char** argv);

}  // namespace rcm::dds_node
