// rosbag2 round trips: a recording written in every storage layout the test
// writer makes (SQLite schemas 0/3/4, bare or as a directory with metadata 5
// or 9, split; MCAP uncompressed/lz4/zstd, chunked or not, with or without
// summary and message indexes) reads back unchanged, through
// load_rosbag2_recording and through load_recording. Values must come back
// bit for bit (CDR carries the doubles), time to 1 ns (stamps are integer ns).
// The MCAP indexes, which rcm's reader does not use, are checked by walking
// them here.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "temp_dir.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/rosbag2.hpp"
#include "support/rosbag2_writer.hpp"

namespace fs = std::filesystem;
using rcm::test::Rosbag2WriteOptions;
using Storage = Rosbag2WriteOptions::Storage;

namespace {

// Temporary directories of this file are named rcm_test_rosbag2_roundtrip_<n>.
struct TempDir : rcm::test::TempDir {
  TempDir() : rcm::test::TempDir("rcm_test_rosbag2_roundtrip_") {}
};

constexpr const char* kForceTopic = "/PSM1/body/measured_cf";

// 2 s at 1 kHz, 7 joints, force: sines of different frequency and phase per
// column, so that a column or sample out of place shows.
rcm::Recording make_recording(Eigen::Index samples = 2000, int joints = 7) {
  rcm::Recording r;
  r.source = "sines";
  r.time.resize(samples);
  r.position.resize(samples, joints);
  r.velocity.resize(samples, joints);
  r.effort.resize(samples, joints);
  r.force = Eigen::MatrixXd(samples, 3);
  for (Eigen::Index k = 0; k < samples; ++k) {
    const double t = 0.001 * static_cast<double>(k);
    r.time[k] = t;
    for (int j = 0; j < joints; ++j) {
      const double w = 2.0 * M_PI * (0.3 + 0.17 * j), phase = 0.4 * j;
      r.position(k, j) = 0.2 * (j + 1) * std::sin(w * t + phase);
      r.velocity(k, j) = 0.2 * (j + 1) * w * std::cos(w * t + phase);
      r.effort(k, j) = -0.05 * (j + 1) + 0.3 * std::sin(1.7 * w * t + phase);
    }
    for (int i = 0; i < 3; ++i) (*r.force)(k, i) = 2.0 * std::sin(2.0 * M_PI * (0.5 + i) * t) - 0.5 * i;
  }
  return r;
}

struct Variant {
  std::string name;  // also the bag's file or directory name
  Rosbag2WriteOptions options;
  std::size_t files = 1;
  int metadata_version = 0;  // 0: a bare file
};

std::vector<Variant> every_variant() {
  std::vector<Variant> out;
  for (int schema : {0, 3, 4}) {
    Rosbag2WriteOptions o;
    o.storage = Storage::sqlite3;
    o.sqlite_schema = schema;
    const std::string s = "s" + std::to_string(schema);
    out.push_back({s + ".db3", o});
    for (int version : {5, 9}) {
      o.metadata_version = version;
      out.push_back({s + "_md" + std::to_string(version), o, 1, version});
    }
    o.split_every = 667;  // 2000 samples: 667 + 667 + 666
    out.push_back({s + "_split", o, 3, 9});
  }
  for (const std::string compression : {"", "lz4", "zstd"}) {
    for (bool summary : {true, false}) {
      for (bool indexes : {true, false}) {
        Rosbag2WriteOptions o;
        o.mcap_compression = compression;
        o.mcap_summary = summary;
        o.mcap_message_indexes = indexes;
        o.mcap_chunk_bytes = 64 * 1024;  // about 13 chunks
        const std::string name = "c" + (compression.empty() ? std::string("none") : compression) +
                                 (summary ? "_sum" : "_nosum") + (indexes ? "_idx" : "_noidx");
        out.push_back({name + ".mcap", o});
      }
    }
    Rosbag2WriteOptions o;  // one chunk of 1 MiB, as a directory split in 3
    o.mcap_compression = compression;
    o.split_every = 667;
    o.metadata_version = 9;
    out.push_back({"c" + (compression.empty() ? std::string("none") : compression) + "_split", o, 3, 9});
  }
  for (bool summary : {true, false}) {
    Rosbag2WriteOptions o;
    o.mcap_chunked = false;
    o.mcap_summary = summary;
    out.push_back({std::string("unchunked") + (summary ? "_sum" : "_nosum") + ".mcap", o});
    o.metadata_version = 5;
    out.push_back({std::string("unchunked") + (summary ? "_sum" : "_nosum") + "_md5", o, 1, 5});
  }
  return out;
}

void expect_same_joint_data(const rcm::Recording& back, const rcm::Recording& r) {
  ASSERT_EQ(back.num_samples(), r.num_samples());
  ASSERT_EQ(back.num_joints(), r.num_joints());
  double worst = 0.0;
  for (Eigen::Index k = 0; k < r.time.size(); ++k)
    worst = std::max(worst, std::abs(back.time[k] - (r.time[k] - r.time[0])));
  EXPECT_LE(worst, 1e-9);
  EXPECT_TRUE(back.position == r.position);
  EXPECT_TRUE(back.velocity == r.velocity);
  EXPECT_TRUE(back.effort == r.effort);
}

}  // namespace

