// rosbag2 recordings without ROS 2: CDR decoding against hand-laid bytes, the
// SQLite layouts rosbag2 has written (before Humble, Humble, Jazzy), bag
// directories with metadata.yaml and split files, MCAP files written by the
// reference implementation, the time rules (zero stamp = invalid; --time
// receive), and a located error for every defect.
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

TEST(Cdr, DecodesHandLaidLittleEndianBytes) {
  // Alignment counts from the byte after the 4-byte encapsulation header.
  const std::vector<std::uint8_t> bytes = {
      0x00, 0x01, 0x00, 0x00,                          // CDR little-endian
      0x01, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00,  // stamp 1 s 2 ns        @0
      0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // frame_id "" + pad 3   @8
      0x01, 0x00, 0x00, 0x00,                          // 1 name                @16
      0x02, 0x00, 0x00, 0x00, 'a', 0x00, 0x00, 0x00,   // "a" + pad 2           @20
      0x01, 0x00, 0x00, 0x00,                          // 1 position            @28
      0, 0, 0, 0, 0, 0, 0xf8, 0x3f,                    // 1.5 (aligned to 8)    @32
      0x01, 0x00, 0x00, 0x00, 0, 0, 0, 0,              // 1 velocity + pad 4    @40
      0, 0, 0, 0, 0, 0, 0x04, 0xc0,                    // -2.5                  @48
      0x01, 0x00, 0x00, 0x00, 0, 0, 0, 0,              // 1 effort + pad 4      @56
      0, 0, 0, 0, 0, 0, 0x10, 0x40,                    // 4.0                   @64
  };
  rcm::cdr::JointState m;
  rcm::cdr::decode(bytes.data(), bytes.size(), m);
  EXPECT_EQ(m.header.sec, 1);
  EXPECT_EQ(m.header.nanosec, 2u);
  EXPECT_EQ(m.header.get_stamp_ns(), 1000000002);
  ASSERT_EQ(m.name.size(), 1u);
  EXPECT_EQ(m.name[0], "a");
  EXPECT_EQ(m.position, std::vector<double>{1.5});
  EXPECT_EQ(m.velocity, std::vector<double>{-2.5});
  EXPECT_EQ(m.effort, std::vector<double>{4.0});
  EXPECT_EQ(rcm::cdr::encode(m), bytes);
}

TEST(Cdr, BigEndianRoundTripAndEveryTruncationIsAnError) {
  const rcm::cdr::JointState m = joint_state(3, kT0);
  for (bool big : {false, true}) {
    const auto bytes = rcm::cdr::encode(m, big);
    EXPECT_EQ(bytes[1], big ? 0 : 1);
    rcm::cdr::JointState back;
    rcm::cdr::decode(bytes.data(), bytes.size(), back);
    EXPECT_EQ(back.name, m.name);
    EXPECT_EQ(back.position, m.position);
    EXPECT_EQ(back.effort, m.effort);
    EXPECT_EQ(back.header.get_stamp_ns(), kT0);
    // Cut anywhere before the last field ends: an error, never a read past the end.
    for (std::size_t n = 0; n + 4 < bytes.size(); ++n)
      EXPECT_THROW(rcm::cdr::decode(bytes.data(), n, back), rcm::cdr::DecodeError) << n;
  }
  std::vector<std::uint8_t> huge = rcm::cdr::encode(m);
  huge[20] = 0xff;  // the name count: 0xff... elements in a 200-byte message
  huge[21] = 0xff;
  huge[22] = 0xff;
  rcm::cdr::JointState back;
  try {
    rcm::cdr::decode(huge.data(), huge.size(), back);
    ADD_FAILURE() << "accepted a sequence longer than the message";
  } catch (const rcm::cdr::DecodeError& e) {
    EXPECT_EQ(e.field(), "name");
  }
  std::vector<std::uint8_t> xcdr2 = rcm::cdr::encode(m);
  xcdr2[1] = 0x07;
  EXPECT_THROW(rcm::cdr::decode(xcdr2.data(), xcdr2.size(), back), rcm::cdr::DecodeError);
}

