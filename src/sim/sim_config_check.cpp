// validate_config: every value of a simulator configuration checked against
// its range and against the robot's joint limits, with the JSON path of the
// first bad field.

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "rcm/common/error.hpp"
#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/sim_config.hpp"
#include "sim_config_parts.hpp"

namespace rcm::sim {

using detail::kJointKeys;

void validate_config(const SimConfig& c, const std::string& source) {
  auto require = [&](bool ok, const std::string& field, const std::string& what) {
    if (!ok) detail::fail_config_field(source, field, what);
  };
  auto positive3 = [&](const Eigen::Vector3d& v, const std::string& field, bool allow_zero) {
    for (int j = 0; j < 3; ++j)
      require(std::isfinite(v[j]) && (allow_zero ? v[j] >= 0 : v[j] > 0),
              field + fmt::format("[{}]", j), allow_zero ? "expected >= 0" : "expected > 0");
  };
  require(c.threads >= 1 && c.threads <= 64, "threads", "expected 1..64");
  const std::pair<const RigidBodyParams*, const char*> bodies[] = {
      {&c.arm.yaw_link, "arm.yaw_link"}, {&c.arm.pitch_link, "arm.pitch_link"},
      {&c.arm.insertion_stage, "arm.insertion_stage"}};
  for (const auto& [b, name] : bodies) {
    require(b->mass_kg >= 0, std::string(name) + ".mass_kg", "expected >= 0");
    positive3(b->inertia_diag_kg_m2, std::string(name) + ".inertia_diag_kg_m2", true);
  }
  require(std::isfinite(c.arm.insertion_stiffness_n_per_m) && c.arm.insertion_stiffness_n_per_m >= 0,
          "arm.insertion_stiffness_n_per_m", "expected >= 0");
  require(c.arm.insertion_stage.mass_kg > 0, "arm.insertion_stage.mass_kg",
          "expected > 0 (the insertion axis needs inertia)");
  for (int j = 0; j < 3; ++j) {
    const auto& t = c.arm.transmission[static_cast<std::size_t>(j)];
    const std::string k = std::string("arm.transmission.") + kJointKeys[j];
    require(std::isfinite(t.rotor_inertia) && t.rotor_inertia >= 0, k + ".rotor_inertia", "expected >= 0");
    require(std::isfinite(t.stiffness) && t.stiffness >= 0, k + ".stiffness", "expected >= 0 (0: rigid)");
    require(std::isfinite(t.damping) && t.damping >= 0, k + ".damping", "expected >= 0");
    require(t.friction_link_share >= 0 && t.friction_link_share <= 1, k + ".friction_link_share",
            "expected 0..1");
    if (t.stiffness > 0) {
      require(t.rotor_inertia > 0, k + ".rotor_inertia", "expected > 0 with a compliant cable (stiffness > 0)");
      // Semi-implicit Euler resolves the motor against cable and controller
      // only well below its stability limit dt * omega = 2.
      const double omega = std::sqrt((t.stiffness + c.controller.kp[j]) / t.rotor_inertia);
      const double damping_rate = (t.damping + c.controller.kd[j]) / t.rotor_inertia;
      require(omega / c.controller.physics_rate_hz < 0.5 && damping_rate / c.controller.physics_rate_hz < 0.5,
              k + ".stiffness",
              fmt::format("the motor's fastest mode ({:.0f} rad/s, damping {:.0f} 1/s) is too fast for "
                          "controller.physics_rate_hz = {}: raise the rate or the rotor inertia",
                          omega, damping_rate, c.controller.physics_rate_hz));
    }
  }
  for (int j = 0; j < 3; ++j) {
    const auto& p = c.friction[static_cast<std::size_t>(j)];
    const std::string k = std::string("friction.") + kJointKeys[j];
    // A LuGre element needs both levels; both 0 leaves it out.
    const bool lugre = p.coulomb_pos > 0 || p.coulomb_neg > 0;
    require(lugre ? p.coulomb_pos > 0 : p.coulomb_pos == 0, k + ".coulomb_pos",
            "expected > 0 (or 0 with coulomb_neg: no LuGre element)");
    require(lugre ? p.coulomb_neg > 0 : p.coulomb_neg == 0, k + ".coulomb_neg",
            "expected > 0 (or 0 with coulomb_pos: no LuGre element)");
    require(p.stiction_ratio >= 1.0, k + ".stiction_ratio", "expected >= 1");
    require(p.stribeck_velocity > 0, k + ".stribeck_velocity", "expected > 0");
    require(p.viscous >= 0, k + ".viscous", "expected >= 0");
    require(!lugre || p.bristle_stiffness > 0, k + ".bristle_stiffness", "expected > 0");
    require(p.bristle_damping >= 0, k + ".bristle_damping", "expected >= 0");
    require(p.slip_elements.size() <= static_cast<std::size_t>(kMaxSlipElements), k + ".slip_elements",
            fmt::format("{} elements, at most {} expected", p.slip_elements.size(), kMaxSlipElements));
    for (std::size_t i = 0; i < p.slip_elements.size(); ++i)
      require(p.slip_elements[i][0] > 0 && p.slip_elements[i][1] >= 0 && p.slip_elements[i].allFinite(),
              fmt::format("{}.slip_elements[{}]", k, i),
              "expected [breakaway displacement > 0, force >= 0]");
    require(p.slip_damping >= 0, k + ".slip_damping", "expected >= 0");
  }
  const auto& C = c.controller;
  require(C.physics_rate_hz >= 200 && C.physics_rate_hz <= 1e5, "controller.physics_rate_hz",
          "expected 200..100000 Hz");
  positive3(C.kp, "controller.kp", false);
  positive3(C.kd, "controller.kd", true);
  require(C.velocity_filter_hz > 0, "controller.velocity_filter_hz", "expected > 0");
  require(C.settle_s >= 0, "controller.settle_s", "expected >= 0");
  const auto& S = c.sensors;
  require(S.log_rate_hz > 0 && S.log_rate_hz <= C.physics_rate_hz, "sensors.log_rate_hz",
          "expected > 0 and <= controller.physics_rate_hz");
  const double ratio = C.physics_rate_hz / S.log_rate_hz;
  require(std::abs(ratio - std::round(ratio)) < 1e-9, "sensors.log_rate_hz",
          fmt::format("must divide controller.physics_rate_hz ({} / {} is not an integer)",
                      C.physics_rate_hz, S.log_rate_hz));
  positive3(S.effort_noise, "sensors.effort_noise", true);
  positive3(S.position_quantum, "sensors.position_quantum", true);
  positive3(S.velocity_noise, "sensors.velocity_noise", true);
  positive3(S.velocity_noise_fade, "sensors.velocity_noise_fade", false);
  require(S.force_noise_n >= 0, "sensors.force_noise_n", "expected >= 0");
  require(S.repeat_row_probability >= 0 && S.repeat_row_probability < 1,
          "sensors.repeat_row_probability", "expected 0 <= p < 1");
  const auto& T = c.trajectory;
  positive3(T.amplitude, "trajectory.amplitude", true);
  require(T.min_frequency_hz > 0, "trajectory.min_frequency_hz", "expected > 0");
  require(T.max_frequency_hz >= T.min_frequency_hz && T.max_frequency_hz <= 5.0,
          "trajectory.max_frequency_hz", "expected min_frequency_hz..5 Hz");
  require(T.harmonics >= 1 && T.harmonics <= 64, "trajectory.harmonics", "expected 1..64");
  require(T.segment_s >= 5.0, "trajectory.segment_s", "expected >= 5 s");
  require(T.blend_s > 0.0 && T.blend_s <= 0.5 * T.segment_s, "trajectory.blend_s", "expected 0 < blend_s <= segment_s / 2");
  require(T.pause_fraction >= 0 && T.pause_fraction <= 0.8, "trajectory.pause_fraction", "expected 0..0.8");
  require(T.pause_min_s > 0 && T.pause_max_s >= T.pause_min_s, "trajectory.pause_max_s",
          "expected 0 < pause_min_s <= pause_max_s");
  require(T.max_theta_rad > 0 && T.max_theta_rad < 1.3, "trajectory.max_theta_rad", "expected 0..1.3 rad");
  require(T.free_space_path == "teleoperation" || T.free_space_path == "excitation" || T.free_space_path == "file",
          "trajectory.free_space_path", "expected teleoperation, excitation or file, got '" + T.free_space_path + "'");
  require(T.free_space_path != "file" || !T.free_space_file.empty(), "trajectory.free_space_file",
          "required when trajectory.free_space_path is file: a joint trajectory CSV");
  require(T.excitation_period_s > 0, "trajectory.excitation_period_s", "expected > 0");
  require(T.excitation_harmonics >= 1 && T.excitation_harmonics <= 50, "trajectory.excitation_harmonics",
          "expected 1..50");
  require(T.excitation_ramp_s > 0, "trajectory.excitation_ramp_s", "expected > 0");
  require(T.excitation_falloff >= 0 && T.excitation_falloff <= 4, "trajectory.excitation_falloff", "expected 0..4");
  const auto& X = c.tissue;
  require(X.stiffness_n_per_m >= 0, "tissue.stiffness_n_per_m", "expected >= 0");
  require(X.cubic_n_per_m3 >= 0, "tissue.cubic_n_per_m3", "expected >= 0");
  require(X.damping_n_s_per_m >= 0, "tissue.damping_n_s_per_m", "expected >= 0");
  require(X.axial_friction_n >= 0, "tissue.axial_friction_n", "expected >= 0");
  require(X.axial_bristle_n_per_m > 0, "tissue.axial_bristle_n_per_m", "expected > 0");
  require(X.axial_bristle_damping_n_s_per_m >= 0, "tissue.axial_bristle_damping_n_s_per_m", "expected >= 0");
  require(X.min_pad_cosine > 0 && X.min_pad_cosine < 1, "tissue.min_pad_cosine", "expected 0..1");

  const auto& P = c.protocol;
  // Joint limits come from the robot description, never from this file.
  const PsmModel robot = load_robot_model(c.robot, source + ": field robot");
  {
    InputLocation where;
    where.file = source;
    where.field = "protocol.q0";
    where.kind = InputLocation::Kind::json_field;
    robot.check_within_limits(P.q0, where);
  }
  for (int j = 0; j < 3; ++j) {
    const auto& lim = robot.joints()[static_cast<std::size_t>(j)];
    const std::string field = fmt::format("trajectory.amplitude[{}]", j);
    require(P.q0[j] - T.amplitude[j] >= lim.q_min && P.q0[j] + T.amplitude[j] <= lim.q_max, field,
            fmt::format("q0 +- amplitude leaves the joint range [{}, {}] of {}", lim.q_min, lim.q_max,
                        lim.name));
    const double b = P.baseline_start_offset[j];
    require(P.q0[j] + b >= lim.q_min && P.q0[j] + b <= lim.q_max,
            fmt::format("protocol.baseline_start_offset[{}]", j), "start pose outside the joint range");
  }
  // The largest pivot angle of the teleoperation box is at one of its corners.
  const auto z3 = [](double q1, double q2) { return compute_z3_base(Eigen::Vector3d(q1, q2, 0.0)); };
  const Eigen::Vector3d n = z3(P.q0[0], P.q0[1]);
  double min_cos = 1.0;
  for (int a = -1; a <= 1; a += 2)
    for (int b = -1; b <= 1; b += 2)
      min_cos = std::min(min_cos, n.dot(z3(P.q0[0] + a * T.amplitude[0], P.q0[1] + b * T.amplitude[1])));
  require(std::acos(std::clamp(min_cos, -1.0, 1.0)) <= T.max_theta_rad, "trajectory.amplitude",
          fmt::format("the ranges reach a pivot angle of {:.1f} deg, above trajectory.max_theta_rad ({:.1f} deg)",
                      std::acos(std::clamp(min_cos, -1.0, 1.0)) * 180 / M_PI, T.max_theta_rad * 180 / M_PI));
  require(min_cos >= X.min_pad_cosine, "trajectory.amplitude",
          "the ranges bring the shaft flatter to the pad than tissue.min_pad_cosine");
  require(P.free_space_s > 0, "protocol.free_space_s", "expected > 0");
  require(P.free_space_files >= 1 && P.free_space_files <= 100, "protocol.free_space_files", "expected 1..100");
  require(P.baseline_approach_s > 0, "protocol.baseline_approach_s", "expected > 0");
  require(P.baseline_hold_s > 0, "protocol.baseline_hold_s", "expected > 0");
  require(P.calibration_s > 0, "protocol.calibration_s", "expected > 0");
  require(P.trial_s > 0, "protocol.trial_s", "expected > 0");
  require(P.trial_paths == "own" || P.trial_paths == "shared", "protocol.trial_paths",
          "expected own or shared, got '" + P.trial_paths + "'");
  require(P.static_return_s > 0, "protocol.static_return_s", "expected > 0");
  require(P.static_hold_s > 0, "protocol.static_hold_s", "expected > 0");
  require(P.static_approaches >= 1 && P.static_approaches <= 8, "protocol.static_approaches", "expected 1..8");
  positive3(P.static_approach_offset, "protocol.static_approach_offset", false);
  auto check_offset = [&](double D, const std::string& field) {
    require(D >= -0.02 && D <= 0.07, field, "expected a coaxial offset in [-0.02, 0.07] m");
    // The shaft must reach the pad: the tip is at about q3 along z3.
    require(std::abs(D) / std::max(min_cos, 1e-6) < P.q0[2] - T.amplitude[2], field,
            fmt::format("the pad (up to {:.3f} m along the shaft) lies beyond the shallowest insertion {:.3f} m",
                        std::abs(D) / std::max(min_cos, 1e-6), P.q0[2] - T.amplitude[2]));
  };
  check_offset(P.calibration_offset_m, "protocol.calibration_offset_m");
  for (std::size_t i = 0; i < P.coaxial_offsets_m.size(); ++i)
    check_offset(P.coaxial_offsets_m[i], fmt::format("protocol.coaxial_offsets_m[{}]", i));
  for (std::size_t i = 0; i < P.radial_offsets_m.size(); ++i)
    require(P.radial_offsets_m[i].norm() <= 0.045, fmt::format("protocol.radial_offsets_m[{}]", i),
            "expected a radial offset within the 9 x 9 cm pad (|r| <= 0.045 m)");
  const auto& V = c.speed;
  require(V.duration_s > 0, "speed.duration_s", "expected > 0");
  require(V.slowdown >= 1 && V.slowdown <= 20, "speed.slowdown", "expected 1..20");
  require(V.period_s > 0, "speed.period_s", "expected > 0");
  require(V.harmonics >= 1 && V.harmonics <= 50, "speed.harmonics", "expected 1..50");
  require(V.ramp_s > 0, "speed.ramp_s", "expected > 0");
  positive3(V.amplitude, "speed.amplitude", false);
  require(V.falloff >= 0 && V.falloff <= 4, "speed.falloff", "expected 0..4");
  const auto& F = c.force_angle;
  require(F.pivot_joint == 1 || F.pivot_joint == 2, "force_angle.pivot_joint", "expected 1 or 2");
  require(F.move_s > 0 && F.hold_s > 0, "force_angle.hold_s", "expected move_s, hold_s > 0");
  require(F.average_s > 0 && F.average_s <= F.hold_s, "force_angle.average_s", "expected 0 < average_s <= hold_s");
  require(!F.offsets_m.empty() && !F.angles_deg.empty(), "force_angle.offsets_m", "expected at least one offset and angle");
  for (std::size_t i = 0; i < F.angles_deg.size(); ++i) {
    const double a = F.angles_deg[i] * M_PI / 180.0;
    const auto& lim = robot.joints()[static_cast<std::size_t>(F.pivot_joint - 1)];
    require(P.q0[F.pivot_joint - 1] + a >= lim.q_min && P.q0[F.pivot_joint - 1] + a <= lim.q_max &&
                std::cos(a) >= X.min_pad_cosine && std::abs(a) <= T.max_theta_rad + 1e-12,
            fmt::format("force_angle.angles_deg[{}]", i),
            "angle outside the joint range or beyond trajectory.max_theta_rad");
  }
  for (std::size_t i = 0; i < F.offsets_m.size(); ++i)
    require(F.offsets_m[i] >= -0.02 && F.offsets_m[i] <= 0.07 &&
                std::abs(F.offsets_m[i]) / 0.5 < P.q0[2],  // cos(60 deg) = 0.5
            fmt::format("force_angle.offsets_m[{}]", i), "expected [-0.02, 0.07] m, within the insertion depth");
}

void validate_speed_experiment(const SimConfig& c, const std::string& source) {
  validate_config(c, source);
  const PsmModel robot = load_robot_model(c.robot, source + ": field robot");
  for (int j = 0; j < 3; ++j) {
    const auto& lim = robot.joints()[static_cast<std::size_t>(j)];
    const double q0 = c.protocol.q0[j], a = c.speed.amplitude[j];
    if (q0 - a < lim.q_min || q0 + a > lim.q_max)
      detail::fail_config_field(source, fmt::format("speed.amplitude[{}]", j),
                                fmt::format("q0 +- speed.amplitude leaves the joint range [{}, {}] of {}",
                                            lim.q_min, lim.q_max, lim.name));
  }
}

}  // namespace rcm::sim
