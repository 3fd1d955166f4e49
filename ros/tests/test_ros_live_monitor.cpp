// rcm::LiveMonitor, the per-message path of rcm_monitor_node, without a ROS
// master: the same numbers as the pipeline fed directly, joints mapped by name
// whatever their order in the message, bad messages rejected and counted
// (never thrown), and no allocation per message after the first.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <cmath>
#include <limits>
#include <memory>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/ros/live_monitor.hpp"

using rcm::test::g_allocations;
using Verdict = rcm::LiveMonitor::Verdict;

namespace {

const Eigen::Vector3d kQ0(0.0, 0.0, 0.12);
const std::vector<std::string> kNames = {"outer_yaw", "outer_pitch", "outer_insertion", "outer_roll"};

// A linear free-space model reading 4 joints and a linear tissue, as in
// test_online: the numbers do not matter, only that both paths agree.
std::shared_ptr<const rcm::OnlinePipeline> make_pipeline() {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  rcm::dynamics::LinearTorqueParameters lp{Eigen::VectorXd::Constant(17, 0.01), Eigen::VectorXd::Constant(3, 0.02),
                                           Eigen::VectorXd::Constant(3, 0.01),  Eigen::VectorXd::Constant(3, 0.01),
                                           Eigen::VectorXd::Constant(3, 0.0),   Eigen::VectorXd::Constant(3, 1e-3)};
  rcm::JointTissueModel tissue;
  tissue.parameters = Eigen::Vector4d(875.0, 0.0, 2.0, 0.3);
  rcm::OnlineEstimatorOptions o;
  o.torque_sigma = Eigen::Vector3d(0.02, 0.02, 0.1);
  return std::make_shared<const rcm::OnlinePipeline>(
      std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, lp),
      rcm::OnlineEstimator(rcm::make_incision_frame(kQ0), tissue, o));
}

struct Sample {
  double t;
  double q[4], qd[4], effort[4];
};
Sample make_sample(int k) {
  Sample s;
  s.t = k / 500.0;
  const double w = 2 * M_PI / 3.0;
  for (int j = 0; j < 4; ++j) {
    s.q[j] = (j == 2 ? kQ0[2] : 0.0) + (j == 2 ? 0.01 : 0.4) * std::sin(w * s.t + j);
    s.qd[j] = (j == 2 ? 0.01 : 0.4) * w * std::cos(w * s.t + j);
    s.effort[j] = 0.3 * std::sin(w * s.t + 2 * j) + (j == 2 ? 1.0 : 0.0);
  }
  return s;
}

// A JointState of sample k with the joints in `order` (indices into kNames).
sensor_msgs::JointState make_message(const Sample& s, const std::vector<int>& order, std::int64_t base_ns) {
  sensor_msgs::JointState m;
  m.header.stamp.fromNSec(static_cast<std::uint64_t>(base_ns + std::llround(s.t * 1e9)));
  for (int j : order) {
    m.name.push_back(kNames[static_cast<std::size_t>(j)]);
    m.position.push_back(s.q[j]);
    m.velocity.push_back(s.qd[j]);
    m.effort.push_back(s.effort[j]);
  }
  return m;
}

constexpr std::int64_t kBase = 1700000000LL * 1000000000LL;

TEST(LiveMonitor, SameAsThePipelineWhateverTheJointOrder) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  auto ws = pipeline->create_workspace();
  for (int k = 0; k < 3000; ++k) {
    const Sample s = make_sample(k);
    // The first message sets the order; later ones come shuffled now and then.
    const std::vector<int> order = k % 7 == 3 ? std::vector<int>{3, 1, 0, 2} : std::vector<int>{0, 1, 2, 3};
    ASSERT_EQ(monitor.compute_message(make_message(s, order, kBase), 0), Verdict::accepted) << k;
    const double t = static_cast<double>(std::llround(s.t * 1e9)) * 1e-9;
    const rcm::OnlineOutput& direct = pipeline->compute_sample(ws, t, s.q, s.qd, s.effort);
    ASSERT_EQ(monitor.get_output().misalignment_m, direct.misalignment_m) << k;
    ASSERT_EQ(monitor.get_output().f_inc_base, direct.f_inc_base) << k;
  }
  EXPECT_EQ(monitor.get_counters().accepted, 3000u);
  EXPECT_EQ(monitor.get_counters().get_rejected(), 0u);
  EXPECT_EQ(monitor.get_time_origin_ns(), kBase);
  EXPECT_FALSE(monitor.uses_receive_time());
}