TEST(Rosbag2, ReadsEverySqliteLayout) {
  TempDir dir;
  for (int schema : {0, 3, 4}) {
    for (bool qos : {false, true}) {
      if (schema > 0 && !qos) continue;
      const fs::path db = dir.path() / ("s" + std::to_string(schema) + (qos ? "q" : "") + ".db3");
      write_db3(db, schema, kTopics, make_messages(20));
      rcm::Rosbag2ReadInfo info;
      const rcm::Recording r = rcm::load_rosbag2_recording(db, {}, &info);
      ASSERT_EQ(r.num_samples(), 20u) << db;
      EXPECT_EQ(r.num_joints(), 4);
      EXPECT_EQ(r.layout, rcm::RecordingLayout::rosbag2);
      EXPECT_EQ(info.storage, "sqlite3");
      EXPECT_EQ(info.sqlite_schema, schema);
      EXPECT_EQ(info.joint_names, kNames);
      EXPECT_EQ(info.time_origin_ns, kT0);
      EXPECT_DOUBLE_EQ(r.time[19], 0.19);
      EXPECT_DOUBLE_EQ(r.position(7, 2), 0.3 + 0.007);
      EXPECT_DOUBLE_EQ(r.effort(7, 3), -0.2 + 0.0007);
      EXPECT_FALSE(r.has_force());
    }
  }
}

TEST(Rosbag2, DirectoryWithSplitFilesAndForce) {
  TempDir dir;
  const fs::path bag = dir.path() / "run";
  fs::create_directories(bag);
  write_db3(bag / "run_0.db3", 3, kTopics, make_messages(30, 0));
  write_db3(bag / "run_1.db3", 3, kTopics, make_messages(30, 30));
  for (int version : {4, 5, 9}) {
    write_text(bag / "metadata.yaml", metadata_yaml(version, "sqlite3", {"run_0.db3", "run_1.db3"}));
    rcm::TopicReadOptions o;
    o.force_topic = "/PSM1/body/measured_cf";
    rcm::Rosbag2ReadInfo info;
    const rcm::Recording r = rcm::load_rosbag2_recording(bag, o, &info);
    ASSERT_EQ(r.num_samples(), 60u);
    EXPECT_EQ(info.metadata_version, version);
    EXPECT_EQ(info.files.size(), 2u);
    EXPECT_EQ(info.force_messages, 30u);
    EXPECT_EQ(info.force_frame_id, "PSM1");
    ASSERT_TRUE(r.has_force());
    // Odd samples fall between two wrenches: the mean of their x.
    EXPECT_NEAR((*r.force)(31, 0), 1.0 + 0.01 * 31, 1e-12);
    EXPECT_DOUBLE_EQ((*r.force)(30, 1), -2.0);
  }
  // Early rosbag2 named the files relative to the bag's parent directory.
  write_text(bag / "metadata.yaml", metadata_yaml(4, "sqlite3", {"run/run_0.db3", "run/run_1.db3"}));
  EXPECT_EQ(rcm::load_rosbag2_recording(bag).num_samples(), 60u);
  // Through load_recording, as every command and session reads it.
  EXPECT_EQ(rcm::load_recording(bag).num_samples(), 60u);
  EXPECT_EQ(rcm::load_recording(bag / "run_1.db3").num_samples(), 30u);

  // A recorder that did not finish: no metadata.yaml, files in split order.
  fs::remove(bag / "metadata.yaml");
  rcm::Rosbag2ReadInfo info;
  EXPECT_EQ(rcm::load_rosbag2_recording(bag, {}, &info).num_samples(), 60u);
  ASSERT_EQ(info.warnings.size(), 1u);
  EXPECT_NE(info.warnings[0].find("no metadata.yaml"), std::string::npos);

  write_text(bag / "metadata.yaml", metadata_yaml(5, "sqlite3", {"run_0.db3", "run_7.db3"}));
  expect_error([&] { rcm::load_rosbag2_recording(bag); },
               {"metadata.yaml", "relative_file_paths[1]", "'run_7.db3': no such file"});
  write_text(bag / "metadata.yaml", "rosbag2_bagfile_information:\n  version: [\n");
  expect_error([&] { rcm::load_rosbag2_recording(bag); }, {"metadata.yaml:", "not valid YAML"});
  std::string compressed = metadata_yaml(5, "sqlite3", {"run_0.db3"});
  compressed.replace(compressed.find("compression_mode: \"\""), 20, "compression_mode: FILE");
  write_text(bag / "metadata.yaml", compressed);
  expect_error([&] { rcm::load_rosbag2_recording(bag); }, {"compression_mode", "'FILE'", "not read"});
}