TEST(Rosbag2RoundTrip, EveryLayoutReadsBackTheRecording) {
  TempDir dir;
  const rcm::Recording r = make_recording();
  const auto variants = every_variant();
  EXPECT_GE(variants.size(), 30u);
  for (const Variant& v : variants) {
    SCOPED_TRACE(v.name);
    const fs::path path = dir.path() / v.name;
    rcm::test::write_rosbag2(path, r, v.options);
    EXPECT_EQ(fs::is_directory(path), v.metadata_version != 0);

    rcm::TopicReadOptions o;
    o.force_topic = kForceTopic;
    rcm::Rosbag2ReadInfo info;
    const rcm::Recording back = rcm::load_rosbag2_recording(path, o, &info);
    expect_same_joint_data(back, r);
    ASSERT_TRUE(back.has_force());
    EXPECT_TRUE(*back.force == *r.force);
    EXPECT_EQ(back.layout, rcm::RecordingLayout::rosbag2);

    const bool sqlite = v.options.storage == Storage::sqlite3;
    EXPECT_EQ(info.storage, sqlite ? "sqlite3" : "mcap");
    EXPECT_EQ(info.files.size(), v.files);
    EXPECT_EQ(info.metadata_version, v.metadata_version);
    EXPECT_EQ(info.sqlite_schema, sqlite ? v.options.sqlite_schema : 0);
    EXPECT_EQ(info.ros_distro, !sqlite || v.options.sqlite_schema == 0 ? ""
                               : v.options.sqlite_schema == 3      ? "humble"
                                                                   : "jazzy");
    EXPECT_EQ(info.joint_names, rcm::test::default_joint_names(7));
    EXPECT_EQ(info.time_origin_ns, v.options.time_origin_ns);
    EXPECT_EQ(info.messages, 2000u);
    EXPECT_EQ(info.force_messages, 2000u);
    EXPECT_EQ(info.zero_stamp_messages + info.force_zero_stamp_messages, 0u);
    EXPECT_EQ(info.force_frame_id, "PSM1_base");
    EXPECT_TRUE(info.warnings.empty()) << info.warnings.front();

    // The recorder's clock: the stamps shifted by the receive delay.
    o.time = rcm::MessageTime::receive;
    const rcm::Recording received = rcm::load_rosbag2_recording(path, o, &info);
    EXPECT_EQ(info.time_origin_ns, v.options.time_origin_ns + v.options.receive_delay_ns);
    expect_same_joint_data(received, r);

    // As every command and session reads a file: default topic, no force.
    const rcm::Recording loaded = rcm::load_recording(path);
    expect_same_joint_data(loaded, r);
    EXPECT_FALSE(loaded.has_force());
  }
}

