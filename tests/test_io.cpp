// Recording CSV and session JSON readers: exact round trips, both CSV layouts,
// and a located error for every kind of defect, including hostile input.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "temp_dir.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"

namespace fs = std::filesystem;

namespace {

// Temporary directories of this file are named rcm_test_io_<n>.
struct TempDir : rcm::test::TempDir {
  TempDir() : rcm::test::TempDir("rcm_test_io_") {}
};

const char* kHeader = "time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,effort_3";

std::string row(double t, double v) {
  std::ostringstream s;
  s << t;
  for (int k = 0; k < 9; ++k) s << "," << v + 0.001 * k;
  return s.str();
}

std::string good_csv(int rows = 5) {
  std::string out = std::string(kHeader) + "\n";
  for (int i = 0; i < rows; ++i) out += row(0.005 * i, 0.1 * i) + "\n";
  return out;
}

// Expects an InputError whose message contains every needle.
void expect_error(const std::string& text, std::vector<std::string> needles,
                  rcm::RecordingReadOptions options = {}) {
  try {
    rcm::parse_recording(text, "rec.csv", options);
    ADD_FAILURE() << "accepted input; expected an error containing '" << needles.front() << "'";
  } catch (const rcm::InputError& e) {
    for (const auto& n : needles)
      EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << "message: " << e.what() << "\nmissing: " << n;
  }
}

TEST(Recording, ReadsContractLayout) {
  const rcm::Recording r = rcm::parse_recording(good_csv(), "rec.csv");
  EXPECT_EQ(r.num_samples(), 5u);
  EXPECT_EQ(r.num_joints(), 3);
  EXPECT_FALSE(r.has_force());
  EXPECT_DOUBLE_EQ(r.position(2, 1), 0.2 + 0.001);
  EXPECT_DOUBLE_EQ(r.effort(4, 2), 0.4 + 0.008);
  EXPECT_EQ(r.line.front(), 2u);
  EXPECT_EQ(r.layout, rcm::RecordingLayout::rcm_csv);
}

TEST(Recording, ExtraColumnsJointsAndForce) {
  const std::string text =
      "note,time,position_1,position_2,position_3,position_4,velocity_1,velocity_2,velocity_3,velocity_4,"
      "effort_1,effort_2,effort_3,effort_4,force_x,force_y,force_z\r\n"
      "\"a, quoted\",0,1,2,3,4,5,6,7,8,9,10,11,12,-1,-2,-3\r\n"
      "b,0.005,1,2,3,4,5,6,7,8,9,10,11,12.5,-1,-2,+3e0\r\n";
  const rcm::Recording r = rcm::parse_recording(text, "x.csv");
  EXPECT_EQ(r.num_joints(), 4);
  ASSERT_TRUE(r.has_force());
  EXPECT_DOUBLE_EQ((*r.force)(1, 2), 3.0);
  EXPECT_DOUBLE_EQ(r.effort(1, 3), 12.5);
}

TEST(Recording, ReadsRostopicEchoLayout) {
  const std::string text =
      "%time,field.header.seq,field.header.stamp,field.header.frame_id,field.name0,field.name1,field.name2,"
      "field.position0,field.position1,field.position2,field.velocity0,field.velocity1,field.velocity2,"
      "field.effort0,field.effort1,field.effort2\n"
      "1700000000000000000,1,1700000000000000000,,outer_yaw,outer_pitch,outer_insertion,0.1,0.2,0.12,0,0,0,0.5,0.6,1.2\n"
      "1700000000005000000,2,1700000000005000000,,outer_yaw,outer_pitch,outer_insertion,0.1,0.2,0.121,0,0,0.2,0.5,0.6,1.3\n";
  const rcm::Recording r = rcm::parse_recording(text, "measured_js.csv");
  EXPECT_EQ(r.layout, rcm::RecordingLayout::rostopic_csv);
  EXPECT_EQ(r.num_joints(), 3);
  EXPECT_NEAR(r.time[1] - r.time[0], 0.005, 1e-6);
  EXPECT_DOUBLE_EQ(r.position(1, 2), 0.121);
  EXPECT_DOUBLE_EQ(r.effort(1, 2), 1.3);
}

TEST(Recording, RoundTripIsExact) {
  TempDir dir;
  rcm::Recording r;
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  const int T = 300;
  r.time.resize(T);
  for (int t = 0; t < T; ++t) r.time[t] = 0.005 * t + 1e-7 * std::abs(n(rng));
  r.position = Eigen::MatrixXd::NullaryExpr(T, 3, [&] { return n(rng); });
  r.velocity = Eigen::MatrixXd::NullaryExpr(T, 3, [&] { return n(rng) * 1e-300; });
  r.effort = Eigen::MatrixXd::NullaryExpr(T, 3, [&] { return n(rng) * 1e300; });
  r.force = Eigen::MatrixXd::NullaryExpr(T, 3, [&] { return n(rng); });
  const fs::path p = dir.path() / "rt.csv";
  rcm::save_recording(p, r);
  const rcm::Recording back = rcm::load_recording(p);
  EXPECT_TRUE(back.time == r.time);
  EXPECT_TRUE(back.position == r.position);
  EXPECT_TRUE(back.velocity == r.velocity);
  EXPECT_TRUE(back.effort == r.effort);
  ASSERT_TRUE(back.force);
  EXPECT_TRUE(*back.force == *r.force);
  for (const auto& entry : fs::directory_iterator(dir.path()))  // no temporary left behind
    EXPECT_EQ(entry.path().filename(), "rt.csv");
}

TEST(Recording, RepeatedRowsAreCountedKeptOrDropped) {
  std::string text = std::string(kHeader) + "\n" + row(0, 0.1) + "\n" + row(0.005, 0.2) + "\n" + row(0.010, 0.2) +
                     "\n" + row(0.015, 0.3) + "\n";
  const rcm::Recording kept = rcm::parse_recording(text, "r.csv");
  EXPECT_EQ(kept.num_samples(), 4u);
  EXPECT_EQ(kept.repeated_rows, 1u);
  EXPECT_FALSE(kept.repeated_rows_removed);
  rcm::RecordingReadOptions o;
  o.dedupe = true;
  const rcm::Recording dropped = rcm::parse_recording(text, "r.csv", o);
  EXPECT_EQ(dropped.num_samples(), 3u);
  EXPECT_EQ(dropped.repeated_rows, 1u);
  EXPECT_TRUE(dropped.repeated_rows_removed);
  EXPECT_EQ(dropped.line, (std::vector<std::size_t>{2, 3, 5}));
  // A repeated row with a repeated time stamp: an error that suggests --dedupe ...
  const std::string same_time = std::string(kHeader) + "\n" + row(0, 0.1) + "\n" + row(0, 0.1) + "\n";
  expect_error(same_time, {"rec.csv:3", "column time", "must increase", "--dedupe"});
  // ... and that --dedupe resolves.
  EXPECT_EQ(rcm::parse_recording(same_time, "r.csv", o).num_samples(), 1u);
}

TEST(Recording, MissingTimeNeedsAnExplicitRate) {
  const std::string text =
      "position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,effort_3\n"
      "1,2,3,4,5,6,7,8,9\n1,2,3,4,5,6,7,8,10\n";
  expect_error(text, {"rec.csv:1", "no time column", "--rate"});
  rcm::RecordingReadOptions o;
  o.assumed_rate_hz = 200.0;
  const rcm::Recording r = rcm::parse_recording(text, "r.csv", o);
  EXPECT_TRUE(r.time_from_rate);
  EXPECT_DOUBLE_EQ(r.time[1], 0.005);
}

TEST(Recording, LocatedErrors) {
  const std::string h = std::string(kHeader) + "\n";
  expect_error("", {"rec.csv", "empty"});
  expect_error("\n\n", {"rec.csv", "empty"});
  expect_error(h, {"rec.csv:1", "header only"});
  expect_error(h + row(0, 1) + "\n" + "0.005,1,2,abc,4,5,6,7,8,9\n", {"rec.csv:3", "column position_3", "'abc'"});
  expect_error(h + "0,1,2,3,4,5,nan,7,8,9\n", {"rec.csv:2", "column velocity_3", "finite", "'nan'"});
  expect_error(h + "0,1,2,3,4,5,6,inf,8,9\n", {"rec.csv:2", "column effort_1", "finite"});
  expect_error(h + "0,1,2,3,4,5,6,7,1e999,9\n", {"rec.csv:2", "column effort_2", "out of range"});
  expect_error(h + "0,1,2,3,4,5,6,7,8,\n", {"rec.csv:2", "column effort_3", "empty cell"});
  expect_error(h + "0,1,2,3,4,5,6,7,8\n", {"rec.csv:2", "found 9", "truncated"});
  expect_error(h + "0,1,2,3,4,5,6,7,8,9,10\n", {"rec.csv:2", "expected 10", "found 11"});
  expect_error(h + row(0.01, 1) + "\n" + row(0.005, 1.1) + "\n", {"rec.csv:3", "column time", "must increase"});
  expect_error("time,position_1,position_2,velocity_1,velocity_2,effort_1,effort_2\n0,1,2,3,4,5,6\n",
               {"rec.csv:1", "column position_3", "too few joints"});
  expect_error("time,position_1,position_2,position_3,velocity_1,velocity_2,effort_1,effort_2,effort_3\n",
               {"rec.csv:1", "column velocity_3", "missing"});
  expect_error("time,position_1,position_2,position_3,position_5,velocity_1,velocity_2,velocity_3,effort_1,effort_2,"
               "effort_3\n",
               {"rec.csv:1", "column position_5", "position_4 is missing"});
  expect_error(std::string(kHeader) + ",force_x,force_y\n", {"rec.csv:1", "column force_z"});
  expect_error(std::string(kHeader) + ",time\n", {"rec.csv:1", "column time", "duplicate"});
  expect_error("\n" + good_csv(), {"rec.csv:1", "header row on line 1"});
}

TEST(Recording, HostileInputNeverCrashes) {
  // 10^5 columns: the unknown ones are ignored, the row width is still checked.
  std::string wide = kHeader;
  for (int i = 0; i < 100000; ++i) wide += ",x" + std::to_string(i);
  std::string wide_row = row(0, 1);
  for (int i = 0; i < 100000; ++i) wide_row += ",0";
  const rcm::Recording r = rcm::parse_recording(wide + "\n" + wide_row + "\n", "wide.csv");
  EXPECT_EQ(r.num_samples(), 1u);
  expect_error(wide + "\n" + row(0, 1) + "\n", {"rec.csv:2", "expected 100010"});

  // Binary bytes in a numeric cell and in the header.
  const std::string bad_row("0.005,1,2,\x01\xff\x00z,4,5,6,7,8,9\n", 27);
  const std::string binary = std::string(kHeader) + "\n" + row(0, 1) + "\n" + bad_row;
  expect_error(binary, {"rec.csv:3"});
  expect_error(std::string("\x89PNG\r\n\x1a\n\x00\x00\x00", 12), {"rec.csv"});
  // Random garbage of many shapes: an InputError every time, never a crash.
  std::mt19937 rng(11);
  for (int k = 0; k < 300; ++k) {
    std::string text = good_csv(4);
    const int edits = 1 + static_cast<int>(rng() % 5);
    for (int e = 0; e < edits; ++e) {
      const std::size_t pos = rng() % text.size();
      switch (rng() % 3) {
        case 0: text[pos] = static_cast<char>(rng() % 256); break;
        case 1: text.erase(pos, 1 + rng() % 8); break;
        default: text.insert(pos, std::string(1 + rng() % 3, static_cast<char>(rng() % 256)));
      }
      if (text.empty()) text = "x";
    }
    try {
      rcm::parse_recording(text, "fuzz.csv");
    } catch (const rcm::InputError& e) {
      EXPECT_EQ(std::string(e.what()).rfind("fuzz.csv", 0), 0u) << e.what();
    }
  }
  // A very long cell is quoted with a bound.
  const std::string long_cell = std::string(kHeader) + "\n0,1,2," + std::string(100000, '7') + "x,4,5,6,7,8,9\n";
  try {
    rcm::parse_recording(long_cell, "long.csv");
    FAIL();
  } catch (const rcm::InputError& e) {
    EXPECT_LT(std::string(e.what()).size(), 300u);
  }
}

TEST(Recording, MissingFileIsLocated) {
  try {
    rcm::load_recording("/nonexistent/free_space.csv");
    FAIL();
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/free_space.csv: file not found"), std::string::npos);
  }
}

TEST(Recording, SummaryReportsRateJitterAndRanges) {
  const rcm::Recording r = rcm::parse_recording(good_csv(11), "r.csv");
  const rcm::RecordingSummary s = rcm::summarize_recording(r);
  EXPECT_NEAR(s.rate_hz, 200.0, 1e-6);
  EXPECT_NEAR(s.duration_s, 0.05, 1e-12);
  EXPECT_LT(s.jitter_s, 1e-12);
  EXPECT_DOUBLE_EQ(s.position[0].max, 1.0);
}

// ---------------------------------------------------------------- sessions

struct SessionFixture : ::testing::Test {
  TempDir dir;
  fs::path manifest;
  void SetUp() override {
    for (const char* f : {"fs.csv", "base.csv", "cal.csv", "t1.csv", "t1s.csv"}) dir.write(f, good_csv());
    manifest = write_manifest(R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "q0": [0.0, 0.0, 0.12],
      "free_space": ["fs.csv"], "baseline": "base.csv",
      "calibration": {"recording": "cal.csv", "coaxial_offset_m": 0.030},
      "trials": [{"name": "D30_r10_15", "recording": "t1.csv", "static": "t1s.csv",
                  "truth": {"misalignment_m": [0.010, 0.015, 0.030]}}],
      "bench": "left phantom"})");
  }
  fs::path write_manifest(const std::string& text) { return dir.write("session.json", text); }
  void expect_error(const std::string& text, std::vector<std::string> needles) {
    write_manifest(text);
    try {
      rcm::load_session(manifest);
      ADD_FAILURE() << "accepted: " << text.substr(0, 80);
    } catch (const rcm::InputError& e) {
      for (const auto& n : needles)
        EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what() << "\nmissing: " << n;
    }
  }
};

