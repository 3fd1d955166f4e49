// rcm_monitor_dds end to end, on the loopback interface only: a separate DDS
// participant (this test) publishes one simulated trial on rt/PSM1/measured_js
// as a ROS 2 dVRK would (RELIABLE, KEEP_LAST 100, VOLATILE; joints now and then
// in another order; a duplicate, an out-of-order, a zero-stamp, a NaN and a
// short message among them), paced at 1.5 kHz; the node's published
// estimates must equal `rcm monitor` on the same recording to 1e-9 m, every
// bad message must be rejected and counted, and the latched topics must follow
// the monitor's events. A lossy link's lost messages are counted missing. The
// DDS configuration in use must name `lo` only.

#include <gtest/gtest.h>
#include <dds/dds.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <regex>
#include <thread>

#include "child_process.hpp"
#include "monitor_reference.hpp"
#include "dds_test_fixture.hpp"
#include "rcm/io/recording.hpp"
#include "ros2_msgs.h"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using rcm::test::ChildProcess;
using rcm::test::read_text;
using rcm::test::wait_for;

using rcm::test::kModel;
using rcm::test::kSession;
using rcm::test::kTrial;
using rcm::test::run_cli;

dds_qos_t* make_qos(dds_reliability_kind_t r, dds_history_kind_t h, int depth, dds_durability_kind_t d) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, r, DDS_SECS(1));
  dds_qset_history(q, h, depth);
  dds_qset_durability(q, d);
  return q;
}

// Deletes a DDS entity (and what it holds) when the test returns, passed or not.
struct DeleteOnExit {
  dds_entity_t e;
  ~DeleteOnExit() { dds_delete(e); }
};

// A writer of rt/PSM1/measured_js as the dVRK's (KEEP_LAST 100, VOLATILE) with
// `reliability`; a DDS return code below zero on failure.
dds_entity_t make_joint_state_writer(dds_entity_t participant, dds_reliability_kind_t reliability) {
  const dds_entity_t topic = dds_create_topic(participant, &sensor_msgs_msg_dds__JointState__desc,
                                              "rt/PSM1/measured_js", nullptr, nullptr);
  if (topic < 0) return topic;
  dds_qos_t* q = make_qos(reliability, DDS_HISTORY_KEEP_LAST, 100, DDS_DURABILITY_VOLATILE);
  const dds_entity_t writer = dds_create_writer(participant, topic, q, nullptr);
  dds_delete_qos(q);
  return writer;
}

// One JointState_ sample built from sample k; owns the memory its pointers use.
struct JointStateSample {
  std::vector<std::string> names;
  std::vector<char*> name_ptrs;
  std::vector<double> position, velocity, effort;
  sensor_msgs_msg_dds__JointState_ msg{};
  char empty[1] = {0};

  JointStateSample(const rcm::Recording& rec, Eigen::Index k, std::int64_t stamp_ns, const std::vector<int>& order) {
    static const char* dvrk[] = {"outer_yaw", "outer_pitch", "outer_insertion", "outer_roll", "outer_wrist_pitch",
                                 "outer_wrist_yaw", "jaw"};
    for (int i = 0; i < rec.num_joints(); ++i) {
      const int j = order.empty() ? i : order[static_cast<std::size_t>(i)];
      names.push_back(dvrk[j]);
      position.push_back(rec.position(k, j));
      velocity.push_back(rec.velocity(k, j));
      effort.push_back(rec.effort(k, j));
    }
    set_stamp(stamp_ns);
  }
  void set_stamp(std::int64_t ns) {
    msg.header.stamp.sec = static_cast<std::int32_t>(ns / 1000000000);
    msg.header.stamp.nanosec = static_cast<std::uint32_t>(ns % 1000000000);
  }
  const void* get() {
    name_ptrs.clear();
    for (auto& n : names) name_ptrs.push_back(n.data());
    msg.header.frame_id = empty;
    msg.name = {static_cast<std::uint32_t>(names.size()), static_cast<std::uint32_t>(names.size()), name_ptrs.data(), false};
    msg.position = {static_cast<std::uint32_t>(position.size()), static_cast<std::uint32_t>(position.size()),
                    position.data(), false};
    msg.velocity = {static_cast<std::uint32_t>(velocity.size()), static_cast<std::uint32_t>(velocity.size()),
                    velocity.data(), false};
    msg.effort = {static_cast<std::uint32_t>(effort.size()), static_cast<std::uint32_t>(effort.size()), effort.data(),
                  false};
    return &msg;
  }
};

