// rcm_monitor_node end to end: a private ROS master on 127.0.0.1 and a free
// port, the node started on the fixture's quick simulated session and linear
// model, one trial published as the dVRK would (joints now and then in another
// order, plus a duplicate, an out-of-order, a NaN and a short message), and the
// node's last published estimate compared with `rcm monitor --json` on the
// same recording; the alarm and onset topics must follow the monitor's events.
// The joint order is given as ~joint_names (a comma-separated string).
// Every process is stopped on every path (RAII, and PR_SET_PDEATHSIG should the
// test itself die); every wait has a timeout.

#include <gtest/gtest.h>

#include <geometry_msgs/Vector3Stamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <ros/ros.h>
#include <std_msgs/Bool.h>
#include <std_msgs/String.h>
#include <std_msgs/UInt64.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>

#include <chrono>
#include <cstdlib>
#include <functional>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "rcm/io/recording.hpp"
#include "child_process.hpp"
#include "monitor_reference.hpp"
#include "ros_test_util.hpp"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using rcm::test::ChildProcess;
using rcm::test::wait_for;

int find_free_port() {
  const int s = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof addr;
  if (s < 0 || ::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      ::getsockname(s, reinterpret_cast<sockaddr*>(&addr), &len) != 0)
    return -1;
  const int port = ntohs(addr.sin_port);
  ::close(s);
  return port;
}

// What the node published, as received.
struct Received {
  std::mutex mutex;
  std::size_t estimates = 0, sds = 0, forces = 0, corrections = 0;
  geometry_msgs::Vector3Stamped last_estimate, last_sd, last_correction;
  std::vector<std::string> advice;
  geometry_msgs::WrenchStamped last_force;
  std::vector<bool> onset, alarm, out_of_regime;
  std::uint64_t rejected = 0;
  std::size_t rejected_messages = 0;
};

