// rcm::LiveMonitor, the per-message path of the live nodes (ROS 1, DDS), without
// any middleware: the same numbers as the pipeline fed directly, joints mapped by name
// whatever their order in the message, bad messages rejected and counted
// (never thrown), and no allocation per message after the first.

#include <gtest/gtest.h>

#include "counting_new.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/live/live_monitor.hpp"
#include "rcm/live/monitor_node.hpp"

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

// A JointState as any middleware delivers it: the four arrays and the stamp.
struct Message {
  std::int64_t stamp_ns = 0;
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
};

// A JointState of sample k with the joints in `order` (indices into kNames).
Message make_message(const Sample& s, const std::vector<int>& order, std::int64_t base_ns) {
  Message m;
  m.stamp_ns = base_ns + std::llround(s.t * 1e9);
  for (int j : order) {
    m.name.push_back(kNames[static_cast<std::size_t>(j)]);
    m.position.push_back(s.q[j]);
    m.velocity.push_back(s.qd[j]);
    m.effort.push_back(s.effort[j]);
  }
  return m;
}

// A node's calls: the message seen as a view, its stamp in ns.
Verdict compute(rcm::LiveMonitor& monitor, const Message& m, std::int64_t receive_time_ns) {
  return monitor.compute_message(rcm::view_joint_state(m), m.stamp_ns, receive_time_ns);
}
std::string describe(const rcm::LiveMonitor& monitor, Verdict v, const Message& m) {
  return monitor.describe_rejection(v, rcm::view_joint_state(m), m.stamp_ns);
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
    ASSERT_EQ(compute(monitor, make_message(s, order, kBase), 0), Verdict::accepted) << k;
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
  ASSERT_EQ(compute(monitor, make_message(make_sample(0), order, kBase), 0), Verdict::accepted);
  ASSERT_EQ(compute(monitor, make_message(make_sample(1), order, kBase), 0), Verdict::accepted);
  const Eigen::Vector3d after_two = monitor.get_output().misalignment_m;

  auto expect = [&](const Message& m, Verdict v, const std::string& text) {
    EXPECT_EQ(compute(monitor, m, 0), v) << text;
    EXPECT_NE(describe(monitor, v, m).find(text), std::string::npos) << describe(monitor, v, m);
    EXPECT_EQ(monitor.get_output().misalignment_m, after_two);  // nothing reached the estimator
  };
  expect(make_message(make_sample(1), order, kBase), Verdict::duplicate_stamp, "repeats");
  expect(make_message(make_sample(0), order, kBase), Verdict::out_of_order, "earlier");
  Message m = make_message(make_sample(2), order, kBase);
  m.stamp_ns = 0;
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
  EXPECT_EQ(compute(monitor, make_message(make_sample(2), order, kBase), 0), Verdict::accepted);
  m = make_message(make_sample(3), {3, 0, 1, 2}, kBase);
  m.effort[0] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(compute(monitor, m, 0), Verdict::accepted);
  EXPECT_EQ(c.accepted, 4u);
  EXPECT_EQ(monitor.get_joint_map().names(), std::vector<std::string>({"outer_yaw", "outer_pitch", "outer_insertion"}));
}