TEST(LiveMonitor, RejectsAndCountsBadMessages) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  const std::vector<int> order = {0, 1, 2, 3};
  ASSERT_EQ(monitor.compute_message(make_message(make_sample(0), order, kBase), 0), Verdict::accepted);
  ASSERT_EQ(monitor.compute_message(make_message(make_sample(1), order, kBase), 0), Verdict::accepted);
  const Eigen::Vector3d after_two = monitor.get_output().misalignment_m;

  auto expect = [&](const sensor_msgs::JointState& m, Verdict v, const std::string& text) {
    EXPECT_EQ(monitor.compute_message(m, 0), v) << text;
    EXPECT_NE(monitor.describe_rejection(v, m).find(text), std::string::npos) << monitor.describe_rejection(v, m);
    EXPECT_EQ(monitor.get_output().misalignment_m, after_two);  // nothing reached the estimator
  };
  expect(make_message(make_sample(1), order, kBase), Verdict::duplicate_stamp, "repeats");
  expect(make_message(make_sample(0), order, kBase), Verdict::out_of_order, "earlier");
  sensor_msgs::JointState m = make_message(make_sample(2), order, kBase);
  m.header.stamp = ros::Time();
  expect(m, Verdict::bad_stamp, "zero");
  m = make_message(make_sample(2), order, kBase);
  m.effort[2] = std::numeric_limits<double>::quiet_NaN();
  expect(m, Verdict::malformed, "effort[2] ('outer_insertion'): expected a finite number");
  m = make_message(make_sample(2), order, kBase);
  m.velocity.pop_back();
  expect(m, Verdict::malformed, "velocity: 3 entries, expected 4");
  m = make_message(make_sample(2), {0, 1, 3}, kBase);
  expect(m, Verdict::malformed, "missing joint 'outer_insertion'");
  m = make_message(make_sample(2), order, kBase);
  m.name.clear();
  expect(m, Verdict::malformed, "name: missing");
  m = make_message(make_sample(2), order, kBase);
  m.effort.clear();
  expect(m, Verdict::malformed, "effort: missing");

  const auto& c = monitor.get_counters();
  EXPECT_EQ(c.duplicate_stamp, 1u);
  EXPECT_EQ(c.out_of_order, 1u);
  EXPECT_EQ(c.bad_stamp, 1u);
  EXPECT_EQ(c.malformed, 5u);
  EXPECT_EQ(c.get_rejected(), 8u);
  // The stream goes on. A joint the model does not read (outer_roll) is not checked.
  EXPECT_EQ(monitor.compute_message(make_message(make_sample(2), order, kBase), 0), Verdict::accepted);
  m = make_message(make_sample(3), {3, 0, 1, 2}, kBase);
  m.effort[0] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(monitor.compute_message(m, 0), Verdict::accepted);
  EXPECT_EQ(c.accepted, 4u);
  EXPECT_EQ(monitor.get_joint_map().names(), std::vector<std::string>({"outer_yaw", "outer_pitch", "outer_insertion"}));
}

TEST(LiveMonitor, PositionalStreamsReadTheFirstJoints) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  auto ws = pipeline->create_workspace();
  for (int k = 0; k < 10; ++k) {
    sensor_msgs::JointState m = make_message(make_sample(k), {0, 1, 2, 3}, kBase);
    m.name.clear();
    ASSERT_EQ(monitor.compute_message(m, 0), Verdict::accepted) << k;
    const Sample s = make_sample(k);
    EXPECT_EQ(monitor.get_output().misalignment_m,
              pipeline->compute_sample(ws, static_cast<double>(std::llround(s.t * 1e9)) * 1e-9, s.q, s.qd, s.effort).misalignment_m);
  }
  sensor_msgs::JointState m = make_message(make_sample(10), {0, 1, 2}, kBase);  // a joint fewer than the stream's
  m.name.clear();
  EXPECT_EQ(monitor.compute_message(m, 0), Verdict::malformed);
  EXPECT_NE(monitor.describe_rejection(Verdict::malformed, m).find("3 entries, expected 4"), std::string::npos)
      << monitor.describe_rejection(Verdict::malformed, m);
}