TEST(Rosbag2, ZeroStampsAreInvalidDataSkippedAndCounted) {
  TempDir dir;
  std::vector<Message> msgs = make_messages(10);
  // Messages 3 and 4 of the joint topic carry a zero stamp.
  int k = 0;
  for (Message& m : msgs) {
    if (m.topic_id != 1) continue;
    if (k == 3 || k == 4) {
      rcm::cdr::JointState js;
      rcm::cdr::decode(m.data.data(), m.data.size(), js);
      js.header.sec = 0;
      js.header.nanosec = 0;
      m.data = rcm::cdr::encode(js);
    }
    ++k;
  }
  const fs::path db = dir.path() / "zero.db3";
  write_db3(db, 4, kTopics, msgs);
  rcm::Rosbag2ReadInfo info;
  const rcm::Recording r = rcm::load_rosbag2_recording(db, {}, &info);
  EXPECT_EQ(r.num_samples(), 8u);
  EXPECT_EQ(info.messages, 10u);
  EXPECT_EQ(info.zero_stamp_messages, 2u);
  EXPECT_DOUBLE_EQ(r.time[3], 0.05);  // message 5

  // --time receive keeps them all, on the recorder's clock.
  rcm::TopicReadOptions o;
  o.time = rcm::MessageTime::receive;
  const rcm::Recording rr = rcm::load_rosbag2_recording(db, o, &info);
  EXPECT_EQ(rr.num_samples(), 10u);
  EXPECT_EQ(info.time_origin_ns, kT0 + 1000000);

  // No valid message at all: an error that says what to do.
  std::vector<Message> zeros;
  for (int i = 0; i < 3; ++i) zeros.push_back({1, kT0 + i * kDt, rcm::cdr::encode(joint_state(i, 0))});
  const fs::path z = dir.path() / "zeros.db3";
  write_db3(z, 3, kTopics, zeros);
  expect_error([&] { rcm::load_rosbag2_recording(z); }, {"zeros.db3", "/PSM1/measured_js", "3 messages, none valid",
                                                        "--time receive"});
}

TEST(Rosbag2, LocatedErrors) {
  TempDir dir;
  const fs::path db = dir.path() / "bad.db3";
  // A NaN effort in message 6.
  std::vector<Message> msgs = make_messages(10);
  {
    rcm::cdr::JointState js = joint_state(6, kT0 + 6 * kDt);
    js.effort[2] = std::nan("");
    for (Message& m : msgs)
      if (m.topic_id == 1 && m.receive_ns == kT0 + 6 * kDt + 1000000) m.data = rcm::cdr::encode(js);
  }
  write_db3(db, 3, kTopics, msgs);
  expect_error([&] { rcm::load_rosbag2_recording(db); },
               {"bad.db3", "/PSM1/measured_js message 6 (t = 0.06 s)", "effort[2]", "'outer_insertion'", "finite"});

  // A message cut short.
  msgs = make_messages(10);
  for (Message& m : msgs)
    if (m.topic_id == 1 && m.receive_ns == kT0 + 4 * kDt + 1000000) m.data.resize(60);
  fs::remove(db);
  write_db3(db, 3, kTopics, msgs);
  expect_error([&] { rcm::load_rosbag2_recording(db); },
               {"bad.db3", "/PSM1/measured_js message 4", "cannot be decoded as sensor_msgs/msg/JointState", "CDR byte"});

  // Time going back.
  msgs = make_messages(10);
  for (Message& m : msgs)
    if (m.topic_id == 1 && m.receive_ns == kT0 + 5 * kDt + 1000000) m.data = rcm::cdr::encode(joint_state(5, kT0));
  fs::remove(db);
  write_db3(db, 3, kTopics, msgs);
  expect_error([&] { rcm::load_rosbag2_recording(db); },
               {"message 5", "header.stamp", "time must increase strictly"});

  // The topic is absent, or of another type, or another serialization.
  fs::remove(db);
  write_db3(db, 3, kTopics, make_messages(5));
  rcm::TopicReadOptions o;
  o.topic = "/PSM2/measured_js";
  expect_error([&] { rcm::load_rosbag2_recording(db, o); },
               {"/PSM2/measured_js", "no such JointState topic", "/PSM1/measured_js (sensor_msgs/msg/JointState)"});
  o.topic = "/PSM1/body/measured_cf";
  expect_error([&] { rcm::load_rosbag2_recording(db, o); },
               {"has type geometry_msgs/msg/WrenchStamped, expected sensor_msgs/msg/JointState"});
  const fs::path json = dir.path() / "json.db3";
  write_db3(json, 3, {{"/PSM1/measured_js", "sensor_msgs/msg/JointState", "json"}}, {});
  expect_error([&] { rcm::load_rosbag2_recording(json); }, {"serialization format 'json'", "'cdr'"});

  // Not a database at all, and a database that is not a bag.
  const fs::path junk = dir.path() / "junk.db3";
  write_text(junk, std::string(5000, 'x'));
  expect_error([&] { rcm::load_rosbag2_recording(junk); }, {"junk.db3"});
  const fs::path other = dir.path() / "other.db3";
  {
    sqlite3* h = nullptr;
    sqlite3_open(other.c_str(), &h);
    exec(h, "CREATE TABLE t(x);");
    sqlite3_close(h);
  }
  expect_error([&] { rcm::load_rosbag2_recording(other); }, {"other.db3", "no 'topics' table"});
  expect_error([&] { rcm::load_rosbag2_recording(dir.path() / "absent.db3"); }, {"absent.db3", "no such file"});
  const fs::path empty_dir = dir.path() / "empty";
  fs::create_directories(empty_dir);
  expect_error([&] { rcm::load_recording(empty_dir); }, {"not a rosbag2 recording"});
}

