// Kinematics of the PSM and the incision-port Jacobian J_D (paper III-A).
#include <gtest/gtest.h>

#include <Eigen/SVD>
#include <cmath>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>

#include "rcm/common/error.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace {

const rcm::PsmModel& model() {
  static const rcm::PsmModel m = rcm::load_robot_model("dvrk-psm-classic");
  return m;
}

struct Sample {
  Eigen::Vector3d q, q0;
  double D;
};

// Random configurations within the joint limits with D in [-20, 70] mm, the
// estimator's bounds. theta is kept below 75 deg where sec(theta) is moderate.
std::vector<Sample> random_samples(int n, unsigned seed) {
  std::mt19937 rng(seed);
  const auto& j = model().joints();
  std::uniform_real_distribution<double> q1(j[0].q_min, j[0].q_max), q2(j[1].q_min, j[1].q_max),
      q3(j[2].q_min, j[2].q_max), D(-0.020, 0.070);
  std::vector<Sample> out;
  while (static_cast<int>(out.size()) < n) {
    Sample s{{q1(rng), q2(rng), q3(rng)}, {q1(rng) * 0.3, q2(rng) * 0.3, q3(rng)}, D(rng)};
    const rcm::IncisionFrame inc = rcm::make_incision_frame(s.q0);
    if (rcm::compute_pivot_angle(inc, s.q) < 75.0 * M_PI / 180.0) out.push_back(s);
  }
  return out;
}

// Position of the shaft's material point that sits at distance s from the RCM
// at configuration q_ref, seen at configuration q: the shaft slides with q3.
Eigen::Vector3d shaft_point(const Eigen::Vector3d& q, const Eigen::Vector3d& q_ref, double s) {
  return (s + (q[2] - q_ref[2])) * rcm::compute_z3_base(q);
}

Eigen::Matrix3d finite_difference_jacobian(const Eigen::Vector3d& q, double s, double h) {
  Eigen::Matrix3d J;
  for (int i = 0; i < 3; ++i) {
    Eigen::Vector3d qp = q, qm = q;
    qp[i] += h;
    qm[i] -= h;
    J.col(i) = (shaft_point(qp, q, s) - shaft_point(qm, q, s)) / (2 * h);
  }
  return J;
}

TEST(Kinematics, DhChainReproducesContractFrame3) {
  rcm::KinematicsData data;
  for (const auto& s : random_samples(200, 1)) {
    rcm::compute_forward_kinematics(model(), data, s.q);
    const Eigen::Isometry3d& X = rcm::get_frame_pose(data, 3);
    EXPECT_LT((X.linear() - rcm::compute_R_base_3(s.q)).norm(), 1e-12);
    // Origin of frame 3 at (q3 - l_tool) along z3: d3 = q3 - l_tool.
    const Eigen::Vector3d expected = (s.q[2] - 0.4318) * rcm::compute_z3_base(s.q);
    EXPECT_LT((X.translation() - expected).norm(), 1e-12);
    EXPECT_NEAR(X.linear().determinant(), 1.0, 1e-12);
  }
  EXPECT_DOUBLE_EQ(model().tool_offset(), 0.4318);
}

TEST(Kinematics, InsertionAxisAtHomePointsDown) {
  const Eigen::Vector3d z = rcm::compute_z3_base(Eigen::Vector3d(0, 0, 0.12));
  EXPECT_LT((z - Eigen::Vector3d(0, 0, -1)).norm(), 1e-15);
}

TEST(Kinematics, PivotAngleMatchesEq9) {
  for (const auto& s : random_samples(200, 2)) {
    const rcm::IncisionFrame inc = rcm::make_incision_frame(s.q0);
    const double eq9 = std::acos(std::cos(s.q0[1]) * std::cos(s.q[1]) * std::cos(s.q[0] - s.q0[0]) +
                                 std::sin(s.q0[1]) * std::sin(s.q[1]));
    EXPECT_NEAR(rcm::compute_pivot_angle(inc, s.q), eq9, 1e-7);
  }
  // Near zero, atan2 keeps precision that acos loses.
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.1));
  EXPECT_NEAR(rcm::compute_pivot_angle(inc, Eigen::Vector3d(1e-9, 0, 0.1)), 1e-9, 1e-20);
}

TEST(Kinematics, ShaftDistanceIsDSecTheta) {
  for (const auto& s : random_samples(100, 3)) {
    const rcm::IncisionFrame inc = rcm::make_incision_frame(s.q0);
    const double theta = rcm::compute_pivot_angle(inc, s.q);
    EXPECT_NEAR(rcm::compute_shaft_distance(inc, s.q, s.D), s.D / std::cos(theta), 1e-12);
    // The point lies on the pad plane at offset D along z_inc.
    const Eigen::Vector3d p = rcm::compute_shaft_distance(inc, s.q, s.D) * rcm::compute_z3_base(s.q);
    EXPECT_NEAR(p.dot(inc.z_inc_base()), s.D, 1e-12);
  }
}

