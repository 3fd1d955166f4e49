// Recordings read as a stream of chunks (io/recording_reader.hpp): every
// format gives, chunk by chunk, exactly the samples of a whole read, keeps
// the checks that span rows across a chunk boundary, and names the line of a
// defect in a later chunk; the summary, the exact median and the chunked
// writer agree with their whole-recording forms.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "io/rosbag2/cdr.hpp"
#include "io/stream_median.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/io/rosbag2.hpp"
#include "support/rosbag2_writer.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;

namespace {

struct TempDir : rcm::test::TempDir {
  TempDir() : rcm::test::TempDir("rcm_test_io_stream_") {}
};

// The same numbers, bit for bit (NaN never occurs in a read recording).
void expect_same(const rcm::Recording& a, const rcm::Recording& b, const std::string& what) {
  SCOPED_TRACE(what);
  EXPECT_EQ(a.source, b.source);
  EXPECT_EQ(a.layout, b.layout);
  ASSERT_EQ(a.num_samples(), b.num_samples());
  ASSERT_EQ(a.num_joints(), b.num_joints());
  EXPECT_TRUE(a.time == b.time);
  EXPECT_TRUE(a.position == b.position);
  EXPECT_TRUE(a.velocity == b.velocity);
  EXPECT_TRUE(a.effort == b.effort);
  ASSERT_EQ(a.has_force(), b.has_force());
  if (a.has_force()) EXPECT_TRUE(*a.force == *b.force);
  EXPECT_EQ(a.line, b.line);
  EXPECT_EQ(a.repeated_rows, b.repeated_rows);
  EXPECT_EQ(a.repeated_rows_removed, b.repeated_rows_removed);
  EXPECT_EQ(a.time_from_rate, b.time_from_rate);
}

// Reads every chunk and checks each is at most chunk_rows long; the chunks concatenated.
rcm::Recording read_in_chunks(rcm::RecordingReader& reader) {
  std::vector<rcm::Recording> chunks;
  rcm::Recording chunk;
  while (reader.read_chunk(chunk)) {
    EXPECT_GE(chunk.num_samples(), 1u);
    EXPECT_LE(chunk.num_samples(), reader.chunk_rows());
    EXPECT_EQ(chunk.source, reader.source());
    chunks.push_back(chunk);
  }
  EXPECT_EQ(chunk.num_samples(), 0u);
  EXPECT_FALSE(reader.read_chunk(chunk));  // stays exhausted
  rcm::Recording out;
  out.source = reader.source();
  out.layout = reader.layout();
  out.time_from_rate = reader.time_from_rate();
  out.repeated_rows = reader.repeated_rows();
  out.repeated_rows_removed = reader.repeated_rows_removed();
  Eigen::Index T = 0;
  for (const auto& c : chunks) T += c.time.size();
  const int N = reader.num_joints();
  out.time.resize(T);
  out.position.resize(T, N);
  out.velocity.resize(T, N);
  out.effort.resize(T, N);
  if (reader.has_force()) out.force = Eigen::MatrixXd(T, 3);
  Eigen::Index at = 0;
  for (const auto& c : chunks) {
    const Eigen::Index n = c.time.size();
    out.time.segment(at, n) = c.time;
    out.position.middleRows(at, n) = c.position;
    out.velocity.middleRows(at, n) = c.velocity;
    out.effort.middleRows(at, n) = c.effort;
    if (out.force) out.force->middleRows(at, n) = *c.force;
    out.line.insert(out.line.end(), c.line.begin(), c.line.end());
    at += n;
  }
  EXPECT_EQ(reader.samples_read(), static_cast<std::size_t>(T));
  return out;
}

// A contract CSV of `rows` rows with force; rows listed in `repeat` repeat the previous row's joint data.
std::string make_csv(int rows, const std::vector<int>& repeat = {}) {
  std::ostringstream s;
  s << "time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,effort_3,"
       "force_x,force_y,force_z\n";
  s.precision(17);
  int k = 0;
  for (int i = 0; i < rows; ++i) {
    if (std::find(repeat.begin(), repeat.end(), i) == repeat.end()) k = i;
    s << 0.001 * i + 1e-7 * (i % 7);
    for (int j = 0; j < 9; ++j) s << "," << std::sin(0.01 * k + j);
    for (int j = 0; j < 3; ++j) s << "," << std::cos(0.02 * i + j);
    s << "\n";
    if (i == 10) s << "\n";  // a blank line: skipped, still counted
  }
  return s.str();
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const rcm::InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(RecordingStream, CsvChunksAreTheWholeRecording) {
  // A repeated run from row 6 to 9 crosses the boundaries of chunks of 3, 4 and 7.
  const std::string text = make_csv(40, {6, 7, 8, 9, 20});
  for (bool dedupe : {false, true}) {
    rcm::RecordingReadOptions o;
    o.dedupe = dedupe;  // the repeated rows keep increasing stamps: kept without it
    const rcm::Recording whole = rcm::parse_recording(text, "rec.csv", o);
    EXPECT_EQ(whole.repeated_rows, 5u);
    EXPECT_EQ(whole.num_samples(), dedupe ? 35u : 40u);
    for (std::size_t rows : {1, 2, 3, 4, 7, 8192}) {
      const auto reader = rcm::open_recording_text(text, "rec.csv", o, rows);
      expect_same(read_in_chunks(*reader), whole, "chunk_rows " + std::to_string(rows));
    }
  }
}

TEST(RecordingStream, CsvFileLayoutsAndRateAgree) {
  TempDir dir;
  const fs::path path = dir.path() / "rec.csv";
  std::ofstream(path) << make_csv(25);
  const rcm::Recording whole = rcm::load_recording(path);
  expect_same(read_in_chunks(*rcm::open_recording(path, {}, 6)), whole, "file");
  // rostopic layout, ns time; and a file without time numbered by a rate.
  const std::string rostopic =
      "%time,field.header.seq,field.name0,field.position0,field.position1,field.position2,field.velocity0,"
      "field.velocity1,field.velocity2,field.effort0,field.effort1,field.effort2\n"
      "1700000000000000000,1,\"a,b\",0.1,0.2,0.3,1,2,3,4,5,6\n"
      "1700000000001000000,2,\"a,b\",0.1,0.2,0.4,1,2,3,4,5,6\n"
      "1700000000002000000,3,\"a,b\",0.1,0.2,0.5,1,2,3,4,5,6\n";
  expect_same(read_in_chunks(*rcm::open_recording_text(rostopic, "echo.csv", {}, 2)),
              rcm::parse_recording(rostopic, "echo.csv"), "rostopic");
  rcm::RecordingReadOptions rate;
  rate.assumed_rate_hz = 250.0;
  const std::string no_time = "position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,effort_2,"
                              "effort_3\n1,2,3,4,5,6,7,8,9\n1,2,3,4,5,6,7,8,9\n2,2,3,4,5,6,7,8,9\n";
  expect_same(read_in_chunks(*rcm::open_recording_text(no_time, "r.csv", rate, 1)),
              rcm::parse_recording(no_time, "r.csv", rate), "rate");
}

TEST(RecordingStream, ADefectInALaterChunkNamesItsLine) {
  std::string text = make_csv(60);
  // Line 52 (header 1, a blank line after row 10): a cell that is not a number.
  std::istringstream in(text);
  std::string line, out;
  for (int n = 1; std::getline(in, line); ++n) out += (n == 52 ? line.substr(0, line.rfind(',')) + ",oops" : line) + "\n";
  const auto reader = rcm::open_recording_text(out, "long.csv", {}, 8);
  rcm::Recording chunk;
  std::size_t before = 0;
  const std::string e = error_of([&] {
    while (reader->read_chunk(chunk)) before += chunk.num_samples();
  });
  EXPECT_NE(e.find("long.csv:52"), std::string::npos) << e;
  EXPECT_NE(e.find("force_z"), std::string::npos) << e;
  EXPECT_NE(e.find("'oops'"), std::string::npos) << e;
  EXPECT_EQ(before, 48u);  // the six chunks before the defect's were handed out whole
  EXPECT_EQ(e, error_of([&] { rcm::parse_recording(out, "long.csv"); }));
}

TEST(RecordingStream, TimeOrderAndRepeatsAreCheckedAcrossChunkBoundaries) {
  // Row 8 (line 10) goes back in time; with chunks of 4 it starts a chunk: line 9 is in the one before.
  std::string text = make_csv(20);
  std::istringstream in(text);
  std::string line, back;
  for (int n = 1; std::getline(in, line); ++n) {
    if (n == 10) line = "0.0001" + line.substr(line.find(','));
    back += line + "\n";
  }
  const std::string e = error_of([&] { read_in_chunks(*rcm::open_recording_text(back, "t.csv", {}, 4)); });
  EXPECT_NE(e.find("t.csv:10"), std::string::npos) << e;
  EXPECT_NE(e.find("on line 9"), std::string::npos) << e;
  EXPECT_EQ(e, error_of([&] { rcm::parse_recording(back, "t.csv"); }));

  // A logger that wrote the same message twice, stamp and all, across a boundary:
  // an error naming the repeat without --dedupe, dropped with it.
  const std::string header = "time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,effort_1,"
                             "effort_2,effort_3\n";
  const std::string twice = header + "0,1,2,3,4,5,6,7,8,9\n0.01,1,2,3,4,5,6,7,8,8\n0.01,1,2,3,4,5,6,7,8,8\n"
                            "0.02,1,2,3,4,5,6,7,8,7\n";
  const std::string r = error_of([&] { read_in_chunks(*rcm::open_recording_text(twice, "d.csv", {}, 2)); });
  EXPECT_NE(r.find("d.csv:4"), std::string::npos) << r;
  EXPECT_NE(r.find("--dedupe"), std::string::npos) << r;
  rcm::RecordingReadOptions dedupe;
  dedupe.dedupe = true;
  const auto reader = rcm::open_recording_text(twice, "d.csv", dedupe, 2);
  const rcm::Recording kept = read_in_chunks(*reader);
  EXPECT_EQ(kept.num_samples(), 3u);
  EXPECT_EQ(kept.repeated_rows, 1u);
  EXPECT_EQ(kept.line, (std::vector<std::size_t>{2, 3, 5}));
}

TEST(RecordingStream, OpeningFailsAsAWholeReadFails) {
  for (const std::string text : {std::string(""), std::string("\n\ntime,position_1\n"),
                                 std::string("time,position_1,position_2,position_3,velocity_1,velocity_2,velocity_3,"
                                             "effort_1,effort_2,effort_3\n\n")}) {
    const std::string whole = error_of([&] { rcm::parse_recording(text, "x.csv"); });
    EXPECT_NE(whole, "(no error)");
    EXPECT_EQ(error_of([&] { rcm::open_recording_text(text, "x.csv"); }), whole);
  }
  EXPECT_NE(error_of([&] { rcm::open_recording("no/such/file.csv"); }).find("file not found"), std::string::npos);
}

rcm::Recording make_message_recording(int samples) {
  rcm::Recording r;
  r.source = "sines";
  r.time.resize(samples);
  r.position.resize(samples, 6);
  r.velocity.resize(samples, 6);
  r.effort.resize(samples, 6);
  r.force = Eigen::MatrixXd(samples, 3);
  for (int k = 0; k < samples; ++k) {
    r.time[k] = 0.002 * k;
    for (int j = 0; j < 6; ++j) {
      // Samples 30 and 31 repeat sample 29 (a logger that ran faster than the topic).
      const int s = k == 30 || k == 31 ? 29 : k;
      r.position(k, j) = std::sin(0.05 * s + j);
      r.velocity(k, j) = std::cos(0.05 * s + j);
      r.effort(k, j) = 0.1 * std::sin(0.07 * s + j);
    }
    for (int i = 0; i < 3; ++i) (*r.force)(k, i) = std::sin(0.03 * k + i);
  }
  return r;
}

TEST(RecordingStream, Rosbag2ChunksAreTheWholeRecordingInEveryStorage) {
  TempDir dir;
  const rcm::Recording rec = make_message_recording(300);
  struct Case {
    std::string name;
    rcm::Rosbag2WriteOptions options;
  };
  std::vector<Case> cases(4);
  cases[0].name = "run.db3";
  cases[0].options.storage = rcm::Rosbag2WriteOptions::Storage::sqlite3;
  cases[1].name = "run.mcap";  // zstd chunks of 4 kB: a chunk boundary every few dozen samples
  cases[1].options.mcap_chunk_bytes = 4096;
  cases[2].name = "lz4.mcap";
  cases[2].options.mcap_compression = "lz4";
  cases[2].options.mcap_chunk_bytes = 4096;
  cases[3].name = "split";  // a directory of three files
  cases[3].options.split_every = 100;
  for (const Case& c : cases) {
    const fs::path path = dir.path() / c.name;
    rcm::test::write_rosbag2(path, rec, c.options);
    for (bool dedupe : {false, true}) {
      rcm::TopicReadOptions t;
      t.force_topic = "/PSM1/body/measured_cf";
      t.read.dedupe = dedupe;
      rcm::Rosbag2ReadInfo info;
      const rcm::Recording whole = rcm::load_rosbag2_recording(path, t, &info);
      EXPECT_EQ(whole.repeated_rows, 2u);
      EXPECT_EQ(whole.num_samples(), dedupe ? 298u : 300u);
      for (std::size_t rows : {1, 7, 64}) {
        const auto reader = rcm::open_rosbag2_recording(path, t, rows);
        expect_same(read_in_chunks(*reader), whole, c.name + " chunk_rows " + std::to_string(rows));
        EXPECT_EQ(reader->info().messages, info.messages);
        EXPECT_EQ(reader->info().force_messages, info.force_messages);
        EXPECT_EQ(reader->info().files, info.files);
      }
      // The force at the samples: the written force (the topics share their stamps).
      for (Eigen::Index k = 0, i = 0; k < 300; ++k) {
        if (dedupe && (k == 30 || k == 31)) continue;
        ASSERT_EQ(whole.force->row(i), rec.force->row(k)) << k;
        ++i;
      }
    }
  }
}

TEST(RecordingStream, ABadMessageInALaterChunkIsNamed) {
  // 200 JointState messages written raw; message 150 has a NaN effort.
  TempDir dir;
  const fs::path path = dir.path() / "bad.db3";
  std::vector<rcm::test::BagMessage> messages;
  for (int k = 0; k < 200; ++k) {
    rcm::cdr::JointState js;
    const std::int64_t t = 1700000000000000000 + 2000000LL * k;
    js.header.sec = static_cast<std::int32_t>(t / 1000000000);
    js.header.nanosec = static_cast<std::uint32_t>(t % 1000000000);
    js.name = {"a", "b", "c"};
    js.position = {0.01 * k, 0.2, 0.3};
    js.velocity = {1.0, 2.0, 3.0};
    js.effort = {0.1, 0.2, k == 150 ? std::nan("") : 0.3};
    messages.push_back({1, t + 500000, rcm::cdr::encode(js)});
  }
  rcm::test::write_db3(path, 3, {{"/PSM1/measured_js", "sensor_msgs/msg/JointState"}}, messages);
  const auto reader = rcm::open_rosbag2_recording(path, {}, 16);
  rcm::Recording chunk;
  std::size_t before = 0;
  const std::string e = error_of([&] {
    while (reader->read_chunk(chunk)) before += chunk.num_samples();
  });
  EXPECT_NE(e.find("/PSM1/measured_js message 150"), std::string::npos) << e;
  EXPECT_NE(e.find("effort[2]"), std::string::npos) << e;
  EXPECT_EQ(before, 144u);
  EXPECT_EQ(e, error_of([&] { rcm::load_rosbag2_recording(path); }));
}

TEST(RecordingStream, SummaryOfTheChunksIsTheWholeSummary) {
  const std::string text = make_csv(500, {100, 101});
  const rcm::Recording whole = rcm::parse_recording(text, "s.csv");
  const rcm::RecordingSummary a = rcm::summarize_recording(whole);
  const auto reader = rcm::open_recording_text(text, "s.csv", {}, 33);
  const rcm::RecordingSummary b = rcm::summarize_recording(*reader, {});
  EXPECT_EQ(a.samples, b.samples);
  EXPECT_EQ(a.duration_s, b.duration_s);
  EXPECT_EQ(a.dt_median_s, b.dt_median_s);
  EXPECT_EQ(a.dt_min_s, b.dt_min_s);
  EXPECT_EQ(a.dt_max_s, b.dt_max_s);
  EXPECT_EQ(a.jitter_s, b.jitter_s);
  EXPECT_EQ(a.repeated_rows, b.repeated_rows);
  for (std::size_t j = 0; j < 3; ++j) {
    EXPECT_EQ(a.position[j].min, b.position[j].min);
    EXPECT_EQ(a.effort[j].max, b.effort[j].max);
    EXPECT_EQ(a.force[j].min, b.force[j].min);
  }
  // The median is the element nth_element picks; the jitter the population standard deviation.
  std::vector<double> dt;
  for (Eigen::Index t = 1; t < whole.time.size(); ++t) dt.push_back(whole.time[t] - whole.time[t - 1]);
  std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
  EXPECT_EQ(b.dt_median_s, dt[dt.size() / 2]);
}

TEST(RecordingStream, TheMedianIsExactWhateverTheNumberOfDistinctValues) {
  std::mt19937_64 rng(5);
  for (std::size_t n : {1u, 2u, 10u, 1000u, 300000u}) {
    for (int spread : {0, 1, 2}) {
      std::vector<double> v(n);
      std::uniform_real_distribution<double> u(0.0, 1.0);
      for (double& x : v)
        x = spread == 0 ? std::round(u(rng) * 50) * 1e-3      // few distinct values: one pass
            : spread == 1 ? 6.6e-4 + 1e-6 * u(rng)            // all distinct, one binade: several passes
                          : std::ldexp(u(rng) - 0.3, static_cast<int>(u(rng) * 40) - 20);  // signs and binades
      rcm::detail::StreamMedian m;
      for (double x : v) m.add(x);
      int passes = 1;
      while (m.needs_pass()) {
        m.start_pass();
        std::shuffle(v.begin(), v.end(), rng);  // any order
        for (double x : v) m.add(x);
        ++passes;
      }
      EXPECT_LE(passes, 4);
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(n / 2), v.end());
      EXPECT_EQ(m.get(), v[n / 2]) << n << " values, spread " << spread;
      if (spread == 0) EXPECT_EQ(passes, 1);
    }
  }
}

TEST(RecordingStream, TheChunkedWriterWritesWhatSaveRecordingWrites) {
  TempDir dir;
  const rcm::Recording rec = rcm::parse_recording(make_csv(50), "w.csv");
  rcm::save_recording(dir.path() / "whole.csv", rec);
  {
    rcm::RecordingWriter writer(dir.path() / "chunked.csv", 3, true);
    const auto reader = rcm::open_recording_rows(rec, 7);
    rcm::Recording chunk;
    while (reader->read_chunk(chunk)) writer.write(chunk);
    EXPECT_FALSE(fs::exists(dir.path() / "chunked.csv"));  // whole or not at all
    writer.commit();
  }
  auto slurp = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  EXPECT_EQ(slurp(dir.path() / "chunked.csv"), slurp(dir.path() / "whole.csv"));
  {
    // Abandoned midway (an error while streaming): nothing under the name.
    rcm::RecordingWriter writer(dir.path() / "abandoned.csv", 3, true);
    writer.write(rec);
  }
  EXPECT_FALSE(fs::exists(dir.path() / "abandoned.csv"));
}

}  // namespace