// A publisher's clock: one stamp hours off is rejected (ahead: time jump;
// behind: out of order) and the stream goes on; a timeline that moves for good
// is followed after ten consistent messages; a silence is not a jump.
TEST(LiveMonitor, ClockGlitchesAreRejectedAndMovedTimelinesFollowed) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline, {}, rcm::LiveMonitor::ZeroStamp::invalid);
  const std::vector<int> order = {0, 1, 2, 3};
  constexpr std::int64_t kHour = 3600LL * 1000000000LL;
  std::int64_t shift = 0;  // what the publisher's clock adds to the true stamp
  std::int64_t silence = 0;  // time without messages, on both clocks
  auto send = [&](int k, std::int64_t extra = 0) {
    Message m = make_message(make_sample(k), order, kBase + shift + silence + extra);
    return compute(monitor, m, kBase + silence + std::llround(make_sample(k).t * 1e9));
  };
  for (int k = 0; k < 20; ++k) ASSERT_EQ(send(k), Verdict::accepted) << k;
  EXPECT_EQ(send(20, 3 * kHour), Verdict::time_jump);
  EXPECT_NE(describe(monitor, Verdict::time_jump, make_message(make_sample(20), order, kBase + 3 * kHour))
                .find("more than the receive clock advanced"),
            std::string::npos);
  EXPECT_EQ(send(21, -3 * kHour), Verdict::out_of_order);
  for (int k = 22; k < 30; ++k) ASSERT_EQ(send(k), Verdict::accepted) << k;
  EXPECT_EQ(monitor.get_counters().time_jump, 1u);
  EXPECT_EQ(monitor.get_counters().out_of_order, 1u);

  silence = 600LL * 1000000000LL;  // ten minutes without a message: accepted
  ASSERT_EQ(send(30), Verdict::accepted);
  EXPECT_NEAR(monitor.get_output().time, 600.0 + make_sample(30).t, 1e-9);

  shift = -2 * kHour;  // the publisher's clock steps back for good
  for (int k = 31; k < 40; ++k) ASSERT_EQ(send(k), Verdict::out_of_order) << k;
  const double before = monitor.get_output().time;
  ASSERT_EQ(send(40), Verdict::accepted);
  EXPECT_EQ(monitor.get_counters().retimed, 1u);
  // The estimator's time went on by the receive clock; the published stamp is the new one.
  EXPECT_NEAR(monitor.get_output().time - before, make_sample(40).t - make_sample(30).t, 1e-9);
  EXPECT_EQ(monitor.get_last_time_ns(), kBase + shift + silence + std::llround(make_sample(40).t * 1e9));
  for (int k = 41; k < 50; ++k) ASSERT_EQ(send(k), Verdict::accepted) << k;

  shift = 5 * kHour;  // ... and forward for good
  for (int k = 50; k < 59; ++k) ASSERT_EQ(send(k), Verdict::time_jump) << k;
  ASSERT_EQ(send(59), Verdict::accepted);
  EXPECT_EQ(monitor.get_counters().retimed, 2u);
  EXPECT_EQ(monitor.get_counters().time_jump, 10u);
  EXPECT_EQ(monitor.get_counters().out_of_order, 10u);
  EXPECT_EQ(monitor.get_counters().accepted, 40u);

  // With retiming off, a moved timeline stays rejected.
  rcm::LiveMonitor strict(*pipeline, {}, rcm::LiveMonitor::ZeroStamp::invalid, {1.0, 0});
  ASSERT_EQ(compute(strict, make_message(make_sample(0), order, kBase), 0), Verdict::accepted);
  for (int k = 1; k < 40; ++k)
    ASSERT_EQ(compute(strict, make_message(make_sample(k), order, kBase - kHour), 0), Verdict::out_of_order) << k;
}

TEST(LiveMonitor, PositionalStreamsReadTheFirstJoints) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  auto ws = pipeline->create_workspace();
  for (int k = 0; k < 10; ++k) {
    Message m = make_message(make_sample(k), {0, 1, 2, 3}, kBase);
    m.name.clear();
    ASSERT_EQ(compute(monitor, m, 0), Verdict::accepted) << k;
    const Sample s = make_sample(k);
    EXPECT_EQ(monitor.get_output().misalignment_m,
              pipeline->compute_sample(ws, static_cast<double>(std::llround(s.t * 1e9)) * 1e-9, s.q, s.qd, s.effort).misalignment_m);
  }
  Message m = make_message(make_sample(10), {0, 1, 2}, kBase);  // a joint fewer than the stream's
  m.name.clear();
  EXPECT_EQ(compute(monitor, m, 0), Verdict::malformed);
  EXPECT_NE(describe(monitor, Verdict::malformed, m).find("3 entries, expected 4"), std::string::npos)
      << describe(monitor, Verdict::malformed, m);
}

TEST(LiveMonitor, ZeroStampsUseTheReceiveTime) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  for (int k = 0; k < 5; ++k) {
    Message m = make_message(make_sample(k), {0, 1, 2, 3}, kBase);
    m.stamp_ns = 0;
    ASSERT_EQ(compute(monitor, m, kBase + 2000000LL * k), Verdict::accepted);
  }
  EXPECT_TRUE(monitor.uses_receive_time());
  EXPECT_EQ(monitor.get_last_time_ns(), kBase + 8000000LL);
  Message m = make_message(make_sample(9), {0, 1, 2, 3}, kBase);
  m.stamp_ns = 0;
  EXPECT_EQ(compute(monitor, m, kBase + 8000000LL), Verdict::duplicate_stamp);
}

