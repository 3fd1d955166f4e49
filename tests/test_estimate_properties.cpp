// Numbers in, numbers out: the joint estimate on random simulated sessions
// (docking configuration q0 within the joint limits, offsets, tissue family and
// stiffness drawn at random), with the free-space torque known exactly, so that
// what is checked is the estimator: every estimate finite, inside its bounds and
// inside its own interval, and the 95 % intervals covering the truth at their
// stated rate. Each session (q0, tissue, its calibration fitted once) gets
// several trials with random offsets. The coverage is reported per axis over all
// cases and must not fall below what 95 % coverage leaves with probability
// 0.999. `make test` runs 4 sessions of 3 trials; `make soak` runs
// RCM_PROPERTY_SESSIONS=50 of RCM_PROPERTY_TRIALS=4 (200 cases).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include "rcm/estimation/joint.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"

namespace {

double draw(std::mt19937_64& rng, double lo, double hi) {
  return lo + (hi - lo) * std::uniform_real_distribution<double>(0.0, 1.0)(rng);
}

int get_count(const char* name, int fallback) {
  const char* env = std::getenv(name);
  return env ? std::atoi(env) : fallback;
}

// A docking configuration anywhere the excursion stays within the joint limits
// (validate_config says), a tissue family and its stiffness.
rcm::sim::SimConfig draw_session(std::mt19937_64& rng, std::uint64_t seed) {
  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  config.seed = seed;
  config.threads = 1;
  config.protocol.calibration_s = 30.0;
  config.protocol.trial_s = 20.0;
  config.protocol.static_hold_s = 5.0;
  rcm::sim::apply_tissue_preset(config.tissue, draw(rng, 0.0, 1.0) < 0.5 ? "linear" : "stiffening");
  config.tissue.stiffness_n_per_m *= draw(rng, 0.6, 1.6);
  config.tissue.cubic_n_per_m3 *= draw(rng, 0.5, 2.0);
  for (int attempt = 0;; ++attempt) {
    config.protocol.q0 = Eigen::Vector3d(draw(rng, -0.9, 0.9), draw(rng, -0.4, 0.4), draw(rng, 0.09, 0.20));
    try {
      rcm::sim::validate_config(config, "property case");
      return config;
    } catch (const rcm::InputError&) {
      if (attempt > 1000) throw;
    }
  }
}

std::string describe(const rcm::sim::SimConfig& c, const Eigen::Vector3d& truth) {
  char text[256];
  std::snprintf(text, sizeof text, "q0 [%.3f, %.3f, %.3f], %s tissue k1 %.0f N/m, truth [%.2f, %.2f, %.2f] mm, seed %llu",
                c.protocol.q0[0], c.protocol.q0[1], c.protocol.q0[2], c.tissue.preset.c_str(), c.tissue.stiffness_n_per_m,
                1e3 * truth[0], 1e3 * truth[1], 1e3 * truth[2], static_cast<unsigned long long>(c.seed));
  return text;
}

TEST(EstimateProperties, FiniteBoundedAndCoveredAtTheStatedRate) {
  const int sessions = get_count("RCM_PROPERTY_SESSIONS", 4), trials = get_count("RCM_PROPERTY_TRIALS", 3);
  ASSERT_GT(sessions, 0);
  ASSERT_GT(trials, 0);
  const int cases = sessions * trials;
  std::mt19937_64 rng(20261125);
  rcm::JointEstimatorOptions options;
  int covered[3] = {0, 0, 0}, solved = 0;
  double worst_error_m = 0.0;
  for (int session = 0; session < sessions; ++session) {
    const rcm::sim::SimConfig config = draw_session(rng, static_cast<std::uint64_t>(session + 1));
    const rcm::IncisionFrame incision = rcm::make_incision_frame(config.protocol.q0);
    const rcm::sim::SimulatedRecording calibration = rcm::sim::simulate_calibration(config);
    const rcm::JointTissueModel tissue = rcm::fit_joint_tissue_model(
        incision, rcm::make_joint_samples(incision, calibration.recording, calibration.truth.tau_fs),
        config.protocol.calibration_offset_m, options);
    ASSERT_TRUE(tissue.parameters.allFinite()) << "session " << session;
    for (int k = 0; k < trials; ++k) {
      const Eigen::Vector3d truth(draw(rng, -0.015, 0.015), draw(rng, -0.015, 0.015), draw(rng, 0.005, 0.050));
      const rcm::sim::SimulatedTrial trial = rcm::sim::simulate_trial(config, truth);
      const rcm::JointEstimate e = rcm::estimate_joint(
          incision, tissue, rcm::make_joint_samples(incision, trial.recording.recording, trial.recording.truth.tau_fs),
          options);
      ASSERT_TRUE(e.misalignment_m.allFinite() && e.ci_low.allFinite() && e.ci_high.allFinite() &&
                  e.covariance.allFinite())
          << describe(config, truth);
      EXPECT_LE(std::abs(e.misalignment_m[0]), options.radial_max + 1e-12) << describe(config, truth);
      EXPECT_LE(std::abs(e.misalignment_m[1]), options.radial_max + 1e-12) << describe(config, truth);
      EXPECT_GE(e.misalignment_m[2], options.D_min - 1e-12) << describe(config, truth);
      EXPECT_LE(e.misalignment_m[2], options.D_max + 1e-12) << describe(config, truth);
      for (int a = 0; a < 3; ++a) {
        EXPECT_LE(e.ci_low[a], e.misalignment_m[a]) << describe(config, truth);
        EXPECT_GE(e.ci_high[a], e.misalignment_m[a]) << describe(config, truth);
        covered[a] += e.ci_low[a] <= truth[a] && truth[a] <= e.ci_high[a] ? 1 : 0;
      }
      solved += e.solver.converged ? 1 : 0;
      worst_error_m = std::max(worst_error_m, (e.misalignment_m - truth).cwiseAbs().maxCoeff());
    }
  }
  // 95 % coverage leaves fewer than this many misses with probability 0.001
  // (normal approximation of the binomial, 3.09 sd).
  const double n = cases;
  const double min_rate = 0.95 - 3.09 * std::sqrt(0.95 * 0.05 / n);
  std::printf("coverage of the 95 %% intervals over %d random cases: dr_x %.3f, dr_y %.3f, D %.3f "
              "(bar %.3f); solver converged %d; largest error %.2f mm\n",
              cases, covered[0] / n, covered[1] / n, covered[2] / n, min_rate, solved, 1e3 * worst_error_m);
  for (int a = 0; a < 3; ++a) EXPECT_GE(covered[a] / n, min_rate) << "axis " << a;
}

}  // namespace
