// The rosbag reader: a simulated trial written as a bag (as the dVRK records it)
// reads back sample by sample as its CSV, through load_bag_recording, through
// load_recording once registered, and through the CLI (inspect, convert,
// monitor); bad bags give errors that name the file, the topic, the message and
// the field, and a non-zero exit in the CLI.

#include <gtest/gtest.h>

#include <limits>
#include <nlohmann/json.hpp>

#include "rcm/common/error.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"
#include "rcm/ros/bag_reader.hpp"
#include "ros_test_util.hpp"

namespace {

namespace fs = std::filesystem;
using rcm::test::run_cli;

class BagTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(rcm::test::fixture_present()) << rcm::test::kFixtureHint;
    dir_ = fs::temp_directory_path() / ("rcm_test_ros_bag_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// Values exact; time within the 1 ns of the stamps (and from the first sample).
void expect_same_samples(const rcm::Recording& bag, const rcm::Recording& csv) {
  ASSERT_EQ(bag.num_samples(), csv.num_samples());
  ASSERT_EQ(bag.num_joints(), csv.num_joints());
  for (Eigen::Index k = 0; k < csv.time.size(); ++k) {
    ASSERT_NEAR(bag.time(k), csv.time(k) - csv.time(0), 1e-9) << "sample " << k;
    for (int j = 0; j < csv.num_joints(); ++j) {
      ASSERT_EQ(bag.position(k, j), csv.position(k, j)) << "sample " << k << " joint " << j;
      ASSERT_EQ(bag.velocity(k, j), csv.velocity(k, j)) << "sample " << k << " joint " << j;
      ASSERT_EQ(bag.effort(k, j), csv.effort(k, j)) << "sample " << k << " joint " << j;
    }
  }
}

TEST_F(BagTest, RoundTripSampleBySample) {
  const rcm::Recording csv = rcm::load_recording(rcm::test::get_trial_csv());
  ASSERT_TRUE(csv.has_force());
  ASSERT_GT(csv.num_samples(), 5000u);  // the quick trial: 30 s at 200 Hz
  const fs::path bag = dir_ / "trial.bag";
  rcm::test::write_bag(bag, csv, "/PSM1/measured_js", "/PSM1/force_sensor");

  rcm::BagReadInfo info;
  rcm::BagReadOptions options;
  options.force_topic = "/PSM1/force_sensor";
  const rcm::Recording r = rcm::load_bag_recording(bag, options, &info);
  expect_same_samples(r, csv);
  ASSERT_TRUE(r.has_force());
  EXPECT_EQ(*r.force, *csv.force);  // same stamps: no interpolation error
  EXPECT_EQ(r.layout, rcm::RecordingLayout::rosbag);
  EXPECT_EQ(r.source, bag.string());
  EXPECT_EQ(info.joint_names, rcm::test::make_joint_names(3));
  EXPECT_FALSE(info.bag_time);
  EXPECT_EQ(info.time_origin_ns, rcm::test::to_stamp_ns(csv.time(0)));
  EXPECT_EQ(info.messages, csv.num_samples());
  EXPECT_EQ(info.force_frame_id, "PSM1_base");

  // Without a force topic: no force columns. Through load_recording once registered.
  rcm::register_bag_recording_reader();
  const rcm::Recording via_registry = rcm::load_recording(bag);
  expect_same_samples(via_registry, csv);
  EXPECT_FALSE(via_registry.has_force());
}

TEST_F(BagTest, ZeroStampsUseTheBagTimeAndNamesMapByName) {
  const rcm::Recording csv = rcm::load_recording(rcm::test::get_trial_csv());
  const fs::path bag_path = dir_ / "zero_stamps.bag";
  {
    rosbag::Bag bag;
    bag.open(bag_path.string(), rosbag::bagmode::Write);
    for (Eigen::Index k = 0; k < csv.time.size(); ++k) {
      // Joints in another order every third message; stamps never set.
      sensor_msgs::JointState m = rcm::test::make_joint_state(csv, k, k % 3 == 1 ? std::vector<int>{2, 0, 1} : std::vector<int>{});
      const ros::Time t = m.header.stamp;
      m.header.stamp = ros::Time();
      bag.write("/PSM1/measured_js", t, m);
    }
    bag.close();
  }
  rcm::BagReadInfo info;
  const rcm::Recording r = rcm::load_bag_recording(bag_path, {}, &info);
  EXPECT_TRUE(info.bag_time);
  expect_same_samples(r, csv);

  // An explicit order by name.
  rcm::BagReadOptions options;
  options.joint_names = {"outer_insertion", "outer_yaw", "outer_pitch"};
  const rcm::Recording reordered = rcm::load_bag_recording(bag_path, options);
  EXPECT_EQ(reordered.position.col(0), csv.position.col(2));
  EXPECT_EQ(reordered.effort.col(1), csv.effort.col(0));
}

// A small bag of `n` messages of the trial, `edit` changing message k before it is written.
template <typename Edit>
fs::path write_small_bag(const fs::path& path, const rcm::Recording& rec, int n, Edit edit) {
  rosbag::Bag bag;
  bag.open(path.string(), rosbag::bagmode::Write);
  for (int k = 0; k < n; ++k) {
    sensor_msgs::JointState m = rcm::test::make_joint_state(rec, k);
    edit(k, m);
    bag.write("/PSM1/measured_js", ros::Time(1.0 + k), m);
  }
  bag.close();
  return path;
}

std::string read_error(const fs::path& bag, const rcm::BagReadOptions& options = {}) {
  try {
    rcm::load_bag_recording(bag, options);
  } catch (const rcm::InputError& e) {
    return e.what();
  }
  return "no error";
}

void expect_contains(const std::string& text, const std::vector<std::string>& parts) {
  for (const auto& p : parts) EXPECT_NE(text.find(p), std::string::npos) << "'" << p << "' not in: " << text;
}

TEST_F(BagTest, BadBagsGiveLocatedErrors) {
  const rcm::Recording csv = rcm::load_recording(rcm::test::get_trial_csv());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const fs::path good = write_small_bag(dir_ / "good.bag", csv, 10, [](int, sensor_msgs::JointState&) {});
  ASSERT_EQ(rcm::load_bag_recording(good).num_samples(), 10u);

  // Wrong topic: the error lists what the bag has.
  rcm::BagReadOptions other;
  other.topic = "/PSM2/measured_js";
  expect_contains(read_error(good, other),
                  {good.string(), "/PSM2/measured_js", "no messages", "/PSM1/measured_js (sensor_msgs/JointState, 10 messages)"});
  // A topic of another type.
  {
    const fs::path p = dir_ / "wrench.bag";
    rosbag::Bag bag;
    bag.open(p.string(), rosbag::bagmode::Write);
    geometry_msgs::WrenchStamped w;
    w.header.stamp = ros::Time(1.0);
    bag.write("/PSM1/measured_js", ros::Time(1.0), w);
    bag.close();
    expect_contains(read_error(p), {"/PSM1/measured_js", "has type geometry_msgs/WrenchStamped, expected sensor_msgs/JointState"});
  }
  // NaN.
  expect_contains(read_error(write_small_bag(dir_ / "nan.bag", csv, 10,
                                             [&](int k, sensor_msgs::JointState& m) { if (k == 7) m.effort[2] = nan; })),
                  {"nan.bag", "/PSM1/measured_js message 7", "effort[2] ('outer_insertion')", "expected a finite number"});
  // Time going back.
  expect_contains(read_error(write_small_bag(dir_ / "back.bag", csv, 10,
                                             [&](int k, sensor_msgs::JointState& m) {
                                               if (k == 5) m.header.stamp.fromNSec(rcm::test::to_stamp_ns(csv.time(2)));
                                             })),
                  {"back.bag", "/PSM1/measured_js message 5", "header.stamp", "time must increase strictly", "in message 4"});
  // A repeated stamp with a repeated sample: the hint to --dedupe, which then reads it.
  const fs::path repeat = write_small_bag(dir_ / "repeat.bag", csv, 10, [&](int k, sensor_msgs::JointState& m) {
    if (k == 6) m = rcm::test::make_joint_state(csv, 5);
  });
  expect_contains(read_error(repeat), {"message 6", "--dedupe"});
  rcm::BagReadOptions dedupe;
  dedupe.read.dedupe = true;
  const rcm::Recording deduped = rcm::load_bag_recording(repeat, dedupe);
  EXPECT_EQ(deduped.num_samples(), 9u);
  EXPECT_EQ(deduped.repeated_rows, 1u);
  // Wrong lengths.
  expect_contains(read_error(write_small_bag(dir_ / "len.bag", csv, 10,
                                             [&](int k, sensor_msgs::JointState& m) { if (k == 3) m.velocity.pop_back(); })),
                  {"len.bag", "message 3", "velocity: 2 entries, expected 3"});
  // A joint missing by name.
  expect_contains(read_error(write_small_bag(dir_ / "missing.bag", csv, 10,
                                             [&](int k, sensor_msgs::JointState& m) {
                                               if (k == 4) m.name[1] = "outer_roll";
                                             })),
                  {"message 4", "missing joint 'outer_pitch'"});
  // Effort not published at all.
  expect_contains(read_error(write_small_bag(dir_ / "noeffort.bag", csv, 10,
                                             [&](int, sensor_msgs::JointState& m) { m.effort.clear(); })),
                  {"message 0", "effort: missing"});
  // Stamps set on some messages only.
  expect_contains(read_error(write_small_bag(dir_ / "mixed.bag", csv, 10,
                                             [&](int k, sensor_msgs::JointState& m) { if (k == 2) m.header.stamp = ros::Time(); })),
                  {"message 2", "header.stamp", "zero"});
  // Too few joints.
  expect_contains(read_error(write_small_bag(dir_ / "two.bag", csv, 10,
                                             [&](int, sensor_msgs::JointState& m) {
                                               m.name.pop_back();
                                               m.position.pop_back();
                                               m.velocity.pop_back();
                                               m.effort.pop_back();
                                             })),
                  {"too few joints (2)"});
  // Not a bag at all.
  std::ofstream(dir_ / "text.bag") << "time,position_1\n0,1\n";
  expect_contains(read_error(dir_ / "text.bag"), {"text.bag", "not a readable rosbag"});
  expect_contains(read_error(dir_ / "absent.bag"), {"absent.bag", "no such file"});
}

TEST_F(BagTest, CliReadsBags) {
  const rcm::Recording csv = rcm::load_recording(rcm::test::get_trial_csv());
  const fs::path bag = dir_ / "trial.bag";
  rcm::test::write_bag(bag, csv, "/PSM2/measured_js", "/PSM2/force");

  // inspect, with --topic and --force-topic.
  const auto inspect = run_cli("inspect " + bag.string() + " --topic /PSM2/measured_js --force-topic /PSM2/force --json");
  ASSERT_EQ(inspect.status, 0) << inspect.err;
  const auto j = nlohmann::json::parse(inspect.out);
  EXPECT_EQ(j["layout"], "rosbag");
  EXPECT_EQ(j["samples"].get<std::size_t>(), csv.num_samples());
  EXPECT_EQ(j["joints"], 3);
  EXPECT_TRUE(j["has_force"].get<bool>());

  // The default topic is not in this bag: exit 2 and a located message.
  const auto wrong = run_cli("inspect " + bag.string());
  EXPECT_EQ(wrong.status, 2);
  expect_contains(wrong.err, {bag.string(), "/PSM1/measured_js", "no messages", "/PSM2/measured_js"});

  // convert writes the CSV layout; reading it back gives the same samples.
  const fs::path out = dir_ / "converted.csv";
  const auto conv = run_cli("convert " + bag.string() + " " + out.string() +
                            " --topic /PSM2/measured_js --force-topic /PSM2/force --json");
  ASSERT_EQ(conv.status, 0) << conv.err;
  const auto cj = nlohmann::json::parse(conv.out);
  EXPECT_EQ(cj["time_source"], "header_stamp");
  EXPECT_EQ(cj["time_origin_ns"].get<std::int64_t>(), rcm::test::to_stamp_ns(csv.time(0)));
  const rcm::Recording back = rcm::load_recording(out);
  expect_same_samples(back, csv);
  EXPECT_EQ(*back.force, *csv.force);

  // A bad bag through the CLI.
  const fs::path nan_bag = write_small_bag(dir_ / "nan.bag", csv, 10, [&](int k, sensor_msgs::JointState& m) {
    if (k == 3) m.position[0] = std::numeric_limits<double>::quiet_NaN();
  });
  const auto bad = run_cli("convert " + nan_bag.string() + " " + (dir_ / "x.csv").string());
  EXPECT_EQ(bad.status, 2);
  expect_contains(bad.err, {"nan.bag", "/PSM1/measured_js message 3", "position[0] ('outer_yaw')"});
  EXPECT_FALSE(fs::exists(dir_ / "x.csv"));
}

TEST_F(BagTest, SessionsMayNameBags) {
  // The fixture's session with its calibration recorded as a bag.
  rcm::Session session = rcm::load_session(rcm::test::get_session_manifest());
  ASSERT_TRUE(session.calibration);
  const rcm::Recording calibration = rcm::load_recording(session.calibration->recording);
  const fs::path bag = dir_ / "calibration.bag";
  rcm::test::write_bag(bag, calibration, "/PSM1/measured_js");
  session.calibration->recording = bag;
  session.trials.resize(1);
  const fs::path manifest = dir_ / "session.json";
  rcm::save_session(manifest, session);
  const auto inspect = run_cli("inspect " + manifest.string() + " --json");
  ASSERT_EQ(inspect.status, 0) << inspect.err;
  const auto j = nlohmann::json::parse(inspect.out);
  EXPECT_EQ(j["calibration"]["layout"], "rosbag");
  EXPECT_EQ(j["calibration"]["samples"].get<std::size_t>(), calibration.num_samples());
  EXPECT_EQ(j["trials"][0]["recording"]["layout"], "rcm");
}

TEST_F(BagTest, MonitorOnABagAgreesWithTheCsv) {
  const rcm::Recording csv = rcm::load_recording(rcm::test::get_trial_csv());
  const fs::path bag = dir_ / "trial.bag";
  rcm::test::write_bag(bag, csv, "/PSM1/measured_js");
  const std::string common = "monitor --session " + rcm::test::get_session_manifest().string() + " --model-file " +
                             rcm::test::get_model_file().string() + " --json ";
  const auto from_bag = run_cli(common + bag.string());
  const auto from_csv = run_cli(common + rcm::test::get_trial_csv().string());
  ASSERT_EQ(from_bag.status, 0) << from_bag.err;
  ASSERT_EQ(from_csv.status, 0) << from_csv.err;
  const auto b = nlohmann::json::parse(from_bag.out)["final"], c = nlohmann::json::parse(from_csv.out)["final"];
  for (int i = 0; i < 3; ++i) {
    // The bag's time is the CSV's rounded to whole nanoseconds (200 Hz: exact).
    EXPECT_NEAR(b["misalignment_m"][i].get<double>(), c["misalignment_m"][i].get<double>(), 1e-9) << i;
    EXPECT_NEAR(b["sd_m"][i].get<double>(), c["sd_m"][i].get<double>(), 1e-9) << i;
  }
  EXPECT_EQ(nlohmann::json::parse(from_bag.out)["alarms"].size(), nlohmann::json::parse(from_csv.out)["alarms"].size());
}

}  // namespace