TEST(MonitorNode, EndToEndAgreesWithRcmMonitor) {
  ASSERT_TRUE(rcm::test::fixture_present()) << rcm::test::kFixtureHint;
  ASSERT_STRNE(RCM_ROSMASTER_PATH, "") << "rosmaster not found at configure time: install python3-rosmaster "
                                          "(make deps) and re-run cmake";
  const rcm::Recording rec = rcm::load_recording(rcm::test::get_trial_csv());
  ASSERT_TRUE(rec.has_force());
  ASSERT_GT(rec.force->rowwise().norm().maxCoeff(), 10.0) << "the trial's force must exceed the 10 N alarm threshold";

  // What `rcm monitor` says on the same recording (the reference).
  const auto monitor = rcm::test::run_cli("monitor --session " + rcm::test::get_session_manifest().string() +
                                          " --model-file " + rcm::test::get_model_file().string() + " --json " +
                                          rcm::test::get_trial_csv().string());
  ASSERT_EQ(monitor.status, 0) << monitor.err;
  const nlohmann::json expected = nlohmann::json::parse(monitor.out);
  ASSERT_FALSE(expected["alarms"].empty()) << "the trial must raise the alarm";

  const fs::path dir = fs::temp_directory_path() / ("rcm_test_ros_node_" + std::to_string(::getpid()));
  fs::create_directories(dir / "ros_log");
  struct RemoveDir {
    fs::path p;
    bool keep = false;
    ~RemoveDir() {
      if (!keep) fs::remove_all(p);
    }
  } remove_dir{dir};

  // A private master; the environment is this test process's (children inherit it).
  const int port = find_free_port();
  ASSERT_GT(port, 0);
  ::setenv("ROS_MASTER_URI", ("http://127.0.0.1:" + std::to_string(port)).c_str(), 1);
  ::setenv("ROS_IP", "127.0.0.1", 1);
  ::unsetenv("ROS_HOSTNAME");
  ::unsetenv("ROS_NAMESPACE");
  ::setenv("ROS_HOME", dir.c_str(), 1);
  ::setenv("ROS_LOG_DIR", (dir / "ros_log").c_str(), 1);
  ChildProcess master({RCM_ROSMASTER_PATH, "--core", "-p", std::to_string(port), "-w", "3"}, dir / "master.log");
  ASSERT_TRUE(master.started());

  int argc = 1;
  char arg0[] = "test_ros_monitor_node";
  char* argv[] = {arg0, nullptr};
  ros::init(argc, argv, "rcm_test_player", ros::init_options::NoSigintHandler | ros::init_options::AnonymousName);
  struct Shutdown {
    ~Shutdown() { ros::shutdown(); }
  } shutdown_ros_first;  // destroyed before the children: unregister while the master lives
  ASSERT_TRUE(wait_for([&] { return ros::master::check() || !master.alive(); }, 15s)) << master.log();
  ASSERT_TRUE(master.alive()) << master.log();

  ros::NodeHandle nh;
  Received got;
  auto sub_estimate = nh.subscribe<geometry_msgs::Vector3Stamped>(
      "/PSM1/rcm/misalignment", 100000, [&](const geometry_msgs::Vector3Stamped::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(got.mutex);
        ++got.estimates;
        got.last_estimate = *m;
      });
  auto sub_sd = nh.subscribe<geometry_msgs::Vector3Stamped>(
      "/PSM1/rcm/misalignment_sd", 100000, [&](const geometry_msgs::Vector3Stamped::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(got.mutex);
        ++got.sds;
        got.last_sd = *m;
      });
  auto sub_force = nh.subscribe<geometry_msgs::WrenchStamped>(
      "/PSM1/rcm/incision_force", 100000, [&](const geometry_msgs::WrenchStamped::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(got.mutex);
        ++got.forces;
        got.last_force = *m;
      });
  auto sub_correction = nh.subscribe<geometry_msgs::Vector3Stamped>(
      "/PSM1/rcm/correction", 100000, [&](const geometry_msgs::Vector3Stamped::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(got.mutex);
        ++got.corrections;
        got.last_correction = *m;
      });
  auto sub_advice = nh.subscribe<std_msgs::String>("/PSM1/rcm/advice", 1000, [&](const std_msgs::String::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(got.mutex);
    got.advice.push_back(m->data);
  });
  auto sub_onset = nh.subscribe<std_msgs::Bool>("/PSM1/rcm/onset", 1000, [&](const std_msgs::Bool::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(got.mutex);
    got.onset.push_back(m->data);
  });
  auto sub_alarm = nh.subscribe<std_msgs::Bool>("/PSM1/rcm/alarm", 1000, [&](const std_msgs::Bool::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(got.mutex);
    got.alarm.push_back(m->data);
  });
  auto sub_regime = nh.subscribe<std_msgs::Bool>("/PSM1/rcm/out_of_regime", 1000,
                                                 [&](const std_msgs::Bool::ConstPtr& m) {
                                                   std::lock_guard<std::mutex> lock(got.mutex);
                                                   got.out_of_regime.push_back(m->data);
                                                 });
  auto sub_rejected = nh.subscribe<std_msgs::UInt64>("/PSM1/rcm/rejected_samples", 1000,
                                                     [&](const std_msgs::UInt64::ConstPtr& m) {
                                                       std::lock_guard<std::mutex> lock(got.mutex);
                                                       got.rejected = m->data;
                                                       ++got.rejected_messages;
                                                     });
  const Eigen::Index T = rec.time.size();
  ros::Publisher pub = nh.advertise<sensor_msgs::JointState>("/PSM1/measured_js", static_cast<std::uint32_t>(T + 100));
  ros::AsyncSpinner spinner(2);
  spinner.start();

  ChildProcess node({RCM_NODE_PATH, "__name:=rcm_monitor_test", "_session:=" + rcm::test::get_session_manifest().string(),
                     "_model_file:=" + rcm::test::get_model_file().string(), "_queue_size:=100000",
                     "_status_period_s:=0", "_joint_names:=outer_yaw,outer_pitch,outer_insertion"},
                    dir / "node.log");
  ASSERT_TRUE(node.started());
  const bool connected = wait_for(
      [&] {
        std::lock_guard<std::mutex> lock(got.mutex);
        return !node.alive() || (pub.getNumSubscribers() > 0 && sub_estimate.getNumPublishers() > 0 &&
                                 sub_sd.getNumPublishers() > 0 && sub_force.getNumPublishers() > 0 &&
                                 sub_correction.getNumPublishers() > 0 && !got.advice.empty() &&
                                 !got.onset.empty() && !got.alarm.empty() && got.rejected_messages > 0 &&
                                 !got.out_of_regime.empty());
      },
      60s);
  remove_dir.keep = !connected;
  ASSERT_TRUE(connected && node.alive()) << "the node did not come up:\n" << node.log();

  // The trial, as the robot publishes it, with bad messages among the samples.
  const auto start = Clock::now();
  std::size_t injected = 0;
  for (Eigen::Index k = 0; k < T; ++k) {
    // The order is given by ~joint_names: even the first message may come in another.
    pub.publish(rcm::test::make_joint_state(rec, k, k % 5 == 0 ? std::vector<int>{2, 0, 1} : std::vector<int>{}));
    sensor_msgs::JointState bad;
    if (k == 100) bad = rcm::test::make_joint_state(rec, k);  // the same stamp again
    if (k == 200) bad = rcm::test::make_joint_state(rec, k - 50);  // an old one
    if (k == 300 || k == 400) {
      bad = rcm::test::make_joint_state(rec, k);
      bad.header.stamp += ros::Duration(0.001);
      if (k == 300) bad.effort[1] = std::numeric_limits<double>::quiet_NaN();
      if (k == 400) bad.velocity.pop_back();
    }
    if (!bad.position.empty()) {
      pub.publish(bad);
      ++injected;
    }
  }
  // The last estimate is for the last sample, or, with a model whose torque
  // trails, for the sample that long before it; stamped with its stamp.
  const auto last_estimated = static_cast<Eigen::Index>(rcm::test::get_expected_estimates(expected)) - 1;
  ASSERT_GE(last_estimated, 0);
  const ros::Time last_stamp = rcm::test::make_joint_state(rec, last_estimated).header.stamp;
  const bool finished = wait_for(
      [&] {
        std::lock_guard<std::mutex> lock(got.mutex);
        return !node.alive() || (got.estimates > 0 && got.last_estimate.header.stamp == last_stamp &&
                                 got.last_sd.header.stamp == last_stamp && got.last_force.header.stamp == last_stamp);
      },
      60s);
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  std::this_thread::sleep_for(200ms);  // the latched topics' last changes
  const int node_exit = node.stop(10s);
  const std::string node_log = node.log();
  remove_dir.keep = !finished;
  ASSERT_TRUE(finished) << "no estimate for the last sample within 60 s:\n" << node_log;
  EXPECT_EQ(node_exit, 0) << node_log;

  std::lock_guard<std::mutex> lock(got.mutex);
  std::cout << "[ node     ] " << T << " samples + " << injected << " bad messages published and answered in " << seconds
            << " s\n";
  rcm::test::print_node_log_lines(node_log, {"samples accepted", "per sample:", "rcm: regime:", "samples estimated"});
  // Every sample answered once, the bad ones rejected and counted.
  rcm::test::expect_every_sample_answered(node_log, expected, static_cast<std::size_t>(T), injected, got.estimates, got.sds,
                                          got.forces, got.rejected);
  EXPECT_NE(node_log.find("3 joints by name: outer_yaw, outer_pitch, outer_insertion; time from header.stamp"),
            std::string::npos);
  EXPECT_EQ(got.last_estimate.header.frame_id, "PSM1_incision");
  EXPECT_EQ(got.last_force.header.frame_id, "PSM1_base");
  EXPECT_EQ(got.last_correction.header.frame_id, "PSM1_base");
  EXPECT_EQ(got.corrections, got.estimates);
  EXPECT_EQ(got.last_correction.header.stamp, last_stamp);

  // The same pipeline: the same final estimate as rcm monitor.
  const auto& fin = expected["final"];
  const double estimate[3] = {got.last_estimate.vector.x, got.last_estimate.vector.y, got.last_estimate.vector.z};
  const double sd[3] = {got.last_sd.vector.x, got.last_sd.vector.y, got.last_sd.vector.z};
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(estimate[i], fin["misalignment_m"][i].get<double>(), 1e-9) << "offset " << i;
    EXPECT_NEAR(sd[i], fin["sd_m"][i].get<double>(), 1e-9) << "sd " << i;
  }

  // The correction and its advice, as rcm monitor says them.
  rcm::test::expect_final_correction(
      expected, {got.last_correction.vector.x, got.last_correction.vector.y, got.last_correction.vector.z});
  EXPECT_EQ(got.advice, rcm::test::get_expected_advice(expected));
  // Alarm: false at start, then raised and cleared as rcm monitor reports.
  const std::vector<bool> expected_alarm = rcm::test::get_expected_alarm(expected);
  EXPECT_EQ(got.alarm, expected_alarm);
  // Onset: false at start, true once.
  const std::vector<bool> expected_onset = rcm::test::get_expected_onset(expected);
  EXPECT_EQ(got.onset, expected_onset);
  // Regime: false at start; the same count of flagged samples as rcm monitor.
  ASSERT_FALSE(got.out_of_regime.empty());
  EXPECT_FALSE(got.out_of_regime.front());
  const auto flagged = expected["regime"]["flagged"].get<std::size_t>();
  if (flagged == 0) {
    EXPECT_EQ(got.out_of_regime.size(), 1u);
    EXPECT_NE(node_log.find("rcm: regime: all " + std::to_string(last_estimated + 1) + " samples inside"),
              std::string::npos);
  } else {
    EXPECT_GT(got.out_of_regime.size(), 1u);
    EXPECT_NE(node_log.find("outside the free-space model's training regime"), std::string::npos);
  }
  if (::testing::Test::HasFailure()) std::cout << "node log:\n" << node_log;
}

}  // namespace