TEST_F(SessionFixture, ReadsTheContractExample) {
  const rcm::Session s = rcm::load_session(manifest);
  EXPECT_EQ(s.robot, "dvrk-psm-classic");
  EXPECT_DOUBLE_EQ(s.q0[2], 0.12);
  ASSERT_EQ(s.free_space.size(), 1u);
  EXPECT_EQ(s.free_space[0], dir.path() / "fs.csv");
  ASSERT_TRUE(s.calibration);
  EXPECT_DOUBLE_EQ(s.calibration->coaxial_offset_m, 0.03);
  ASSERT_EQ(s.trials.size(), 1u);
  EXPECT_EQ(*s.trials[0].static_recording, dir.path() / "t1s.csv");
  EXPECT_DOUBLE_EQ((*s.trials[0].truth_misalignment_m)[1], 0.015);
  EXPECT_EQ(s.extra["bench"], "left phantom");
}

TEST_F(SessionFixture, SaveThenLoadRoundTrips) {
  const rcm::Session s = rcm::load_session(manifest);
  const fs::path copy = dir.path() / "copy.json";
  rcm::save_session(copy, s);
  const rcm::Session back = rcm::load_session(copy);
  EXPECT_EQ(back.trials[0].recording, s.trials[0].recording);
  EXPECT_EQ(back.extra, s.extra);
  const nlohmann::json j = rcm::load_json_file(copy);
  EXPECT_EQ(j["free_space"][0], "fs.csv");  // written relative to the manifest
}

