// rcm_monitor_dds's parameters file (dds_params.hpp).

#include "dds_params.hpp"

#include <yaml-cpp/yaml.h>

#include <vector>

namespace rcm::dds_node {

rcm::InputLocation param_location(const std::string& file, const std::string& name) {
  return rcm::InputLocation::plain(file, name);
}

void read_params_file(const std::string& file, const std::string& node_name, rcm::MonitorNodeParameters& p) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(file);
  } catch (const YAML::Exception& e) {
    rcm::InputLocation where = param_location(file, "");
    if (e.mark.line >= 0) where.line = static_cast<std::size_t>(e.mark.line) + 1;
    throw rcm::InputError(where, "not a readable YAML parameters file: " + e.msg);
  }
  YAML::Node params;
  for (const std::string& key : {node_name, "/" + node_name, std::string("/**")})
    if (root[key] && root[key]["ros__parameters"]) params = root[key]["ros__parameters"];
  if (!params || !params.IsMap())
    throw rcm::InputError(param_location(file, node_name + ".ros__parameters"),
                          "missing: a ROS 2 parameters file has '" + node_name + ":' (or '/**:') then "
                          "'ros__parameters:'");
  for (const auto& kv : params) {
    const std::string name = kv.first.as<std::string>();
    const YAML::Node& v = kv.second;
    const rcm::InputLocation where = param_location(file, node_name + ".ros__parameters." + name);
    try {
      if (name == "session") p.session = v.as<std::string>();
      else if (name == "model_file") p.model_file = v.as<std::string>();
      else if (name == "tissue_model_file") p.tissue_model_file = v.as<std::string>();
      else if (name == "arm") p.arm = v.as<std::string>();
      else if (name == "joint_names")
        p.joint_names = v.IsSequence() ? v.as<std::vector<std::string>>()
                                       : rcm::parse_joint_names(v.as<std::string>(), where);
      else if (name == "alarm_force_n") p.alarm_force_n = v.as<double>();
      else if (name == "onset_threshold") p.onset_threshold = v.as<double>();
      else if (name == "publish_every") p.publish_every = v.as<int>();
      else if (name == "queue_size") p.queue_size = v.as<int>();
      else if (name == "base_frame") p.base_frame = v.as<std::string>();
      else if (name == "incision_frame") p.incision_frame = v.as<std::string>();
      else if (name == "dedupe") p.dedupe = v.as<bool>();
      else if (name == "seed") p.seed = v.as<int>();
      else if (name == "status_period_s") p.status_period_s = v.as<double>();
      else if (name == "tolerance_m") p.correction.tolerance_m = v.as<double>();
      else if (name == "compensate_limit_m") p.correction.compensate_limit_m = v.as<double>();
      else if (name == "max_shift_rate_m_per_s") p.correction.max_rate_m_per_s = v.as<double>();
      else if (name == "jump_threshold") p.jump_threshold = v.as<double>();
      else if (name == "software_rcm") p.software_rcm = v.as<bool>();
      else throw rcm::InputError(where, "unknown parameter");
    } catch (const YAML::Exception& e) {
      throw rcm::InputError(where, "wrong type: " + e.msg);
    }
  }
}

std::string find_params_file(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--params-file" && i + 1 < argc) return argv[i + 1];
    if (a.rfind("--params-file=", 0) == 0) return a.substr(14);
  }
  return {};
}

}  // namespace rcm::dds_node