TEST(LiveMonitor, ZeroStampsUseTheReceiveTime) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  for (int k = 0; k < 5; ++k) {
    sensor_msgs::JointState m = make_message(make_sample(k), {0, 1, 2, 3}, kBase);
    m.header.stamp = ros::Time();
    ASSERT_EQ(monitor.compute_message(m, kBase + 2000000LL * k), Verdict::accepted);
  }
  EXPECT_TRUE(monitor.uses_receive_time());
  EXPECT_EQ(monitor.get_last_time_ns(), kBase + 8000000LL);
  sensor_msgs::JointState m = make_message(make_sample(9), {0, 1, 2, 3}, kBase);
  m.header.stamp = ros::Time();
  EXPECT_EQ(monitor.compute_message(m, kBase + 8000000LL), Verdict::duplicate_stamp);
}

TEST(LiveMonitor, GivenJointNamesAndTooFewJoints) {
  const auto pipeline = make_pipeline();
  // The model reads 3 joints: a stream of 2 is rejected until a longer one comes.
  rcm::LiveMonitor monitor(*pipeline);
  sensor_msgs::JointState short_msg = make_message(make_sample(0), {0, 1}, kBase);
  EXPECT_EQ(monitor.compute_message(short_msg, 0), Verdict::too_few_joints);
  EXPECT_EQ(monitor.compute_message(make_message(make_sample(1), {0, 1, 2}, kBase), 0), Verdict::accepted);

  // Given names fix the order; messages without names are then rejected.
  rcm::LiveMonitor named(*pipeline, {"outer_yaw", "outer_pitch", "outer_insertion"});
  EXPECT_EQ(named.compute_message(make_message(make_sample(0), {2, 3, 0, 1}, kBase), 0), Verdict::accepted);
  auto ws = pipeline->create_workspace();
  const Sample s = make_sample(0);
  EXPECT_EQ(named.get_output().misalignment_m, pipeline->compute_sample(ws, 0.0, s.q, s.qd, s.effort).misalignment_m);
  sensor_msgs::JointState unnamed = make_message(make_sample(1), {0, 1, 2, 3}, kBase);
  unnamed.name.clear();
  EXPECT_EQ(named.compute_message(unnamed, 0), Verdict::malformed);
  EXPECT_THROW(rcm::LiveMonitor(*pipeline, {"a", "b"}), std::invalid_argument);       // fewer than the model reads
  EXPECT_THROW(rcm::LiveMonitor(*pipeline, {"a", "b", "a"}), std::invalid_argument);  // repeated
}

TEST(LiveMonitor, NoAllocationPerMessageAfterTheFirst) {
  const long probe_before = g_allocations;
  delete new std::vector<int>(10);
  ASSERT_GT(g_allocations - probe_before, 0);  // the counter works

  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  std::vector<sensor_msgs::JointState> messages;
  for (int k = 0; k < 2000; ++k) {
    messages.push_back(make_message(make_sample(k), k % 5 == 2 ? std::vector<int>{1, 3, 2, 0} : std::vector<int>{0, 1, 2, 3}, kBase));
    if (k % 97 == 50) messages.push_back(messages.back());  // a duplicate stamp
    if (k % 89 == 60) {                                     // a NaN
      messages.push_back(make_message(make_sample(k), {0, 1, 2, 3}, kBase + 1));
      messages.back().position[1] = std::numeric_limits<double>::quiet_NaN();
    }
  }
  ASSERT_EQ(monitor.compute_message(messages.front(), 0), Verdict::accepted);
  const long before = g_allocations;
  for (std::size_t k = 1; k < messages.size(); ++k) monitor.compute_message(messages[k], 0);
  EXPECT_EQ(g_allocations - before, 0);
  EXPECT_EQ(monitor.get_counters().accepted, 2000u);
  EXPECT_GT(monitor.get_counters().duplicate_stamp, 0u);
  EXPECT_GT(monitor.get_counters().malformed, 0u);
}

}  // namespace
