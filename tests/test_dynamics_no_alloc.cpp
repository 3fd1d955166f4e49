// The per-sample path of every torque model must not allocate: this executable
// replaces the global operator new with a counting one and steps each kind.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <atomic>
#include <cstdlib>
#include <new>
#include <random>

#include "rcm/dynamics/excitation.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/travel_terms.hpp"
#include "rcm/dynamics/networks.hpp"

using rcm::test::g_allocations;

using namespace rcm::dynamics;

TEST(NoAllocation, CountingOperatorNewSeesAllocations) {
  const long before = g_allocations;
  auto* p = new std::vector<int>(10);
  delete p;
  EXPECT_GT(g_allocations - before, 0);  // the counter works, so the test below can fail
}

TEST(NoAllocation, ComputeStepOfEveryKind) {
  TorqueModelInfo info;
  info.num_joints = 6;
  info.num_outputs = 6;
  info.sample_period_s = 0.005;
  Normalization norm{Eigen::VectorXf::Zero(12), Eigen::VectorXf::Ones(12), Eigen::VectorXf::Zero(6),
                     Eigen::VectorXf::Ones(6)};
  LinearTorqueParameters lp{Eigen::VectorXd::Ones(17), Eigen::VectorXd::Ones(6), Eigen::VectorXd::Ones(6),
                            Eigen::VectorXd::Ones(6), Eigen::VectorXd::Ones(6), Eigen::VectorXd::Constant(6, 1e-3)};
  auto base = std::make_shared<const LinearTorqueModel>(info, lp);
  std::vector<std::unique_ptr<TorqueModel>> models;
  models.push_back(std::make_unique<LstmTorqueModel>(info, make_random_lstm_network(12, 128, 2, 16, 6, 1), norm));
  const std::vector<DenseStack> stacks = make_random_mlp_stacks(12, 100, 6, 2, 0.3f);
  models.push_back(std::make_unique<MlpTorqueModel>(info, stacks, norm));
  models.push_back(std::make_unique<LinearTorqueModel>(info, lp));
  LinearTorqueParameters lp_rigid = lp;  // with the rigid-body inertia of joints 1-3
  lp_rigid.inertia = Eigen::VectorXd::Constant(19, 0.1);
  lp_rigid.coulomb_slow = lp_rigid.sqrt_viscous = Eigen::VectorXd::Constant(6, 0.1);
  lp_rigid.coulomb_profile = Eigen::MatrixXd::Constant(6, rcm::dynamics::kCoulombProfileKnots, 0.05);
  lp_rigid.coulomb_profile_range = Eigen::MatrixXd(6, 2);
  lp_rigid.coulomb_profile_range.col(0).setConstant(-1.0);
  lp_rigid.coulomb_profile_range.col(1).setConstant(1.0);
  lp_rigid.stiffness = Eigen::VectorXd::Constant(6, 0.2);
  // The travel terms on every joint (a fit gives them to pitch).
  lp_rigid.travel_range = lp_rigid.coulomb_profile_range;
  lp_rigid.travel_torque = Eigen::MatrixXd::Constant(6, rcm::dynamics::kTravelTorqueKnots, 0.01);
  lp_rigid.travel_hysteresis_displacement = Eigen::MatrixXd::Constant(6, rcm::dynamics::kTravelHysteresisElements, 0.01);
  lp_rigid.travel_hysteresis = Eigen::MatrixXd::Constant(
      6, rcm::dynamics::kTravelHysteresisElements * rcm::dynamics::kTravelHysteresisKnots, 0.02);
  models.push_back(std::make_unique<LinearTorqueModel>(info, lp_rigid));
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, make_random_lstm_network(12, 32, 1, 16, 6, 2), norm));
  Normalization with_direction = norm;  // the fitted default: three direction features per joint
  with_direction.velocity_tanh_scale = Eigen::VectorXf::LinSpaced(18, 0.003f, 0.03f);
  models.push_back(
      std::make_unique<LstmTorqueModel>(info, make_random_lstm_network(30, 128, 1, 64, 6, 4), with_direction));
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, make_random_lstm_network(30, 32, 1, 16, 6, 5),
                                                       with_direction));
  Normalization with_acceleration = with_direction;  // the fitted lstm default: and one acceleration feature
  with_acceleration.acceleration_filter_s = Eigen::VectorXf::Constant(1, 0.03f);
  with_acceleration.acceleration_scale = Eigen::VectorXf::Constant(6, 2.0f);
  models.push_back(
      std::make_unique<LstmTorqueModel>(info, make_random_lstm_network(36, 128, 1, 64, 6, 6), with_acceleration));
  models.push_back(std::make_unique<HybridTorqueModel>(info, base, make_random_lstm_network(36, 32, 1, 16, 6, 7),
                                                       with_acceleration));
  Normalization with_dahl = with_acceleration;  // the fitted lstm default: and three Dahl states per joint
  with_dahl.dahl_displacement = Eigen::VectorXf::LinSpaced(18, 1e-5f, 3e-3f);
  models.push_back(
      std::make_unique<LstmTorqueModel>(info, make_random_lstm_network(54, 128, 1, 64, 6, 8), with_dahl));
  models.push_back(
      std::make_unique<HybridTorqueModel>(info, base, make_random_lstm_network(54, 32, 1, 16, 6, 9), with_dahl));
  for (const auto& m : models) {
    auto ws = m->create_workspace();
    double q[6] = {0.1, 0.2, 0.12, 0, 0, 0}, qd[6] = {0.3, -0.2, 0.01, 0, 0, 0}, tau[6];
    const long before = g_allocations;
    for (int t = 0; t < 500; ++t) {
      q[0] += 1e-3;
      m->compute_step(*ws, t * 0.005, q, qd, tau);
    }
    m->reset_state(*ws);
    m->compute_step(*ws, 0.0, q, qd, tau);
    EXPECT_EQ(g_allocations - before, 0) << to_string(m->kind());
  }
}

TEST(NoAllocation, LstmKernelStepOnEveryInstructionSet) {
  const auto net = make_random_lstm_network(12, 128, 2, 64, 6, 3);
  for (const KernelIsa isa : {KernelIsa::portable, KernelIsa::avx2_fma}) {
    if (!kernel_isa_available(isa)) continue;
    const LstmKernel kernel(net, isa);
    auto state = kernel.create_state();
    float x[12] = {0.1f, -0.2f}, y[6];
    const long before = g_allocations;
    for (int t = 0; t < 200; ++t) {
      x[0] += 1e-3f;
      kernel.step(state, x, y);
    }
    LstmKernel::reset(state);
    kernel.step(state, x, y);
    EXPECT_EQ(g_allocations - before, 0) << to_string(isa);
  }
}

TEST(NoAllocation, RegressorConditioningAddSample) {
  // The excitation's objective adds a sample per point of its grid, thousands
  // of times per design: the workspace is sized once.
  auto conditioning = std::make_unique<RegressorConditioning>(Eigen::Vector3d(1e-3, 1e-3, 1e-4));
  Eigen::Vector3d q(0.1, -0.2, 0.12), qd(0.3, -0.1, 0.02), qdd(0.5, 0.2, -0.1);
  const long before = g_allocations;
  for (int t = 0; t < 200; ++t) {
    q += 0.005 * qd;
    qd = -qd;
    conditioning->add_sample(q, qd, qdd);
  }
  EXPECT_EQ(g_allocations - before, 0);
  EXPECT_TRUE(std::isfinite(conditioning->get_log_condition_number()));
}
