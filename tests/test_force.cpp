// Force at the incision, f = J_D^{-T} (tau - tau_fs) (paper Eq. 6).
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <limits>
#include <random>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_residual.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/tissue/tissue_pairs.hpp"

namespace {

TEST(IncisionForce, InvertsTheTransposedJacobian) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0.05, -0.1, 0.12));
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector3d q(0.8 * u(rng), 0.6 * u(rng), 0.12 + 0.1 * u(rng));
    const double D = 0.045 + 0.025 * u(rng);
    const Eigen::Vector3d dtau(u(rng), u(rng), 5 * u(rng));
    const rcm::IncisionForceSample f = rcm::compute_incision_force(inc, q, D, dtau);
    ASSERT_EQ(f.condition.status, rcm::JacobianStatus::ok);
    const Eigen::Matrix3d J = rcm::compute_incision_jacobian(q, f.shaft_distance);
    EXPECT_LT((J.transpose() * f.f_inc_base - dtau).norm(), 1e-10 * (1 + dtau.norm()));
    const Eigen::Vector3d f_lu = J.transpose().fullPivLu().solve(dtau);
    EXPECT_LT((f.f_inc_base - f_lu).norm(), 1e-9 * (1 + f_lu.norm()));
  }
}

// Virtual work: a force f at the shaft point produces joint torques J^T f, so a
// known lateral force must come back exactly, with the contract's sign.
TEST(IncisionForce, RecoversAKnownForce) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const Eigen::Vector3d q(0.3, -0.2, 0.12);
  const double D = 0.03;
  const Eigen::Vector3d f_true(4.0, -2.5, 1.5);
  const double s = rcm::compute_shaft_distance(inc, q, D);
  const Eigen::Vector3d dtau = rcm::compute_incision_jacobian(q, s).transpose() * f_true;
  EXPECT_LT((rcm::compute_incision_force(inc, q, D, dtau).f_inc_base - f_true).norm(), 1e-12);
}

TEST(IncisionForce, SingularSampleIsFlaggedNotHuge) {
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const rcm::IncisionForceSample f =
      rcm::compute_incision_force(inc, Eigen::Vector3d(0.2, 0.1, 0.12), 0.0, Eigen::Vector3d(0.1, 0.1, 0.1));
  EXPECT_EQ(f.condition.status, rcm::JacobianStatus::singular);
  EXPECT_TRUE(f.f_inc_base.array().isNaN().all());
}

TEST(IncisionForce, SeriesCountsStatusesAndChecksSizes) {
  rcm::Recording rec;
  rec.source = "series.csv";
  const int T = 4;
  rec.time = Eigen::VectorXd::LinSpaced(T, 0.0, 0.015);
  rec.position.resize(T, 3);
  rec.position << 0.0, 0.0, 0.12,  // theta = 0 -> s = D, fine
      0.2, 0.1, 0.12, 0.3, -0.2, 0.12, 0.1, 0.1, 0.12;
  rec.velocity = Eigen::MatrixXd::Zero(T, 3);
  rec.effort = Eigen::MatrixXd::Ones(T, 3);
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  const Eigen::MatrixXd tau_fs = Eigen::MatrixXd::Zero(T, 3);
  const rcm::IncisionForceSeries ok = rcm::compute_incision_force_series(inc, rec, tau_fs, 0.03);
  EXPECT_EQ(ok.num_singular, 0u);
  EXPECT_EQ(ok.f_inc_base.rows(), T);
  const rcm::IncisionForceSeries ill = rcm::compute_incision_force_series(inc, rec, tau_fs, 0.001);
  EXPECT_EQ(ill.num_ill_conditioned, static_cast<std::size_t>(T));
  EXPECT_THROW(rcm::compute_incision_force_series(inc, rec, Eigen::MatrixXd::Zero(T - 1, 3), 0.03), rcm::InputError);
}

// The residual every estimator starts from: effort minus prediction on the
// first three joints, and a prediction of the wrong size or with a value that
// is not finite refused with the file, the line of the sample and the field.
TEST(TorqueResidual, IsEffortMinusPredictionAndRefusesABadPrediction) {
  const rcm::Recording rec = rcm::parse_recording(
      "time,position_1,position_2,position_3,position_4,velocity_1,velocity_2,velocity_3,velocity_4,"
      "effort_1,effort_2,effort_3,effort_4\n"
      "0.000,0,0,0.12,0,0,0,0,0,0.5,-0.25,2,9\n"
      "0.005,0.1,0,0.12,0,0,0,0,0,0.75,-0.5,3,9\n"
      "0.010,0.2,0,0.12,0,0,0,0,0,1,-0.75,4,9\n",
      "residual.csv");
  Eigen::MatrixXd tau_fs(3, 4);
  tau_fs << 0.25, 0.25, 1, 7, 0.25, -0.25, 1, 7, 0.5, 0.25, 1, 7;
  const rcm::TorqueResidual dtau = rcm::compute_torque_residual(rec, tau_fs);
  Eigen::Matrix3d expected;
  expected << 0.25, -0.5, 1, 0.5, -0.25, 2, 0.5, -1, 3;
  EXPECT_EQ(dtau, expected);

  try {
    rcm::compute_torque_residual(rec, tau_fs.topRows(2));
    ADD_FAILURE() << "a prediction with a row missing";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("residual.csv: tau_fs: the free-space torque prediction is 2 x 4, expected 3"),
              std::string::npos)
        << e.what();
  }
  Eigen::MatrixXd bad = tau_fs;
  bad(2, 1) = std::numeric_limits<double>::quiet_NaN();
  try {
    rcm::compute_torque_residual(rec, bad);
    ADD_FAILURE() << "a NaN prediction";
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().line, 4u);
    EXPECT_EQ(e.where().field, "tau_fs_2");
  }
  // A NaN in a joint no estimator reads is not checked.
  bad = tau_fs;
  bad(1, 3) = std::numeric_limits<double>::infinity();
  EXPECT_NO_THROW(rcm::compute_torque_residual(rec, bad));

  // Every consumer refuses the same prediction the same way.
  bad = tau_fs;
  bad(0, 0) = std::numeric_limits<double>::infinity();
  const rcm::IncisionFrame inc = rcm::make_incision_frame(Eigen::Vector3d(0, 0, 0.12));
  EXPECT_THROW(rcm::compute_incision_force_series(inc, rec, bad, 0.03), rcm::InputError);
  EXPECT_THROW(rcm::compute_tissue_pairs(rec, bad, Eigen::Vector3d(0, 0, 0.12), 0.03), rcm::InputError);
}

}  // namespace