// The one home of the shaft's closed forms: its axes are DH frame 3's and its
// derivatives those of z3 (central differences, h = 1e-6: error < 1e-9).
TEST(Kinematics, ShaftDirectionsAreFrame3AndTheDerivativesOfItsAxis) {
  rcm::KinematicsData data;
  const double h = 1e-6;
  for (const auto& s : random_samples(200, 7)) {
    const rcm::ShaftDirections d = rcm::compute_shaft_directions(s.q);
    rcm::compute_forward_kinematics(model(), data, s.q);
    const Eigen::Matrix3d R = rcm::get_frame_pose(data, 3).linear();
    EXPECT_LT((R.col(0) - d.x3).norm(), 1e-12);
    EXPECT_LT((R.col(1) - d.y3).norm(), 1e-12);
    EXPECT_LT((R.col(2) - d.z3).norm(), 1e-12);
    for (int j = 0; j < 2; ++j) {
      const Eigen::Vector3d e = Eigen::Vector3d::Unit(j) * h;
      const Eigen::Vector3d fd = (rcm::compute_z3_base(s.q + e) - rcm::compute_z3_base(s.q - e)) / (2 * h);
      EXPECT_LT((fd - (j == 0 ? d.dz3_dq1 : d.get_dz3_dq2())).norm(), 1e-9) << "joint " << j + 1;
    }
    EXPECT_NEAR(d.dz3_dq1.norm(), std::abs(d.cos_q2), 1e-15);
    EXPECT_DOUBLE_EQ(d.cos_q2, std::cos(s.q[1]));
  }
}

TEST(IncisionJacobian, ClosedFormEqualsDhChainAndFiniteDifferences) {
  rcm::KinematicsData data;
  int n = 0;
  for (const auto& s : random_samples(300, 4)) {
    const rcm::IncisionFrame inc = rcm::make_incision_frame(s.q0);
    const double sd = rcm::compute_shaft_distance(inc, s.q, s.D);
    const Eigen::Matrix3d J = rcm::compute_incision_jacobian(s.q, sd);
    const Eigen::Matrix3d J_dh = rcm::compute_incision_jacobian_dh(model(), data, s.q, sd);
    EXPECT_LT((J - J_dh).cwiseAbs().maxCoeff(), 1e-12);
    // Central differences: truncation error ~ h^2 |p'''| / 6 with |p'''| <~ |s| + 1,
    // rounding ~ eps / h; h = 1e-5 leaves both below 1e-9.
    const Eigen::Matrix3d J_fd = finite_difference_jacobian(s.q, sd, 1e-5);
    EXPECT_LT((J - J_fd).cwiseAbs().maxCoeff(), 1e-9) << "q = " << s.q.transpose() << " D = " << s.D;
    ++n;
  }
  EXPECT_GE(n, 100);
}

// Eq. 8 as printed in the paper. Its first two columns are the negative of the
// geometric Jacobian of Table I: the incision point lies at +D sec(theta) along
// z3 (Table I's 'inc' row has alpha = -pi/2 and d = -D sec(theta), i.e. z_inc =
// -z3), so z1 x (p_inc - o_1) = +D sec(theta) dz3/dq1. Using the printed form
// would flip the sign of the lateral force; the geometry is the reference.
TEST(IncisionJacobian, PrintedEq8HasFlippedFirstTwoColumns) {
  for (const auto& s : random_samples(50, 5)) {
    const rcm::IncisionFrame inc = rcm::make_incision_frame(s.q0);
    const double sd = rcm::compute_shaft_distance(inc, s.q, s.D);
    const double s1 = std::sin(s.q[0]), c1 = std::cos(s.q[0]), s2 = std::sin(s.q[1]), c2 = std::cos(s.q[1]);
    Eigen::Matrix3d printed;
    printed << -sd * c1 * c2, sd * s1 * s2, c2 * s1,
               0.0,           sd * c2,      -s2,
               -sd * c2 * s1, -sd * c1 * s2, -c1 * c2;
    const Eigen::Matrix3d J = rcm::compute_incision_jacobian(s.q, sd);
    EXPECT_LT((printed.leftCols<2>() + J.leftCols<2>()).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_LT((printed.col(2) - J.col(2)).cwiseAbs().maxCoeff(), 1e-15);
    if (std::abs(sd) > 1e-3) {
      const Eigen::Matrix3d J_fd = finite_difference_jacobian(s.q, sd, 1e-5);
      EXPECT_GT((printed - J_fd).cwiseAbs().maxCoeff(), 1e-4);  // the printed form is not the derivative
    }
  }
}

TEST(IncisionJacobian, ConditionNumberMatchesSvd) {
  for (const auto& s : random_samples(100, 6)) {
    const rcm::IncisionFrame inc = rcm::make_incision_frame(s.q0);
    const double sd = rcm::compute_shaft_distance(inc, s.q, s.D);
    if (std::abs(sd) < 1e-4) continue;
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(rcm::compute_incision_jacobian(s.q, sd));
    const double expected = svd.singularValues()(0) / svd.singularValues()(2);
    EXPECT_NEAR(rcm::compute_incision_jacobian_condition(s.q, sd).condition, expected, 1e-9 * expected);
  }
}

TEST(IncisionJacobian, StatusFlagsSingularAndIllConditioned) {
  const Eigen::Vector3d q(0.2, 0.1, 0.12);
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q, 0.0).status, rcm::JacobianStatus::singular);
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q, 1e-10).status, rcm::JacobianStatus::singular);
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q, 0.001).status, rcm::JacobianStatus::ill_conditioned);
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q, 0.03).status, rcm::JacobianStatus::ok);
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q, -0.03).status, rcm::JacobianStatus::ok);
  // theta -> 90 deg: sec(theta) grows without bound.
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.1));
  const Eigen::Vector3d q_flat(M_PI / 2, 0.0, 0.1);
  EXPECT_TRUE(std::isinf(rcm::compute_shaft_distance(inc, q_flat, 0.03)));
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q_flat, rcm::compute_shaft_distance(inc, q_flat, 0.03)).status,
            rcm::JacobianStatus::singular);
  const Eigen::Vector3d q_steep(1.5, 0.0, 0.1);  // 86 deg
  EXPECT_EQ(rcm::compute_incision_jacobian_condition(q_steep, rcm::compute_shaft_distance(inc, q_steep, 0.03)).status,
            rcm::JacobianStatus::ok);
}