TEST(LiveMonitor, GivenJointNamesAndTooFewJoints) {
  const auto pipeline = make_pipeline();
  // The model reads 3 joints: a stream of 2 is rejected until a longer one comes.
  rcm::LiveMonitor monitor(*pipeline);
  Message short_msg = make_message(make_sample(0), {0, 1}, kBase);
  EXPECT_EQ(compute(monitor, short_msg, 0), Verdict::too_few_joints);
  EXPECT_EQ(compute(monitor, make_message(make_sample(1), {0, 1, 2}, kBase), 0), Verdict::accepted);

  // Given names fix the order; messages without names are then rejected.
  rcm::LiveMonitor named(*pipeline, {"outer_yaw", "outer_pitch", "outer_insertion"});
  EXPECT_EQ(compute(named, make_message(make_sample(0), {2, 3, 0, 1}, kBase), 0), Verdict::accepted);
  auto ws = pipeline->create_workspace();
  const Sample s = make_sample(0);
  EXPECT_EQ(named.get_output().misalignment_m, pipeline->compute_sample(ws, 0.0, s.q, s.qd, s.effort).misalignment_m);
  Message unnamed = make_message(make_sample(1), {0, 1, 2, 3}, kBase);
  unnamed.name.clear();
  EXPECT_EQ(compute(named, unnamed, 0), Verdict::malformed);
  EXPECT_THROW(rcm::LiveMonitor(*pipeline, {"a", "b"}), std::invalid_argument);       // fewer than the model reads
  EXPECT_THROW(rcm::LiveMonitor(*pipeline, {"a", "b", "a"}), std::invalid_argument);  // repeated
}

TEST(LiveMonitor, NoAllocationPerMessageAfterTheFirst) {
  const long probe_before = g_allocations;
  delete new std::vector<int>(10);
  ASSERT_GT(g_allocations - probe_before, 0);  // the counter works

  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline);
  std::vector<Message> messages;
  for (int k = 0; k < 2000; ++k) {
    messages.push_back(make_message(make_sample(k), k % 5 == 2 ? std::vector<int>{1, 3, 2, 0} : std::vector<int>{0, 1, 2, 3}, kBase));
    if (k % 97 == 50) messages.push_back(messages.back());  // a duplicate stamp
    if (k % 89 == 60) {                                     // a NaN
      messages.push_back(make_message(make_sample(k), {0, 1, 2, 3}, kBase + 1));
      messages.back().position[1] = std::numeric_limits<double>::quiet_NaN();
    }
  }
  ASSERT_EQ(compute(monitor, messages.front(), 0), Verdict::accepted);
  const long before = g_allocations;
  for (std::size_t k = 1; k < messages.size(); ++k) compute(monitor, messages[k], 0);
  EXPECT_EQ(g_allocations - before, 0);
  EXPECT_EQ(monitor.get_counters().accepted, 2000u);
  EXPECT_GT(monitor.get_counters().duplicate_stamp, 0u);
  EXPECT_GT(monitor.get_counters().malformed, 0u);
}

TEST(LiveMonitor, ZeroStampsAreInvalidDataOnRos2) {
  const auto pipeline = make_pipeline();
  rcm::LiveMonitor monitor(*pipeline, {}, rcm::LiveMonitor::ZeroStamp::invalid);
  const std::vector<int> order = {0, 1, 2, 3};
  constexpr std::int64_t kBase = 1700000000000000000;
  Message zero = make_message(make_sample(0), order, kBase);
  zero.stamp_ns = 0;
  // Even the first message: invalid data never starts the stream on the receive clock.
  EXPECT_EQ(compute(monitor, zero, kBase), Verdict::bad_stamp);
  EXPECT_FALSE(monitor.started());
  EXPECT_EQ(compute(monitor, make_message(make_sample(1), order, kBase), 0), Verdict::accepted);
  EXPECT_FALSE(monitor.uses_receive_time());
  EXPECT_EQ(compute(monitor, zero, kBase), Verdict::bad_stamp);
  EXPECT_EQ(describe(monitor, Verdict::bad_stamp, zero), "header.stamp is zero: invalid data");
  EXPECT_EQ(monitor.get_counters().bad_stamp, 2u);
  EXPECT_EQ(monitor.get_counters().accepted, 1u);
}

