// rosbag2 recordings through the CLI: rcm inspect and rcm convert on bags, and
// sessions that name their bags' topics, overridden by the command line.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sys/wait.h>

#include <nlohmann/json.hpp>

#include "io/rosbag2/cdr.hpp"
#include "temp_dir.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/rosbag2.hpp"
#include "rcm/io/session.hpp"
#include "support/rosbag2_writer.hpp"
#include "test_io_rosbag2_fixture.hpp"

using namespace rcm::test::rosbag2;

namespace {
struct CliRun {
  int status;
  std::string out;
};
CliRun run_cli(const std::string& args) {
  const std::string cmd = std::string(RCM_CLI_PATH) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}
}  // namespace

TEST(Rosbag2Cli, InspectConvertAndSessions) {
  TempDir dir;
  const fs::path bag = dir.path() / "run";
  fs::create_directories(bag);
  std::vector<Message> msgs = make_messages(40);
  // One invalid (zero-stamp) message, as cisst-ros 4.0 publishes before its data is valid.
  msgs.insert(msgs.begin(), Message{1, kT0 - kDt, rcm::cdr::encode(joint_state(0, 0))});
  write_db3(bag / "run_0.db3", 4, kTopics, msgs);
  write_text(bag / "metadata.yaml", metadata_yaml(9, "sqlite3", {"run_0.db3"}));

  const CliRun inspect = run_cli("inspect --json " + bag.string());
  ASSERT_EQ(inspect.status, 0) << inspect.out;
  const auto j = nlohmann::json::parse(inspect.out.substr(inspect.out.find('{')));
  EXPECT_EQ(j["layout"], "rosbag2");
  EXPECT_EQ(j["samples"], 40);
  EXPECT_EQ(j["rosbag2"]["storage"], "sqlite3");
  EXPECT_EQ(j["rosbag2"]["metadata_version"], 9);
  EXPECT_EQ(j["rosbag2"]["sqlite_schema"], 4);
  EXPECT_EQ(j["rosbag2"]["messages"], 41);
  EXPECT_EQ(j["rosbag2"]["zero_stamp_messages"], 1);
  // Every topic with its type, count and rate, as the recorder received them.
  ASSERT_EQ(j["rosbag2"]["topics"].size(), 2u);
  EXPECT_EQ(j["rosbag2"]["topics"][0]["name"], "/PSM1/body/measured_cf");
  EXPECT_EQ(j["rosbag2"]["topics"][0]["messages"], 20);
  EXPECT_NEAR(j["rosbag2"]["topics"][0]["rate_hz"].get<double>(), 50.0, 1e-9);
  EXPECT_EQ(j["rosbag2"]["topics"][1]["type"], "sensor_msgs/msg/JointState");
  EXPECT_EQ(j["rosbag2"]["topics"][1]["messages"], 41);
  const CliRun text = run_cli("inspect " + bag.string());
  EXPECT_NE(text.out.find("1 skipped (zero header.stamp: invalid data)"), std::string::npos) << text.out;

  const CliRun receive = run_cli("inspect --json --time receive " + bag.string());
  ASSERT_EQ(receive.status, 0) << receive.out;
  EXPECT_EQ(nlohmann::json::parse(receive.out)["samples"], 41);

  const fs::path csv = dir.path() / "run.csv";
  const CliRun convert =
      run_cli("convert " + bag.string() + " " + csv.string() + " --force-topic /PSM1/body/measured_cf --json");
  ASSERT_EQ(convert.status, 0) << convert.out;
  const auto c = nlohmann::json::parse(convert.out.substr(convert.out.find('{')));
  EXPECT_EQ(c["zero_stamp_messages"], 1);
  EXPECT_EQ(c["force_messages"], 20);
  const rcm::Recording from_csv = rcm::load_recording(csv);
  rcm::TopicReadOptions o;
  o.force_topic = "/PSM1/body/measured_cf";
  const rcm::Recording from_bag = rcm::load_rosbag2_recording(bag, o);
  EXPECT_EQ(from_csv.position, from_bag.position);
  EXPECT_EQ(from_csv.effort, from_bag.effort);
  EXPECT_EQ(*from_csv.force, *from_bag.force);

  // A session names the bag directory like any recording.
  write_text(dir.path() / "session.json",
             R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "q0": [0.0, 0.0, 0.12], "free_space": ["run"]})");
  const CliRun session = run_cli("inspect " + (dir.path() / "session.json").string());
  EXPECT_EQ(session.status, 0) << session.out;
  EXPECT_NE(session.out.find("rosbag2 (sqlite3"), std::string::npos) << session.out;

  // Bad input: exit status 2 and the file named.
  write_text(dir.path() / "bad.mcap", "\x89MCAP0\r\nnot really");
  const CliRun bad = run_cli("inspect " + (dir.path() / "bad.mcap").string());
  EXPECT_EQ(bad.status, 2) << bad.out;
  EXPECT_NE(bad.out.find("bad.mcap"), std::string::npos) << bad.out;
  const CliRun absent = run_cli("inspect --topic /PSM2/measured_js " + bag.string());
  EXPECT_EQ(absent.status, 2);
  EXPECT_NE(absent.out.find("no such JointState topic"), std::string::npos) << absent.out;
  // What is there comes first: layout and the topic table.
  EXPECT_NE(absent.out.find("rosbag2 recording: SQLite schema 4 (1 file(s), metadata.yaml version 9, ROS jazzy)"),
            std::string::npos)
      << absent.out;
  EXPECT_NE(absent.out.find("/PSM1/body/measured_cf  geometry_msgs/msg/WrenchStamped"), std::string::npos) << absent.out;
}

