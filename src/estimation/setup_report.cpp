// How a SetupReport is printed (`rcm setup`) and serialised (--json, setup.json).
#include <fmt/format.h>

#include <cmath>

#include "rcm/estimation/setup.hpp"

namespace rcm {
namespace {

nlohmann::json errors_json(const std::vector<dynamics::JointTorqueError>& errors) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& e : errors) {
    nlohmann::json j = {{"index", e.index}, {"rmse", e.rmse}, {"nrmse_percent", e.nrmse_percent}};
    if (std::isfinite(e.robust_sd)) j["robust_sd"] = e.robust_sd;
    out.push_back(std::move(j));
  }
  return out;
}

std::string rmse_text(const std::vector<dynamics::JointTorqueError>& errors) {
  std::string out;
  for (const auto& e : errors)
    if (e.index >= 1 && e.index <= 3) out += (out.empty() ? "" : " / ") + fmt::format("{:.3f}", e.rmse);
  return out;
}

}  // namespace

nlohmann::json SetupReport::to_json() const {
  nlohmann::json j;
  j["ready"] = ready;
  j["robot"] = robot;
  j["robot_time_s"] = {{"free_space", free_space_s},
                       {"baseline", baseline_s},
                       {"calibration", calibration_s},
                       {"total", get_robot_seconds()}};
  j["compute_s"] = compute_s;
  j["findings"] = nlohmann::json::array();
  for (const auto& f : findings)
    j["findings"].push_back({{"check", f.check}, {"severity", to_string(f.severity)}, {"message", f.message}});
  j["joints"] = nlohmann::json::array();
  for (const auto& c : joints)
    j["joints"].push_back({{"name", c.name},
                           {"position_range", {c.position_min, c.position_max}},
                           {"wanted_range", {c.wanted_min, c.wanted_max}},
                           {"speed_max", c.speed_max},
                           {"calibration_speed_max", c.calibration_speed_max},
                           {"reversals", c.reversals}});
  nlohmann::json model{{"kind", dynamics::to_string(free_space.kind)},
                       {"test_errors", errors_json(free_space.errors)},
                       {"force_error_n", force_error_n},
                       {"check_offset_m", check_offset_m},
                       {"check_pivot_rad", check_pivot_rad},
                       {"seconds", free_space.seconds}};
  model["fit"] = free_space.fit ? free_space.fit->to_json() : nlohmann::json(nullptr);
  j["model"] = model;
  j["learning_curve"] = nlohmann::json::array();
  for (const auto& p : curve)
    j["learning_curve"].push_back(
        {{"fraction", p.fraction}, {"seconds_of_data", p.seconds_of_data}, {"test_errors", errors_json(p.errors)}});
  if (has_calibration) {
    nlohmann::json cal{{"pivot_max_rad", calibration_pivot_max_rad}, {"regime", calibration_regime.to_json()}};
    cal["self_check_error_m"] = calibration_error_m ? nlohmann::json(*calibration_error_m) : nlohmann::json(nullptr);
    if (tissue) {
      cal["tissue"] = {{"family", tissue->family},
                       {"parameters", {tissue->parameters[0], tissue->parameters[1], tissue->parameters[2],
                                       tissue->parameters[3]}},
                       {"calibration_bias_m",
                        {tissue->calibration_bias_m[0], tissue->calibration_bias_m[1], tissue->calibration_bias_m[2]}}};
    }
    j["calibration"] = cal;
  } else {
    j["calibration"] = nullptr;
  }
  return j;
}

std::string SetupReport::to_text() const {
  std::size_t missing = 0;
  for (const auto& f : findings) missing += f.severity == SetupSeverity::missing;
  std::string out = ready ? "ready" : fmt::format("not ready: {} thing{} missing", missing, missing == 1 ? "" : "s");
  out += fmt::format("\nrobot time {:.0f} s (free space {:.0f} s, baseline {:.0f} s, calibration {:.0f} s); "
                     "computed in {:.1f} s\n",
                     get_robot_seconds(), free_space_s, baseline_s, calibration_s, compute_s);
  for (const auto& f : findings) out += fmt::format("  {:<8} {}\n", to_string(f.severity), f.message);
  if (ready) {
    out += fmt::format("expected accuracy: the free-space model's error is {:.1f} N at the incision", force_error_n);
    if (calibration_error_m)
      out += fmt::format("; on the calibration the offset comes out {:.2f} mm from the known one",
                         *calibration_error_m * 1e3);
    out += "\n";
  }
  if (!curve.empty()) {
    out += "learning curve on this free space (held-out RMSE yaw / pitch (N m) / insertion (N)):\n";
    for (const auto& p : curve)
      out += fmt::format("  {:>6.0f} s of data: {}\n", p.seconds_of_data, rmse_text(p.errors));
  }
  return out;
}

}  // namespace rcm