// A recording that went through the CSV layout (times on a 1 ns grid, not
// starting at zero, unevenly spaced) keeps its intervals to 1 ns.
TEST(Rosbag2RoundTrip, CsvTimesOnANanosecondGridSurvive) {
  TempDir dir;
  rcm::Recording r = make_recording(500, 4);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> jitter(-200000, 200000);  // ns
  std::int64_t t_ns = 1234567890123;                            // 1234.567890123 s
  for (Eigen::Index k = 0; k < r.time.size(); ++k) {
    r.time[k] = 1e-9 * static_cast<double>(t_ns);
    t_ns += 1000000 + jitter(rng);
  }
  const fs::path csv = dir.path() / "run.csv";
  rcm::save_recording(csv, r);
  const rcm::Recording from_csv = rcm::load_recording(csv);
  for (const Storage storage : {Storage::sqlite3, Storage::mcap}) {
    Rosbag2WriteOptions o;
    o.storage = storage;
    const fs::path bag = dir.path() / (storage == Storage::sqlite3 ? "run.db3" : "run.mcap");
    rcm::test::write_rosbag2(bag, from_csv, o);
    rcm::TopicReadOptions read;
    read.force_topic = kForceTopic;
    const rcm::Recording back = rcm::load_rosbag2_recording(bag, read);
    expect_same_joint_data(back, from_csv);
    EXPECT_TRUE(*back.force == *from_csv.force);
    for (Eigen::Index k = 1; k < r.time.size(); ++k)
      EXPECT_EQ(std::llround((back.time[k] - back.time[k - 1]) * 1e9),
                std::llround((from_csv.time[k] - from_csv.time[k - 1]) * 1e9))
          << k;
  }
}

TEST(Rosbag2RoundTrip, JointNamesBeyondTheSevenAndWithoutForce) {
  TempDir dir;
  rcm::Recording r = make_recording(50, 9);
  r.force.reset();
  const fs::path bag = dir.path() / "nine.mcap";
  rcm::test::write_rosbag2(bag, r);
  rcm::Rosbag2ReadInfo info;
  const rcm::Recording back = rcm::load_rosbag2_recording(bag, {}, &info);
  expect_same_joint_data(back, r);
  ASSERT_EQ(info.joint_names.size(), 9u);
  EXPECT_EQ(info.joint_names[6], "jaw");
  EXPECT_EQ(info.joint_names[7], "joint_8");
  EXPECT_EQ(info.joint_names[8], "joint_9");
  // No force in the recording: no force topic in the bag.
  rcm::TopicReadOptions o;
  o.force_topic = kForceTopic;
  EXPECT_THROW(rcm::load_rosbag2_recording(bag, o), rcm::InputError);

  Rosbag2WriteOptions named;
  named.storage = Storage::sqlite3;
  named.joint_names = {"a", "b", "c", "d", "e", "f", "g", "h", "i"};
  named.topic = "/PSM2/measured_js";
  rcm::test::write_rosbag2(dir.path() / "named.db3", r, named);
  rcm::TopicReadOptions psm2;
  psm2.topic = "/PSM2/measured_js";
  EXPECT_EQ(rcm::load_rosbag2_recording(dir.path() / "named.db3", psm2, &info).position, r.position);
  EXPECT_EQ(info.joint_names, named.joint_names);
}

TEST(Rosbag2RoundTrip, WriterRejectsWhatItCannotWrite) {
  TempDir dir;
  const rcm::Recording r = make_recording(20, 4);
  Rosbag2WriteOptions o;
  o.split_every = 5;
  EXPECT_THROW(rcm::test::write_rosbag2(dir.path() / "x.mcap", r, o), std::invalid_argument);
  o = {};
  EXPECT_THROW(rcm::test::write_rosbag2(dir.path() / "x.db3", r, o), std::invalid_argument);  // MCAP into .db3
  o.joint_names = {"a", "b"};
  EXPECT_THROW(rcm::test::write_rosbag2(dir.path() / "x.mcap", r, o), std::invalid_argument);
  o = {};
  o.mcap_compression = "brotli";
  EXPECT_THROW(rcm::test::write_rosbag2(dir.path() / "x.mcap", r, o), std::invalid_argument);
  // What the recording itself cannot carry is the user's input: located.
  rcm::Recording dense = r;
  dense.time[1] = dense.time[0] + 1e-10;  // two samples on the same nanosecond
  try {
    rcm::save_rosbag2_recording(dir.path() / "y.mcap", dense);
    ADD_FAILURE() << "two samples on one nanosecond were written";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("sample 1: time closer than 1 ns"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "y.mcap"));
  // A bag directory is written whole, never over files it did not write.
  std::filesystem::create_directories(dir.path() / "full");
  std::ofstream(dir.path() / "full" / "notes.txt") << "mine";
  EXPECT_THROW(rcm::save_rosbag2_recording(dir.path() / "full", r), rcm::InputError);
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "full" / "notes.txt"));
  for (const auto& e : std::filesystem::directory_iterator(dir.path()))
    EXPECT_NE(e.path().filename().string().front(), '.') << "a temporary was left: " << e.path();
}