TEST_F(SessionFixture, LocatedErrors) {
  const std::string base = R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "q0": [0.0, 0.0, 0.12], "free_space": ["fs.csv"])";
  expect_error(base + R"(, "trials": [{"name": "a", "recording": "missing.csv"}]})",
               {"session.json", "field trials[0].recording", "file not found"});
  expect_error(R"({"format": "rcm-session/2", "robot": "dvrk-psm-classic", "q0": [0,0,0.1], "free_space": ["fs.csv"]})",
               {"field format", "rcm-session/1"});
  expect_error(R"({"format": "rcm-session/1", "robot": "dvrk-ecm", "q0": [0,0,0.1], "free_space": ["fs.csv"]})",
               {"field robot", "unknown robot \"dvrk-ecm\""});
  expect_error(R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "q0": [0,2.0,0.1], "free_space": ["fs.csv"]})",
               {"field q0[1]", "outside its limits"});
  expect_error(R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "q0": [0,"x",0.1], "free_space": ["fs.csv"]})",
               {"field q0[1]", "expected a number"});
  expect_error(R"({"format": "rcm-session/1", "robot": "dvrk-psm-classic", "free_space": ["fs.csv"]})", {"field q0", "missing"});
  expect_error(base + R"(, "calibration": {"recording": "cal.csv", "coaxial_offset_m": 30}})",
               {"field calibration.coaxial_offset_m", "metres"});
  expect_error(base + R"(, "trials": [{"name": "a", "recording": "t1.csv"}, {"name": "a", "recording": "t1.csv"}]})",
               {"field trials[1].name", "duplicate"});
  expect_error(base + R"(, "trials": [{"name": "a", "recording": "t1.csv", "truth": {"misalignment_m": [1, 2]}}]})",
               {"field trials[0].truth.misalignment_m", "3 numbers"});
  expect_error(R"({"format": "rcm-session/1",
  "robot": "dvrk-psm-classic",, })", {"session.json:2: column 31", "invalid JSON"});
  expect_error("", {"session.json", "invalid JSON"});
  expect_error("[1, 2]", {"session.json", "JSON object"});
  expect_error(std::string("\x00\xff\xfe{", 4), {"session.json:1", "invalid JSON"});
  expect_error(std::string(100000, '['), {"session.json", "invalid JSON"});
  expect_error("{\"format\": " + std::string(100000, '9') + "}", {"session.json", "invalid JSON", "overflow"});
  try {
    write_manifest("{\"format\": " + std::string(100000, '9') + "}");
    rcm::load_session(manifest);
  } catch (const rcm::InputError& e) {
    EXPECT_LT(std::string(e.what()).size(), 400u);  // a bounded message, not the whole number
  }
  expect_error("{\"format\": 1e999}", {"session.json", "invalid JSON"});
}

TEST(JsonFile, AtomicWriteReplacesWholeFile) {
  TempDir dir;
  const fs::path p = dir.path() / "results.json";
  rcm::save_json_file(p, {{"a", 1}});
  rcm::save_json_file(p, {{"b", 2}});
  EXPECT_EQ(rcm::load_json_file(p), (nlohmann::json{{"b", 2}}));
  EXPECT_THROW(rcm::save_json_file(dir.path() / "no" / "such" / "dir.json", {}), rcm::InputError);
}

}  // namespace