// A session names its bags' topics; the command line overrides them.
TEST(Rosbag2Cli, SessionTopicsAndFlagsOverride) {
  TempDir dir;
  const std::vector<Topic> psm2 = {{"/PSM2/measured_js", "sensor_msgs/msg/JointState"},
                                   {"/PSM2/body/measured_cf", "geometry_msgs/msg/WrenchStamped"}};
  write_db3(dir.path() / "free.db3", 4, psm2, make_messages(40));
  const fs::path manifest = dir.path() / "session.json";
  const std::string base =
      R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "q0": [0.0, 0.0, 0.12], "free_space": ["free.db3"])";
  write_text(manifest, base + R"(, "topics": {"joints": "/PSM2/measured_js", "force": "/PSM2/body/measured_cf"}})");
  const rcm::Session session = rcm::load_session(manifest);
  EXPECT_EQ(session.joint_topic, "/PSM2/measured_js");
  EXPECT_EQ(session.force_topic, "/PSM2/body/measured_cf");
  const rcm::Recording r = rcm::load_recording(session.free_space[0], rcm::get_read_options(session, {}));
  EXPECT_EQ(r.num_samples(), 40u);
  EXPECT_TRUE(r.has_force());

  const CliRun ok = run_cli("inspect --json " + manifest.string());
  ASSERT_EQ(ok.status, 0) << ok.out;
  const auto j = nlohmann::json::parse(ok.out.substr(ok.out.find('{')));
  EXPECT_EQ(j["free_space"][0]["rosbag2"]["topic"], "/PSM2/measured_js");
  EXPECT_EQ(j["free_space"][0]["has_force"], true);
  const CliRun flag = run_cli("inspect --topic /PSM1/measured_js " + manifest.string());
  EXPECT_EQ(flag.status, 2);
  EXPECT_NE(flag.out.find("/PSM1/measured_js: no such JointState topic"), std::string::npos) << flag.out;

  // Without "topics" the default topic is read, and is absent here.
  write_text(manifest, base + "}");
  EXPECT_EQ(run_cli("inspect " + manifest.string()).status, 2);
  write_text(manifest, base + R"(, "topics": {"joint": "/PSM2/measured_js"}})");
  expect_error([&] { rcm::load_session(manifest); }, {"session.json", "topics.joint", "unknown"});
  write_text(manifest, base + R"(, "topics": {"joints": ""}})");
  expect_error([&] { rcm::load_session(manifest); }, {"topics.joints", "empty topic name"});
}

// A CSV recording to a bag and back: the same samples, the force on its own
// topic, the dVRK's joint names; an output it cannot write is refused whole.
TEST(Rosbag2Cli, ConvertWritesABagOfARecording) {
  TempDir dir;
  rcm::Recording rec;
  const int T = 50;
  rec.source = "sines";
  rec.time = Eigen::VectorXd::LinSpaced(T, 0.0, (T - 1) * 0.005);
  rec.position.resize(T, 3);
  rec.velocity.resize(T, 3);
  rec.effort.resize(T, 3);
  rec.force = Eigen::MatrixXd(T, 3);
  for (int k = 0; k < T; ++k)
    for (int j = 0; j < 3; ++j) {
      rec.position(k, j) = 0.1 * std::sin(0.3 * k + j);
      rec.velocity(k, j) = 0.03 * std::cos(0.3 * k + j);
      rec.effort(k, j) = 0.5 * std::sin(0.2 * k - j);
      (*rec.force)(k, j) = 2.0 * std::cos(0.1 * k + j);
    }
  const fs::path csv = dir.path() / "rec.csv";
  rcm::save_recording(csv, rec);
  for (const char* ext : {".mcap", ".db3"}) {
    const fs::path bag = dir.path() / (std::string("rec") + ext);
    const CliRun convert = run_cli("convert " + csv.string() + " " + bag.string());
    ASSERT_EQ(convert.status, 0) << convert.out;
    EXPECT_NE(convert.out.find("50 JointState messages, and the force"), std::string::npos) << convert.out;
    rcm::TopicReadOptions read;
    read.force_topic = "/PSM1/body/measured_cf";
    rcm::Rosbag2ReadInfo info;
    const rcm::Recording back = rcm::load_rosbag2_recording(bag, read, &info);
    EXPECT_EQ(info.joint_names, (std::vector<std::string>{"outer_yaw", "outer_pitch", "outer_insertion"}));
    ASSERT_EQ(back.num_samples(), rec.num_samples());
    EXPECT_LT((back.time - rec.time).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(back.position, rec.position);
    EXPECT_EQ(back.effort, rec.effort);
    ASSERT_TRUE(back.has_force());
    EXPECT_LT((*back.force - *rec.force).cwiseAbs().maxCoeff(), 1e-12);
  }
  const CliRun text = run_cli("convert " + csv.string() + " " + (dir.path() / "rec.txt").string());
  EXPECT_EQ(text.status, 2) << text.out;
  EXPECT_NE(text.out.find("a CSV recording converts to a bag: name the output .mcap or .db3"), std::string::npos)
      << text.out;
  // A stamp that does not fit builtin_interfaces/Time: located, nothing written.
  const CliRun late = run_cli("convert " + csv.string() + " " + (dir.path() / "late.mcap").string() +
                              " --time-origin-ns 9000000000000000000");
  EXPECT_EQ(late.status, 2) << late.out;
  EXPECT_NE(late.out.find("does not fit builtin_interfaces/Time"), std::string::npos) << late.out;
  EXPECT_FALSE(fs::exists(dir.path() / "late.mcap"));
}
