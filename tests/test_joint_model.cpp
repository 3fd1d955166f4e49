// The joint torque-space model's closed-form Jacobians (the batch estimator's
// cost) against central differences of the model itself, over random samples,
// offsets and tissue laws with every term switched on.

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "../src/estimation/joint_model.hpp"
#include "rcm/kinematics/incision.hpp"

namespace {

struct Draw {
  rcm::JointSample sample;
  Eigen::Vector3d p;
  Eigen::Vector4d tissue;
};

// A pivot within 0.5 rad of q0, any direction of motion, offsets within the
// estimator's bounds and a stiffening, damped, sliding tissue.
bool draw(const rcm::IncisionFrame& incision, std::mt19937& rng, Draw& out) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d q(0.5 * u(rng), 0.5 * u(rng), 0.12 + 0.05 * u(rng));
  const Eigen::Vector3d qd(0.5 * u(rng), 0.5 * u(rng), 0.02 * u(rng));
  out.p = Eigen::Vector3d(0.02 * u(rng), 0.02 * u(rng), 0.035 + 0.03 * u(rng));
  out.tissue = Eigen::Vector4d(800.0 + 400.0 * u(rng), 2e5 * (1.0 + u(rng)), 5.0 * (1.0 + u(rng)), 0.5 * (1.0 + u(rng)));
  return rcm::compute_joint_sample(incision, q, qd, Eigen::Vector3d::Zero(), M_PI / 2, out.sample);
}

Eigen::Vector3d predict(const Draw& d, const Eigen::Matrix3d& R, double v0, const Eigen::Vector3d& p,
                        const Eigen::Vector4d& tissue) {
  Eigen::Vector3d tau;
  rcm::detail::predict_joint_torque(d.sample, R, v0, p.data(), tissue.data(), tau.data());
  return tau;
}

TEST(JointModel, ClosedFormJacobiansMatchCentralDifferences) {
  const rcm::IncisionFrame incision = rcm::make_incision_frame(Eigen::Vector3d(0.1, -0.2, 0.12));
  const Eigen::Matrix3d& R = incision.R_base_inc;
  const double v0 = 0.002;
  std::mt19937 rng(7);
  int checked = 0;
  for (int trial = 0; trial < 300; ++trial) {
    Draw d;
    if (!draw(incision, rng, d)) continue;
    Eigen::Vector3d tau;
    Eigen::Matrix3d dtau_dp;
    Eigen::Matrix<double, 3, 4> dtau_dtissue;
    rcm::detail::compute_joint_torque_jacobians(d.sample, R, v0, d.p.data(), d.tissue.data(), tau, dtau_dp,
                                                dtau_dtissue);
    const Eigen::Vector3d tau_model = predict(d, R, v0, d.p, d.tissue);
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(tau[j], tau_model[j], 1e-9 * (1.0 + std::abs(tau_model[j]))) << trial;
    // Steps relative to each variable's scale: the error ~ h^2 |tau'''| plus
    // rounding eps |tau| / h stays far below the tolerance.
    for (int k = 0; k < 3; ++k) {
      const double h = 1e-7;
      Eigen::Vector3d pp = d.p, pm = d.p;
      pp[k] += h;
      pm[k] -= h;
      const Eigen::Vector3d fd = (predict(d, R, v0, pp, d.tissue) - predict(d, R, v0, pm, d.tissue)) / (2 * h);
      for (int j = 0; j < 3; ++j)
        EXPECT_NEAR(dtau_dp(j, k), fd[j], 1e-5 * (1.0 + std::abs(fd[j]))) << "trial " << trial << " d tau" << j << " / d p" << k;
    }
    for (int k = 0; k < 4; ++k) {
      const double h = 1e-6 * std::max(1.0, std::abs(d.tissue[k]));
      Eigen::Vector4d tp = d.tissue, tm = d.tissue;
      tp[k] += h;
      tm[k] -= h;
      const Eigen::Vector3d fd = (predict(d, R, v0, d.p, tp) - predict(d, R, v0, d.p, tm)) / (2 * h);
      for (int j = 0; j < 3; ++j)
        EXPECT_NEAR(dtau_dtissue(j, k), fd[j], 1e-6 * (1.0 + std::abs(fd[j])))
            << "trial " << trial << " d tau" << j << " / d tissue" << k;
    }
    ++checked;
  }
  EXPECT_GT(checked, 250);
}

}  // namespace