// What a node's middleware receives from rcm::MonitorNode.
struct RecordingSink : rcm::MonitorSink {
  std::vector<std::int64_t> estimate_stamps;
  std::vector<std::pair<rcm::MonitorFlag, bool>> flags;
  std::vector<std::uint64_t> rejected;
  std::vector<std::string> lines, advice;
  std::vector<std::int64_t> correction_stamps;
  void publish_estimate(std::int64_t stamp_ns, const rcm::OnlineOutput&) override { estimate_stamps.push_back(stamp_ns); }
  void publish_flag(rcm::MonitorFlag flag, bool value) override { flags.emplace_back(flag, value); }
  void publish_rejected(std::uint64_t total) override { rejected.push_back(total); }
  void publish_correction(std::int64_t stamp_ns, const rcm::CorrectionOutput&) override {
    correction_stamps.push_back(stamp_ns);
  }
  void publish_advice(const std::string& text) override { advice.push_back(text); }
  void log(rcm::LogLevel, const std::string& text, double) override { lines.push_back(text); }
};

TEST(MonitorNodeCore, PublishesEveryNthEstimateFlagsOnChangeAndCountsRejections) {
  rcm::MonitorNodeParameters p;
  p.session = "s.json";
  p.model_file = "m.json";
  p.publish_every = 3;
  p.status_period_s = 0;
  RecordingSink sink;
  rcm::MonitorNode node(p, std::make_unique<rcm::OnlinePipeline>(*make_pipeline()),
                        rcm::LiveMonitor::ZeroStamp::invalid, sink);
  node.start("rt/PSM1/measured_js");
  // The latched outputs start known: no onset, no alarm, in regime, nothing rejected.
  ASSERT_EQ(sink.flags.size(), 3u);
  for (const auto& f : sink.flags) EXPECT_FALSE(f.second);
  EXPECT_EQ(sink.rejected, std::vector<std::uint64_t>{0});
  EXPECT_EQ(sink.advice, std::vector<std::string>{"hold: no misalignment detected"});
  const std::vector<int> order = {0, 1, 2, 3};
  constexpr std::int64_t kBase = 1700000000000000000;
  for (int k = 0; k < 10; ++k) {
    const Message m = make_message(make_sample(k), order, kBase);
    node.compute_message(rcm::view_joint_state(m), m.stamp_ns, 0);
    if (k == 4) node.compute_message(rcm::view_joint_state(m), 0, 0);  // a zero stamp
  }
  // Estimates 3, 6 and 9 (1-based), stamped with their samples' stamps.
  ASSERT_EQ(sink.estimate_stamps.size(), 3u);
  EXPECT_EQ(sink.estimate_stamps[0], kBase + std::llround(make_sample(2).t * 1e9));
  EXPECT_EQ(sink.estimate_stamps[2], kBase + std::llround(make_sample(8).t * 1e9));
  EXPECT_EQ(sink.correction_stamps, sink.estimate_stamps);  // the correction travels with the estimate
  EXPECT_EQ(sink.rejected.back(), 1u);
  const std::string summary = node.get_summary();
  EXPECT_NE(summary.find("10 samples accepted, 1 rejected (duplicate stamp 0, out of order 0, zero stamp 1,"),
            std::string::npos)
      << summary;
  bool first_sample_logged = false;
  for (const auto& l : sink.lines) first_sample_logged |= l.find("3 joints by name: outer_yaw, outer_pitch, outer_insertion (the first message") != std::string::npos;
  EXPECT_TRUE(first_sample_logged);

  rcm::MonitorNodeParameters bad = p;
  bad.publish_every = 0;
  auto where = [](const std::string& name) { return rcm::InputLocation::plain("", name); };
  EXPECT_THROW(bad.check(where), rcm::InputError);
  bad = p;
  bad.correction.compensate_limit_m = 0.001;  // below the tolerance
  EXPECT_THROW(bad.check(where), rcm::InputError);
  bad = p;
  bad.joint_names = {"a", "a"};
  EXPECT_THROW(bad.check(where), rcm::InputError);
  EXPECT_EQ(rcm::parse_joint_names("[outer_yaw, 'outer_pitch']", where("joint_names")),
            (std::vector<std::string>{"outer_yaw", "outer_pitch"}));
  EXPECT_THROW(rcm::parse_joint_names("a,,b", where("joint_names")), rcm::InputError);
}

