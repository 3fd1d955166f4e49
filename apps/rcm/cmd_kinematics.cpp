// rcm kinematics: frame 3, z3, theta and the incision-port Jacobian J_D.

#include <fmt/format.h>

#include <cmath>
#include <iostream>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace {
namespace cmd_kinematics {

struct Options {
  std::string q, q0 = "0,0,0.12", robot = "dvrk-psm-classic";
  double offset = 0.0;
  bool json = false;
};

void run(const Options& o) {
  const rcm::PsmModel model = rcm::load_robot_model(o.robot, "--robot");
  const Eigen::Vector3d q = rcm::cli::parse_vector3(o.q, "--q");
  const Eigen::Vector3d q0 = rcm::cli::parse_vector3(o.q0, "--q0");
  model.check_within_limits(q, rcm::cli::flag_location("--q"));
  model.check_within_limits(q0, rcm::cli::flag_location("--q0"));

  rcm::KinematicsData data;
  rcm::compute_forward_kinematics(model, data, q);
  const Eigen::Isometry3d& X_base_3 = rcm::get_frame_pose(data, 3);
  const rcm::IncisionFrame incision = rcm::make_incision_frame(q0);
  const double theta = rcm::compute_pivot_angle(incision, q);
  const double s = rcm::compute_shaft_distance(incision, q, o.offset);
  const Eigen::Vector3d z3 = rcm::compute_z3_base(q);
  const rcm::JacobianCondition cond = rcm::compute_incision_jacobian_condition(q, s);
  const bool finite = std::isfinite(s);
  const Eigen::Matrix3d J = finite ? rcm::compute_incision_jacobian(q, s) : Eigen::Matrix3d::Constant(NAN);

  if (o.json) {
    nlohmann::json out;
    out["robot"] = model.name();
    out["q"] = rcm::cli::to_json(q);
    out["q0"] = rcm::cli::to_json(q0);
    out["offset_m"] = o.offset;
    out["z3"] = rcm::cli::to_json(z3);
    out["theta"] = theta;
    out["shaft_distance_m"] = finite ? nlohmann::json(s) : nlohmann::json(nullptr);
    out["frame3"] = {{"position_m", rcm::cli::to_json(X_base_3.translation())},
                     {"rotation_rows", rcm::cli::to_json_rows(X_base_3.linear())}};
    out["J_inc_base"] = finite ? rcm::cli::to_json_rows(J) : nlohmann::json(nullptr);
    out["condition"] = std::isfinite(cond.condition) ? nlohmann::json(cond.condition) : nlohmann::json(nullptr);
    out["status"] = rcm::to_string(cond.status);
    rcm::cli::print_json(out);
    return;
  }
  std::cout << fmt::format("robot      {}\n", model.name());
  std::cout << fmt::format("q          [{:.6f}, {:.6f}, {:.6f}]  (rad, rad, m)\n", q[0], q[1], q[2]);
  std::cout << fmt::format("q0         [{:.6f}, {:.6f}, {:.6f}]\n", q0[0], q0[1], q0[2]);
  std::cout << fmt::format("frame 3    origin [{:.6f}, {:.6f}, {:.6f}] m\n", X_base_3.translation()[0],
                           X_base_3.translation()[1], X_base_3.translation()[2]);
  std::cout << fmt::format("z3         [{:.6f}, {:.6f}, {:.6f}]\n", z3[0], z3[1], z3[2]);
  std::cout << fmt::format("theta      {:.6f} rad ({:.3f} deg)\n", theta, theta * 180.0 / M_PI);
  std::cout << fmt::format("D, D secθ  {:.6f} m, {:.6f} m\n", o.offset, s);
  std::cout << "J_inc_base (rows; columns d/dq1, d/dq2, d/dq3)\n";
  for (int i = 0; i < 3; ++i)
    std::cout << fmt::format("  [{:+.6f}, {:+.6f}, {:+.6f}]\n", J(i, 0), J(i, 1), J(i, 2));
  std::cout << fmt::format("condition  {:.6g}  ({})\n", cond.condition, rcm::to_string(cond.status));
}

const bool registered = rcm::cli::register_command({"kinematics", 17, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "kinematics", "Frame 3, insertion axis z3, pivot angle theta, and the incision-port Jacobian J_D (3x3) with its condition number");
  cmd->add_option("--q", o->q, "joint values q1,q2,q3 (rad, rad, m)")->required();
  cmd->add_option("--q0", o->q0, "docking configuration q0 (default: the paper's home 0,0,0.12)");
  cmd->add_option("--offset", o->offset,
                  "coaxial offset D in m (default 0: the incision at the RCM, where J_D is singular)");
  cmd->add_option("--robot", o->robot, "built-in robot name or rcm-robot/1 JSON file");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_kinematics
}  // namespace
