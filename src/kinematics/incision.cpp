#include "rcm/kinematics/incision.hpp"

#include <cmath>
#include <limits>

#include "rcm/common/options.hpp"

namespace rcm {

IncisionFrame make_incision_frame(const Eigen::Vector3d& q0) {
  IncisionFrame frame;
  frame.q0 = q0;
  frame.R_base_inc = compute_R_base_3(q0);
  return frame;
}

double compute_pivot_angle(const IncisionFrame& incision, const Eigen::Vector3d& q) {
  const Eigen::Vector3d z0 = incision.z_inc_base();
  const Eigen::Vector3d z = compute_z3_base(q);
  return std::atan2(z0.cross(z).norm(), z0.dot(z));
}

double compute_shaft_distance(const IncisionFrame& incision, const Eigen::Vector3d& q, double D) {
  const double cos_theta = incision.z_inc_base().dot(compute_z3_base(q));
  // Parallel to the pad (or beyond): cos(pi/2) rounds to ~6e-17, not 0.
  if (cos_theta <= 1e-12) return std::numeric_limits<double>::infinity();
  return D / cos_theta;
}

Eigen::Matrix3d compute_incision_jacobian(const Eigen::Vector3d& q, double s) {
  const ShaftDirections d = compute_shaft_directions(q);
  Eigen::Matrix3d J;
  J << s * d.dz3_dq1, s * d.get_dz3_dq2(), d.z3;
  return J;
}

Eigen::Matrix3d compute_incision_jacobian_dh(const PsmModel& model, KinematicsData& data,
                                             const Eigen::Vector3d& q, double s) {
  compute_forward_kinematics(model, data, q);
  // Paper Table I, row 'inc': referenced to frame 2, a = 0, alpha = -pi/2,
  // d = -s, theta = 0. Its z axis is -z3, so the origin lies at +s along z3.
  const Eigen::Isometry3d X_base_inc =
      data.X_base_frame[2] * compute_dh_transform(0.0, -M_PI / 2.0, -s, 0.0);
  const Eigen::Vector3d p_inc = X_base_inc.translation();
  Eigen::Matrix3d J;
  for (int i = 0; i < 2; ++i) {
    const Eigen::Isometry3d& X = data.X_base_frame[i + 1];
    J.col(i) = X.linear().col(2).cross(p_inc - X.translation());
  }
  J.col(2) = data.X_base_frame[3].linear().col(2);
  return J;
}

const char* to_string(JacobianStatus status) {
  switch (status) {
    case JacobianStatus::ok: return "ok";
    case JacobianStatus::ill_conditioned: return "ill_conditioned";
    case JacobianStatus::singular: return "singular";
  }
  return "unknown";
}

JacobianCondition compute_incision_jacobian_condition(const Eigen::Vector3d& q, double s,
                                                      const JacobianCheckOptions& options) {
  const double c2 = std::abs(std::cos(q[1]));
  const double a = std::abs(s) * c2, b = std::abs(s);
  const double sigma_max = std::max({a, b, 1.0});
  const double sigma_min = std::min({a, b, 1.0});
  JacobianCondition result;
  if (!std::isfinite(s) || !(sigma_min > 0.0)) {
    result.condition = std::numeric_limits<double>::infinity();
    result.status = JacobianStatus::singular;
    return result;
  }
  result.condition = sigma_max / sigma_min;
  if (!std::isfinite(result.condition) || result.condition > options.singular_condition)
    result.status = JacobianStatus::singular;
  else if (result.condition > options.max_condition)
    result.status = JacobianStatus::ill_conditioned;
  return result;
}

const OptionTable<JacobianCheckOptions>& get_option_table(OptionTag<JacobianCheckOptions>) {
  static const auto table =
      OptionTable<JacobianCheckOptions>("JacobianCheckOptions")
          .add("max_condition", &JacobianCheckOptions::max_condition,
               "2-norm condition number of J_D above which a force estimate is flagged ill-conditioned", "",
               OptionLimits::at_least(1))
          .add("singular_condition", &JacobianCheckOptions::singular_condition,
               "condition number above which J_D is treated as singular", "", OptionLimits::at_least(1))
          .add_check([](const JacobianCheckOptions& o) {
            if (!(o.singular_condition >= o.max_condition))
              throw std::invalid_argument("singular_condition must be >= max_condition");
          });
  return table;
}

}  // namespace rcm