TEST(Rosbag2, TruncatedSqliteFilesNeverCrash) {
  TempDir dir;
  const fs::path db = dir.path() / "whole.db3";
  write_db3(db, 3, kTopics, make_messages(200));
  std::ifstream in(db, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const fs::path cut = dir.path() / "cut.db3";
  for (std::size_t n = 0; n < bytes.size(); n += 997) {
    write_text(cut, bytes.substr(0, n));
    try {
      const rcm::Recording r = rcm::load_rosbag2_recording(cut);
      EXPECT_LE(r.num_samples(), 200u);
    } catch (const rcm::InputError& e) {
      EXPECT_NE(std::string(e.what()).find("cut.db3"), std::string::npos) << e.what();
    }
  }
}

// Files written by the reference MCAP implementation (tests/data/rosbag2/README.md).
TEST(Rosbag2, ReadsMcapFromTheReferenceWriter) {
  const fs::path data = fs::path(RCM_SOURCE_DIR) / "tests" / "data" / "rosbag2";
  int files = 0;
  for (const auto& e : fs::directory_iterator(data)) {
    if (e.path().extension() != ".mcap") continue;
    ++files;
    rcm::TopicReadOptions o;
    o.force_topic = "/PSM1/body/measured_cf";
    rcm::Rosbag2ReadInfo info;
    const rcm::Recording r = rcm::load_rosbag2_recording(e.path(), o, &info);
    EXPECT_EQ(info.storage, "mcap");
    ASSERT_EQ(r.num_samples(), 50u) << e.path();
    EXPECT_EQ(r.num_joints(), 7);
    EXPECT_EQ(info.joint_names.front(), "outer_yaw");
    EXPECT_EQ(info.joint_names.back(), "jaw");
    for (Eigen::Index k = 0; k < 50; ++k) {
      EXPECT_NEAR(r.time[k], 0.01 * static_cast<double>(k), 1e-12);
      EXPECT_DOUBLE_EQ(r.position(k, 2), 0.3 + 0.001 * static_cast<double>(k));
      EXPECT_DOUBLE_EQ(r.velocity(k, 6), 0.07);
      EXPECT_DOUBLE_EQ(r.effort(k, 0), -0.05 + 0.0001 * static_cast<double>(k));
    }
    ASSERT_TRUE(r.has_force());
    EXPECT_EQ(info.force_messages, 20u);
    EXPECT_DOUBLE_EQ((*r.force)(0, 0), 1.0);
    EXPECT_DOUBLE_EQ((*r.force)(10, 1), -2.0);
    EXPECT_TRUE(info.warnings.empty());
  }
  EXPECT_GE(files, 5);
}