constexpr std::int64_t kStampBaseNs = 1700000000LL * 1000000000LL;

TEST(DdsMonitorNode, ConfigurationNamesLoopbackOnly) {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  ASSERT_NE(uri, nullptr) << "ctest sets CYCLONEDDS_URI to dds/cyclonedds-lo.xml";
  std::string path = uri;
  if (path.rfind("file://", 0) == 0) path = path.substr(7);
  const std::string xml = read_text(path);
  EXPECT_NE(xml.find("<NetworkInterface name=\"lo\""), std::string::npos) << xml;
  // No other interface, and no multicast anywhere.
  std::size_t interfaces = 0;
  for (std::size_t p = 0; (p = xml.find("<NetworkInterface", p)) != std::string::npos; ++p) ++interfaces;
  EXPECT_EQ(interfaces, 1u);
  EXPECT_NE(xml.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos);
  EXPECT_EQ(xml.find("NetworkInterfaceAddress"), std::string::npos);
  EXPECT_NE(xml.find("<Peer address=\"127.0.0.1\""), std::string::npos);
}

// A ROS 2 parameters file sets the defaults, flags override it, bad values are located errors.
TEST(DdsMonitorNode, ParametersFileAndFlags) {
  ASSERT_TRUE(fs::exists(kSession) && fs::exists(kModel)) << "run through ctest (fixture live_test_session)";
  const fs::path dir = fs::temp_directory_path() / ("rcm_test_dds_params_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path params = dir / "params.yaml";
  std::ofstream(params) << "/**:\n  ros__parameters:\n    session: " << kSession.string()
                        << "\n    model_file: " << kModel.string()
                        << "\n    arm: PSM2\n    joint_names: [outer_yaw, outer_pitch, outer_insertion]\n"
                           "    status_period_s: 0.0\n";
  ::setenv("ROS_DOMAIN_ID", std::to_string(130 + ::getpid() % 30).c_str(), 1);
  {
    ChildProcess node({RCM_DDS_NODE_PATH, "--params-file", params.string(), "--arm", "PSM3"}, dir / "node.log");
    const bool listening =
        wait_for([&] { return !node.alive() || node.log().find("listening on") != std::string::npos; }, 30s);
    const std::string log = node.log();
    EXPECT_TRUE(listening) << log;
    EXPECT_NE(log.find("listening on rt/PSM3/measured_js"), std::string::npos) << log;
    EXPECT_NE(log.find("publishing PSM3/rcm/{misalignment"), std::string::npos) << log;
    EXPECT_EQ(node.stop(10s), 0) << log;
  }
  auto fails = [&](const std::string& yaml, const std::vector<std::string>& args, const std::string& needle) {
    std::ofstream(params) << yaml;
    std::vector<std::string> argv = {RCM_DDS_NODE_PATH, "--params-file", params.string()};
    argv.insert(argv.end(), args.begin(), args.end());
    ChildProcess node(argv, dir / "bad.log");
    EXPECT_TRUE(wait_for([&] { return !node.alive(); }, 30s));
    EXPECT_EQ(node.stop(1s), 2) << node.log();
    EXPECT_NE(node.log().find(needle), std::string::npos) << node.log();
  };
  fails("/**:\n  ros__parameters:\n    arm: PSM1\n", {}, "session: missing");
  fails("/**:\n  ros__parameters:\n    sesion: x\n", {}, "rcm_monitor_dds.ros__parameters.sesion: unknown parameter");
  fails("/**:\n  ros__parameters:\n    publish_every: often\n", {}, "publish_every: wrong type");
  fails("rcm_monitor_dds:\n  ros__parameters:\n    session: " + kSession.string() + "\n    model_file: " +
            kModel.string() + "\n",
        {"--publish-every", "0"}, "publish_every: must be >= 1");
  fails("other_node:\n  ros__parameters:\n    arm: PSM1\n", {}, "'rcm_monitor_dds:' (or '/**:')");
  fs::remove_all(dir);
}

TEST(DdsMonitorNode, EndToEndAgreesWithRcmMonitor) {
  ASSERT_TRUE(fs::exists(kSession) && fs::exists(kModel)) << "run through ctest (fixture live_test_session)";
  const rcm::Recording rec = rcm::load_recording(kTrial);
  const auto monitor = run_cli("monitor --session " + kSession.string() + " --model-file " + kModel.string() +
                               " --json " + kTrial.string());
  ASSERT_EQ(monitor.status, 0);
  const nlohmann::json expected = nlohmann::json::parse(monitor.out);
  ASSERT_FALSE(expected["alarms"].empty()) << "the trial must raise the alarm";

  const fs::path dir = fs::temp_directory_path() / ("rcm_test_dds_node_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const int domain = 100 + ::getpid() % 30;  // a domain of its own (each DDS test has its range)
  ::setenv("ROS_DOMAIN_ID", std::to_string(domain).c_str(), 1);

  const dds_entity_t participant = dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr);
  ASSERT_GT(participant, 0) << dds_strretcode(participant);
  const DeleteOnExit delete_participant{participant};

  auto reader = [&](const dds_topic_descriptor_t* type, const char* name, bool latched) {
    const dds_entity_t t = dds_create_topic(participant, type, name, nullptr, nullptr);
    dds_qos_t* q = latched ? make_qos(DDS_RELIABILITY_RELIABLE, DDS_HISTORY_KEEP_ALL, 1, DDS_DURABILITY_TRANSIENT_LOCAL)
                           : make_qos(DDS_RELIABILITY_RELIABLE, DDS_HISTORY_KEEP_ALL, 1, DDS_DURABILITY_VOLATILE);
    const dds_entity_t r = dds_create_reader(participant, t, q, nullptr);
    dds_delete_qos(q);
    return r;
  };
  const dds_entity_t estimate_reader =
      reader(&geometry_msgs_msg_dds__Vector3Stamped__desc, "rt/PSM1/rcm/misalignment", false);
  const dds_entity_t sd_reader = reader(&geometry_msgs_msg_dds__Vector3Stamped__desc, "rt/PSM1/rcm/misalignment_sd", false);
  const dds_entity_t force_reader =
      reader(&geometry_msgs_msg_dds__WrenchStamped__desc, "rt/PSM1/rcm/incision_force", false);
  const dds_entity_t onset_reader = reader(&std_msgs_msg_dds__Bool__desc, "rt/PSM1/rcm/onset", true);
  const dds_entity_t alarm_reader = reader(&std_msgs_msg_dds__Bool__desc, "rt/PSM1/rcm/alarm", true);
  const dds_entity_t regime_reader = reader(&std_msgs_msg_dds__Bool__desc, "rt/PSM1/rcm/out_of_regime", true);
  const dds_entity_t rejected_reader = reader(&std_msgs_msg_dds__UInt64__desc, "rt/PSM1/rcm/rejected_samples", true);
  const dds_entity_t correction_reader =
      reader(&geometry_msgs_msg_dds__Vector3Stamped__desc, "rt/PSM1/rcm/correction", false);
  const dds_entity_t advice_reader = reader(&std_msgs_msg_dds__String__desc, "rt/PSM1/rcm/advice", true);
  for (dds_entity_t r : {estimate_reader, sd_reader, force_reader, onset_reader, alarm_reader, regime_reader,
                         rejected_reader, correction_reader, advice_reader})
    ASSERT_GT(r, 0) << dds_strretcode(r);

  const dds_entity_t writer = make_joint_state_writer(participant, DDS_RELIABILITY_RELIABLE);  // the dVRK's QoS
  ASSERT_GT(writer, 0) << dds_strretcode(writer);

  ChildProcess node({RCM_DDS_NODE_PATH, "--session", kSession.string(), "--model-file", kModel.string(),
                     "--queue-size", "100000", "--status-period-s", "0", "--joint-names",
                     "outer_yaw,outer_pitch,outer_insertion"},
                    dir / "node.log");
  ASSERT_TRUE(node.started());

  // What the node publishes, taken as it comes.
  std::size_t estimates = 0, sds = 0, forces = 0, corrections = 0;
  geometry_msgs_msg_dds__Vector3Stamped_ last_estimate{}, last_sd{}, last_correction{};
  std::string correction_frame;
  std::vector<std::string> advice;
  geometry_msgs_msg_dds__WrenchStamped_ last_force{};
  std::string estimate_frame, force_frame;
  std::vector<bool> onset, alarm, regime;
  std::uint64_t rejected = 0;
  std::size_t rejected_messages = 0;
  auto drain = [&] {
    void* samples[256] = {};
    dds_sample_info_t infos[256];
    auto take = [&](dds_entity_t r, const std::function<void(const void*)>& f) {
      while (true) {
        for (void*& s : samples) s = nullptr;
        const dds_return_t n = dds_take(r, samples, infos, 256, 256);
        if (n <= 0) return;
        for (dds_return_t i = 0; i < n; ++i)
          if (infos[i].valid_data) f(samples[i]);
        dds_return_loan(r, samples, n);
      }
    };
    take(estimate_reader, [&](const void* s) {
      last_estimate = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(s);
      estimate_frame = last_estimate.header.frame_id;
      ++estimates;
    });
    take(sd_reader, [&](const void* s) {
      last_sd = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(s);
      ++sds;
    });
    take(force_reader, [&](const void* s) {
      last_force = *static_cast<const geometry_msgs_msg_dds__WrenchStamped_*>(s);
      force_frame = last_force.header.frame_id;
      ++forces;
    });
    take(correction_reader, [&](const void* s) {
      last_correction = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(s);
      correction_frame = last_correction.header.frame_id;
      ++corrections;
    });
    take(advice_reader, [&](const void* s) { advice.emplace_back(static_cast<const std_msgs_msg_dds__String_*>(s)->data); });
    take(onset_reader, [&](const void* s) { onset.push_back(static_cast<const std_msgs_msg_dds__Bool_*>(s)->data); });
    take(alarm_reader, [&](const void* s) { alarm.push_back(static_cast<const std_msgs_msg_dds__Bool_*>(s)->data); });
    take(regime_reader, [&](const void* s) { regime.push_back(static_cast<const std_msgs_msg_dds__Bool_*>(s)->data); });
    take(rejected_reader, [&](const void* s) {
      rejected = static_cast<const std_msgs_msg_dds__UInt64_*>(s)->data;
      ++rejected_messages;
    });
  };
  auto matched = [&](dds_entity_t r) {
    dds_subscription_matched_status_t st;
    return dds_get_subscription_matched_status(r, &st) == DDS_RETCODE_OK && st.current_count > 0;
  };
  const bool up = wait_for(
      [&] {
        drain();
        dds_publication_matched_status_t pm;
        return !node.alive() || (dds_get_publication_matched_status(writer, &pm) == DDS_RETCODE_OK &&
                                 pm.current_count > 0 && rcm::test::node_matched_joint_states(node.log()) &&
                                 matched(estimate_reader) && matched(sd_reader) &&
                                 matched(force_reader) && matched(correction_reader) && !advice.empty() &&
                                 !onset.empty() && !alarm.empty() && !regime.empty() &&
                                 rejected_messages > 0);
      },
      60s);
  ASSERT_TRUE(up && node.alive()) << "the node did not come up:\n" << node.log();

  // The trial at 1.5 kHz (the dVRK's fastest rate), bad messages among the samples.
  const Eigen::Index T = rec.time.size();
  std::size_t injected = 0;
  const auto start = Clock::now();
  for (Eigen::Index k = 0; k < T; ++k) {
    std::this_thread::sleep_until(start + std::chrono::microseconds(k * 2000 / 3));
    const std::int64_t stamp = kStampBaseNs + std::llround(rec.time(k) * 1e9);
    JointStateSample good(rec, k, stamp, k % 5 == 0 ? std::vector<int>{2, 0, 1} : std::vector<int>{});
    ASSERT_EQ(dds_write(writer, good.get()), DDS_RETCODE_OK);
    std::optional<JointStateSample> bad;
    if (k == 100) bad.emplace(rec, k, stamp, std::vector<int>{});                                      // same stamp
    if (k == 200) bad.emplace(rec, k - 50, kStampBaseNs + std::llround(rec.time(k - 50) * 1e9), std::vector<int>{});
    if (k == 250) bad.emplace(rec, k, 0, std::vector<int>{});                                          // zero stamp
    if (k == 300 || k == 400) {
      bad.emplace(rec, k, stamp + 1000000, std::vector<int>{});
      if (k == 300) bad->effort[1] = std::numeric_limits<double>::quiet_NaN();
      if (k == 400) bad->velocity.pop_back();
    }
    if (bad) {
      ASSERT_EQ(dds_write(writer, bad->get()), DDS_RETCODE_OK);
      ++injected;
    }
    if (k % 500 == 0) drain();
    // The node stopped for 0.3 s (450 samples, more than the dVRK's own
    // history of 100) as a busy machine may stop it: it catches up, losing nothing.
    if (k == T / 2) node.send(SIGSTOP);
    if (k == T / 2 + 450) node.send(SIGCONT);
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  // The last estimate is for the last sample, or, with a model whose torque
  // trails, for the sample that long before it; stamped with its stamp.
  const auto last_estimated = static_cast<Eigen::Index>(rcm::test::get_expected_estimates(expected)) - 1;
  ASSERT_GE(last_estimated, 0);
  const std::int64_t last_stamp = kStampBaseNs + std::llround(rec.time(last_estimated) * 1e9);
  auto stamp_of = [](const std_msgs_msg_dds__Header_& h) {
    return static_cast<std::int64_t>(h.stamp.sec) * 1000000000 + h.stamp.nanosec;
  };
  const bool finished = wait_for(
      [&] {
        drain();
        return !node.alive() || (estimates > 0 && stamp_of(last_estimate.header) == last_stamp &&
                                 stamp_of(last_sd.header) == last_stamp && stamp_of(last_force.header) == last_stamp);
      },
      60s);
  std::this_thread::sleep_for(300ms);  // the latched topics' last changes
  drain();
  const int node_exit = node.stop(10s);
  const std::string node_log = node.log();
  ASSERT_TRUE(finished) << "no estimate for the last sample within 60 s:\n" << node_log;
  EXPECT_EQ(node_exit, 0) << node_log;
  std::cout << "[ node     ] " << T << " samples + " << injected << " bad messages published at 1.5 kHz in " << seconds
            << " s\n";
  rcm::test::print_node_log_lines(node_log, {"samples accepted", "per sample:", "publishing (own thread)"});

  rcm::test::expect_every_sample_answered(node_log, expected, static_cast<std::size_t>(T), injected, estimates, sds, forces,
                                          rejected);
  EXPECT_NE(node_log.find("zero stamp 1,"), std::string::npos) << node_log;
  EXPECT_NE(node_log.find(", 0 outputs dropped"), std::string::npos) << node_log;
  EXPECT_NE(node_log.find("3 joints by name: outer_yaw, outer_pitch, outer_insertion; time from header.stamp"),
            std::string::npos)
      << node_log;
  EXPECT_EQ(estimate_frame, "PSM1_incision");
  EXPECT_EQ(force_frame, "PSM1_base");
  EXPECT_EQ(correction_frame, "PSM1_base");
  EXPECT_EQ(corrections, estimates);
  rcm::test::expect_final_correction(expected,
                                     {last_correction.vector.x, last_correction.vector.y, last_correction.vector.z});
  EXPECT_EQ(advice, rcm::test::get_expected_advice(expected));

  const auto& fin = expected["final"];
  const double estimate[3] = {last_estimate.vector.x, last_estimate.vector.y, last_estimate.vector.z};
  const double sd[3] = {last_sd.vector.x, last_sd.vector.y, last_sd.vector.z};
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(estimate[i], fin["misalignment_m"][i].get<double>(), 1e-9) << "offset " << i;
    EXPECT_NEAR(sd[i], fin["sd_m"][i].get<double>(), 1e-9) << "sd " << i;
  }
  const std::vector<bool> expected_alarm = rcm::test::get_expected_alarm(expected);
  EXPECT_EQ(alarm, expected_alarm);
  const std::vector<bool> expected_onset = rcm::test::get_expected_onset(expected);
  EXPECT_EQ(onset, expected_onset);
  ASSERT_FALSE(regime.empty());
  EXPECT_FALSE(regime.front());
  if (::testing::Test::HasFailure()) std::cout << "node log:\n" << node_log;
  fs::remove_all(dir);
}

// A lossy link: the publisher, best effort, drops a fifth of its packets on
// the way out (Cyclone's Internal/Test/XmitLossiness, in this process only).
// DDS tells the node nothing; the node counts every lost message it can see
// as missing: all but those before its first median interval (16 intervals)
// and after the last sample it received.
TEST(DdsMonitorNode, CountsTheMessagesALossyLinkLost) {
  ASSERT_TRUE(fs::exists(kSession) && fs::exists(kModel)) << "run through ctest (fixture live_test_session)";
  const rcm::Recording rec = rcm::load_recording(kTrial);
  const fs::path dir = fs::temp_directory_path() / ("rcm_test_dds_lossy_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const int domain = 1 + ::getpid() % 39;  // the range of this test alone
  const char* uri = std::getenv("CYCLONEDDS_URI");
  ASSERT_NE(uri, nullptr) << "ctest sets CYCLONEDDS_URI to dds/cyclonedds-lo.xml";
  std::string config = read_text(std::string(uri).substr(std::string(uri).rfind("file://", 0) == 0 ? 7 : 0));
  const std::size_t end = config.find("</Domain>");
  ASSERT_NE(end, std::string::npos);
  config.insert(end, "<Internal><Test><XmitLossiness>200</XmitLossiness></Test></Internal>");
  const dds_entity_t lossy = dds_create_domain(static_cast<dds_domainid_t>(domain), config.c_str());
  ASSERT_GT(lossy, 0) << dds_strretcode(lossy);
  const DeleteOnExit delete_domain{lossy};
  const dds_entity_t participant = dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr);
  ASSERT_GT(participant, 0) << dds_strretcode(participant);
  const dds_entity_t writer = make_joint_state_writer(participant, DDS_RELIABILITY_BEST_EFFORT);
  ASSERT_GT(writer, 0) << dds_strretcode(writer);

  ChildProcess node({RCM_DDS_NODE_PATH, "--session", kSession.string(), "--model-file", kModel.string(), "--domain",
                     std::to_string(domain), "--best-effort", "--queue-size", "100000", "--status-period-s", "0",
                     "--joint-names", "outer_yaw,outer_pitch,outer_insertion"},
                    dir / "node.log");
  ASSERT_TRUE(node.started());
  const bool up = wait_for(
      [&] {
        dds_publication_matched_status_t pm;
        return !node.alive() || (dds_get_publication_matched_status(writer, &pm) == DDS_RETCODE_OK &&
                                 pm.current_count > 0 && rcm::test::node_matched_joint_states(node.log()));
      },
      60s);
  ASSERT_TRUE(up && node.alive()) << "the node did not come up:\n" << node.log();

  const Eigen::Index sent = std::min<Eigen::Index>(rec.time.size(), 3000);
  const auto start = Clock::now();
  for (Eigen::Index k = 0; k < sent; ++k) {
    std::this_thread::sleep_until(start + std::chrono::microseconds(k * 2000 / 3));
    JointStateSample sample(rec, k, kStampBaseNs + std::llround(rec.time(k) * 1e9), {});
    ASSERT_EQ(dds_write(writer, sample.get()), DDS_RETCODE_OK);
  }
  std::this_thread::sleep_for(500ms);
  const int node_exit = node.stop(10s);
  const std::string node_log = node.log();
  EXPECT_EQ(node_exit, 0) << node_log;
  rcm::test::print_node_log_lines(node_log, {"samples accepted"});

  const std::regex summary(R"(rcm: ([0-9]+) samples accepted, ([0-9]+) rejected .*; ([0-9]+) missing in ([0-9]+) gap)");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(node_log, m, summary)) << node_log;
  const long accepted = std::stol(m[1]), rejected = std::stol(m[2]), missing = std::stol(m[3]), gaps = std::stol(m[4]);
  const long lost = static_cast<long>(sent) - accepted;
  EXPECT_EQ(rejected, 0);
  EXPECT_GT(lost, sent / 10) << "the link lost too few messages to test:\n" << node_log;
  EXPECT_LE(missing, lost);
  EXPECT_GE(missing, lost - 30) << node_log;
  EXPECT_GT(gaps, 0);
  EXPECT_LE(gaps, missing);
  EXPECT_NE(node_log.find("message(s) missing before stamp"), std::string::npos) << node_log;
  fs::remove_all(dir);
}

}  // namespace