TEST(RobotModel, UnknownRobotIsAnError) {
  try {
    rcm::load_robot_model("dvrk-psm-si", "session.json");
    FAIL() << "expected InputError";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown robot \"dvrk-psm-si\""), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("dvrk-psm-classic"), std::string::npos) << e.what();
  }
}

TEST(RobotModel, RejectsMalformedAndNonConformingTables) {
  const std::string good = R"({"format": "rcm-robot/1", "name": "x", "convention": "modified-dh", "joints": [
    {"name": "a", "type": "revolute", "a": 0, "alpha": 1.5707963267948966, "d": 0, "theta": 1.5707963267948966, "qmin": -1, "qmax": 1},
    {"name": "b", "type": "revolute", "a": 0, "alpha": -1.5707963267948966, "d": 0, "theta": -1.5707963267948966, "qmin": -1, "qmax": 1},
    {"name": "c", "type": "prismatic", "a": 0, "alpha": 1.5707963267948966, "d": -0.4, "theta": 0, "qmin": 0, "qmax": 0.2}]})";
  EXPECT_NO_THROW(rcm::PsmModel::from_json_text(good, "good.json"));
  auto expect_error = [&](std::string text, const std::string& needle) {
    try {
      rcm::PsmModel::from_json_text(text, "r.json");
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const rcm::InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  auto replace = [&](const std::string& from, const std::string& to) {
    std::string t = good;
    t.replace(t.find(from), from.size(), to);
    return t;
  };
  expect_error(replace("modified-dh", "standard-dh"), "field convention");
  expect_error(replace("\"prismatic\"", "\"revolute\""), "joints[2].type");
  expect_error(replace("\"qmin\": -1, \"qmax\": 1}", "\"qmin\": 1, \"qmax\": -1}"), "joints[0].qmin");
  expect_error(replace("\"alpha\": -1.5707963267948966", "\"alpha\": 1.5707963267948966"), "frame 3");
  expect_error(replace("\"d\": -0.4", "\"d\": \"far\""), "joints[2].d");
  expect_error("{\"format\": \"rcm-robot/1\"", "not valid JSON");
  expect_error("[]", "expected a JSON object");
}

// The CLI prints the Jacobian that a user will trust; check it against finite
// differences of forward kinematics.
TEST(KinematicsCli, JsonJacobianMatchesFiniteDifferences) {
  const std::string cmd = std::string(RCM_CLI_PATH) +
                          " kinematics --q 0.3,-0.2,0.12 --q0 0,0,0.12 --offset 0.03 --json";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  ASSERT_TRUE(pipe);
  std::string out;
  char buf[4096];
  while (std::size_t n = fread(buf, 1, sizeof buf, pipe.get())) out.append(buf, n);
  const nlohmann::json j = nlohmann::json::parse(out);
  const Eigen::Vector3d q(0.3, -0.2, 0.12);
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const double sd = rcm::compute_shaft_distance(inc, q, 0.03);
  const Eigen::Matrix3d J_fd = finite_difference_jacobian(q, sd, 1e-5);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(j["J_inc_base"][r][c].get<double>(), J_fd(r, c), 1e-6);
  EXPECT_NEAR(j["theta"].get<double>(), rcm::compute_pivot_angle(inc, q), 1e-12);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(j["z3"][k].get<double>(), rcm::compute_z3_base(q)[k], 1e-15);
  EXPECT_GT(j["condition"].get<double>(), 1.0);
}

}  // namespace