// Messages lost on the way are counted missing from the stamps and logged, not
// rejected: a message rejected in a gap held its slot, and one that arrives
// late fills its own back. A stream timed by its receive times is not judged.
TEST(MonitorNodeCore, CountsAndLogsTheMessagesAStreamSkipped) {
  rcm::MonitorNodeParameters p;
  p.session = "s.json";
  p.model_file = "m.json";
  p.status_period_s = 0;
  RecordingSink sink;
  rcm::MonitorNode node(p, std::make_unique<rcm::OnlinePipeline>(*make_pipeline()),
                        rcm::LiveMonitor::ZeroStamp::invalid, sink);
  const std::vector<int> order = {0, 1, 2, 3};
  auto send = [&](int k, bool nan = false) {
    Message m = make_message(make_sample(k), order, kBase);
    if (nan) m.position[0] = std::numeric_limits<double>::quiet_NaN();
    node.compute_message(rcm::view_joint_state(m), m.stamp_ns, m.stamp_ns);
  };
  for (int k = 0; k < 400; ++k) {
    if (k >= 100 && k < 105) continue;  // five lost
    if (k == 300 || k == 302) continue;  // two lost, one at a time
    if (k == 200) continue;              // sent after 201
    send(k, k == 150);                   // a NaN: received and rejected
    if (k == 201) send(200);
    if (k == 250) send(250);             // a duplicate
  }
  const auto& c = node.get_monitor().get_counters();
  EXPECT_EQ(c.missing, 7u);
  EXPECT_EQ(c.gaps, 3u);
  EXPECT_EQ(c.malformed, 1u);
  EXPECT_EQ(c.out_of_order, 1u);
  EXPECT_EQ(c.duplicate_stamp, 1u);
  EXPECT_EQ(node.get_monitor().get_median_interval_ns(), 2000000);
  int gap_lines = 0;
  for (const auto& l : sink.lines)
    if (l.find("missing before stamp") != std::string::npos) {
      ++gap_lines;
      if (gap_lines == 1) EXPECT_NE(l.find("5 message(s) missing before stamp 1700000000.210000 s: 12.0 ms"), std::string::npos) << l;
    }
  EXPECT_EQ(gap_lines, 4);  // 201's gap, taken back when 200 came late, was logged too
  EXPECT_NE(node.get_summary().find("7 missing in 3 gap(s) of the stamps"), std::string::npos) << node.get_summary();

  // Receive times jitter with the network, not with the publisher: not judged.
  rcm::MonitorNode unstamped(p, std::make_unique<rcm::OnlinePipeline>(*make_pipeline()),
                             rcm::LiveMonitor::ZeroStamp::receive_time_when_unstamped, sink);
  for (int k = 0; k < 200; ++k) {
    if (k == 100) continue;
    const Message m = make_message(make_sample(k), order, kBase);
    unstamped.compute_message(rcm::view_joint_state(m), 0, m.stamp_ns);
  }
  EXPECT_EQ(unstamped.get_monitor().get_counters().missing, 0u);
  EXPECT_TRUE(unstamped.get_monitor().uses_receive_time());
}