namespace {

using Bytes = std::vector<std::uint8_t>;

std::uint64_t le(const Bytes& b, std::uint64_t at, int n) {
  if (at + n > b.size()) throw std::out_of_range("read past the end at " + std::to_string(at));
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | b[at + i];
  return v;
}

}  // namespace

// Footer -> SummaryOffset -> ChunkIndex -> Chunk and MessageIndex -> Message:
// every offset the writer puts in an uncompressed file points where it says.
TEST(Rosbag2RoundTrip, McapIndexesPointAtTheirRecords) {
  TempDir dir;
  const rcm::Recording r = make_recording();
  Rosbag2WriteOptions o;
  o.mcap_compression = "";
  o.mcap_chunk_bytes = 64 * 1024;
  const fs::path path = dir.path() / "indexed.mcap";
  rcm::test::write_rosbag2(path, r, o);
  std::ifstream in(path, std::ios::binary);
  const Bytes f((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());

  const std::uint64_t footer = f.size() - 8 - 29;
  ASSERT_EQ(f[footer], 0x02);
  const std::uint64_t summary_start = le(f, footer + 9, 8), offsets_start = le(f, footer + 17, 8);
  ASSERT_GT(summary_start, 0u);
  ASSERT_GT(offsets_start, summary_start);
  // DataEnd ends the data section, right before the summary.
  ASSERT_EQ(f[summary_start - 13], 0x0F);

  std::uint64_t chunk_group = 0, chunk_group_end = 0, statistics = 0;
  for (std::uint64_t p = offsets_start; p < footer; p += 9 + le(f, p + 1, 8)) {
    ASSERT_EQ(f[p], 0x0E);
    const std::uint8_t op = f[p + 9];
    const std::uint64_t start = le(f, p + 10, 8), length = le(f, p + 18, 8);
    ASSERT_EQ(f[start], op);
    if (op == 0x08) chunk_group = start, chunk_group_end = start + length;
    if (op == 0x0B) statistics = start;
  }
  ASSERT_NE(statistics, 0u);
  EXPECT_EQ(le(f, statistics + 9, 8), 4000u);  // message_count
  ASSERT_NE(chunk_group, 0u);

  std::size_t chunks = 0, indexed = 0;
  std::uint64_t previous_log_time = 0;
  for (std::uint64_t p = chunk_group; p < chunk_group_end; p += 9 + le(f, p + 1, 8)) {
    ASSERT_EQ(f[p], 0x08);
    ++chunks;
    std::uint64_t q = p + 9;
    const std::uint64_t start_time = le(f, q, 8), end_time = le(f, q + 8, 8);
    const std::uint64_t chunk = le(f, q + 16, 8), chunk_length = le(f, q + 24, 8);
    ASSERT_EQ(f[chunk], 0x06);
    EXPECT_EQ(9 + le(f, chunk + 1, 8), chunk_length);
    const std::uint64_t compression_len = le(f, chunk + 9 + 28, 4);
    ASSERT_EQ(compression_len, 0u);
    const std::uint64_t records = chunk + 9 + 32 + 8;  // uncompressed: the records as they are
    const std::uint64_t map_len = le(f, q + 32, 4);
    EXPECT_EQ(map_len, 2u * 10u);  // both channels in every chunk
    for (std::uint64_t m = q + 36; m < q + 36 + map_len; m += 10) {
      const std::uint64_t channel = le(f, m, 2), index = le(f, m + 2, 8);
      ASSERT_EQ(f[index], 0x07);
      EXPECT_EQ(le(f, index + 9, 2), channel);
      const std::uint64_t entry_bytes = le(f, index + 11, 4);
      for (std::uint64_t e = index + 15; e < index + 15 + entry_bytes; e += 16) {
        const std::uint64_t log_time = le(f, e, 8), offset = le(f, e + 8, 8);
        const std::uint64_t message = records + offset;
        ASSERT_EQ(f[message], 0x05);
        EXPECT_EQ(le(f, message + 9, 2), channel);
        EXPECT_EQ(le(f, message + 15, 8), log_time);
        EXPECT_GE(log_time, start_time);
        EXPECT_LE(log_time, end_time);
        if (channel == 1) {
          EXPECT_GT(log_time, previous_log_time);
          previous_log_time = log_time;
        }
        ++indexed;
      }
    }
  }
  EXPECT_GT(chunks, 5u);
  EXPECT_EQ(indexed, 4000u);
}