// With a model whose torque trails, an estimate is for the sample that long
// before: the node publishes nothing until the stream is that long, then each
// estimate once, stamped with its own sample's stamp, not the newest message's.
TEST(MonitorNodeCore, StampsADelayedEstimateWithItsSamplesStamp) {
  rcm::dynamics::TorqueModelInfo info;
  info.num_joints = info.num_outputs = 3;
  info.sample_period_s = 0.005;
  rcm::dynamics::LinearTorqueParameters lp{Eigen::VectorXd::Constant(17, 0.01), Eigen::VectorXd::Constant(3, 0.02),
                                           Eigen::VectorXd::Constant(3, 0.01),  Eigen::VectorXd::Constant(3, 0.01),
                                           Eigen::VectorXd::Constant(3, 0.0),   Eigen::VectorXd::Constant(3, 1e-3)};
  lp.batch_acceleration_window_s = Eigen::Vector3d(0.1, 0.1, 0.1);
  lp.live_zero_phase = true;
  const auto model = std::make_shared<const rcm::dynamics::LinearTorqueModel>(info, lp);
  const double delay_s = model->get_output_delay_s();
  ASSERT_NEAR(delay_s, 0.055, 1e-12);  // half the window and 5 ms
  rcm::JointTissueModel tissue;
  tissue.parameters = Eigen::Vector4d(875.0, 0.0, 2.0, 0.3);
  rcm::MonitorNodeParameters p;
  p.session = "s.json";
  p.model_file = "m.json";
  p.status_period_s = 0;
  RecordingSink sink;
  rcm::MonitorNode node(p,
                        std::make_unique<rcm::OnlinePipeline>(
                            model, rcm::OnlineEstimator(rcm::make_incision_frame(kQ0), tissue, rcm::OnlineEstimatorOptions{})),
                        rcm::LiveMonitor::ZeroStamp::invalid, sink);
  node.start("rt/PSM1/measured_js");
  constexpr std::int64_t kBase = 1700000000000000000;
  std::vector<std::int64_t> sent;
  for (int k = 0; k < 200; ++k) {  // 500 Hz
    const Message m = make_message(make_sample(k), {0, 1, 2, 3}, kBase);
    node.compute_message(rcm::view_joint_state(m), m.stamp_ns, 0);
    sent.push_back(m.stamp_ns);
    // The newest estimate is for the newest sample at least the delay old
    // (within the pairing's microsecond; a tie goes to the older sample).
    std::int64_t expected = -1;
    for (const std::int64_t s : sent)
      if (static_cast<double>(m.stamp_ns - s) * 1e-9 >= delay_s - 1e-6) expected = s;
    if (expected < 0) {
      ASSERT_TRUE(sink.estimate_stamps.empty()) << k;
      continue;
    }
    ASSERT_EQ(sink.estimate_stamps.size(), static_cast<std::size_t>(std::count_if(
                                               sent.begin(), sent.end(), [&](std::int64_t s) { return s <= expected; })))
        << k;
    ASSERT_EQ(sink.estimate_stamps.back(), expected) << k;
  }
  EXPECT_EQ(sink.correction_stamps, sink.estimate_stamps);
  EXPECT_EQ(sink.estimate_stamps.front(), kBase);
}

// The node's path per message: checks, estimate and the sink's calls, without
// allocating (only a log line may).
TEST(MonitorNodeCore, NoAllocationPerMessageAfterTheFirst) {
  struct CountingSink : rcm::MonitorSink {
    long estimates = 0, flags = 0, rejected = 0, lines = 0;
    void publish_estimate(std::int64_t, const rcm::OnlineOutput&) override { ++estimates; }
    void publish_flag(rcm::MonitorFlag, bool) override { ++flags; }
    void publish_rejected(std::uint64_t) override { ++rejected; }
    void publish_correction(std::int64_t, const rcm::CorrectionOutput&) override {}
    void publish_advice(const std::string&) override {}
    void log(rcm::LogLevel, const std::string&, double) override { ++lines; }
  } sink;
  rcm::MonitorNodeParameters p;
  p.session = "s.json";
  p.model_file = "m.json";
  p.status_period_s = 0;
  rcm::MonitorNode node(p, std::make_unique<rcm::OnlinePipeline>(*make_pipeline()),
                        rcm::LiveMonitor::ZeroStamp::invalid, sink);
  node.start("rt/PSM1/measured_js");
  const std::vector<int> order = {0, 1, 2, 3};
  constexpr std::int64_t kBase = 1700000000000000000;
  std::vector<Message> messages;
  for (int k = 0; k < 500; ++k) messages.push_back(make_message(make_sample(k), order, kBase));
  node.compute_message(rcm::view_joint_state(messages[0]), messages[0].stamp_ns, 0);
  // Message by message: a message that logs (onset, alarm, regime) may
  // allocate its line; every other must not allocate at all.
  std::size_t quiet = 0;
  for (std::size_t k = 1; k < messages.size(); ++k) {
    const long lines_before = sink.lines;
    const long before = g_allocations;
    node.compute_message(rcm::view_joint_state(messages[k]), messages[k].stamp_ns, 0);
    const long allocations = g_allocations - before;
    if (sink.lines != lines_before) continue;
    ++quiet;
    EXPECT_EQ(allocations, 0) << "message " << k;
  }
  EXPECT_GT(quiet, 450u);
  EXPECT_EQ(sink.estimates, 500);
}

}  // namespace
