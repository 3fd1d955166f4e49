// Speed of reading rosbag2 recordings: a 10-minute dVRK recording at 1 kHz
// (600 000 JointState messages of 7 joints and 600 000 WrenchStamped) in each
// storage rcm reads, loaded with its force topic. The target: under 1.5 s per
// format on one core.
//
// The files are written once per format, outside the timed region, into a
// temporary directory removed at exit; set RCM_BENCH_ROSBAG2_DIR to write them
// there and keep them (to time other tools on the same files).

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include "rcm/io/rosbag2.hpp"
#include "support/rosbag2_writer.hpp"

namespace fs = std::filesystem;
using rcm::test::Rosbag2WriteOptions;

namespace {

constexpr Eigen::Index kSamples = 600000;  // 10 min at 1 kHz
constexpr int kJoints = 7;
constexpr const char* kForceTopic = "/PSM1/body/measured_cf";

// Sines with incommensurate frequencies: values that compress like measured
// data rather than like a constant.
rcm::Recording make_recording() {
  rcm::Recording r;
  r.source = "10 min of sines";
  r.time.resize(kSamples);
  r.position.resize(kSamples, kJoints);
  r.velocity.resize(kSamples, kJoints);
  r.effort.resize(kSamples, kJoints);
  r.force = Eigen::MatrixXd(kSamples, 3);
  for (Eigen::Index k = 0; k < kSamples; ++k) {
    const double t = 0.001 * static_cast<double>(k);
    r.time[k] = t;
    for (int j = 0; j < kJoints; ++j) {
      const double w = 2.0 * M_PI * (0.13 + 0.071 * j);
      r.position(k, j) = 0.3 * std::sin(w * t + j);
      r.velocity(k, j) = 0.3 * w * std::cos(w * t + j);
      r.effort(k, j) = 0.1 * std::sin(3.1 * w * t) + 0.01 * std::sin(97.0 * t + j);
    }
    for (int i = 0; i < 3; ++i) (*r.force)(k, i) = 2.0 * std::sin(2.0 * M_PI * (0.21 + 0.1 * i) * t);
  }
  return r;
}

class BagFiles {
 public:
  BagFiles() {
    if (const char* keep = std::getenv("RCM_BENCH_ROSBAG2_DIR")) {
      dir_ = keep;
      keep_ = true;
    } else {
      dir_ = fs::temp_directory_path() / ("rcm_bench_rosbag2_" + std::to_string(::getpid()));
    }
    fs::create_directories(dir_);
  }
  ~BagFiles() {
    std::error_code ec;
    if (!keep_) fs::remove_all(dir_, ec);
  }
  // The file of `name`, written on first use.
  const fs::path& get(const std::string& name, const Rosbag2WriteOptions& options) {
    auto it = files_.find(name);
    if (it != files_.end()) return it->second;
    if (!recording_) recording_ = std::make_unique<rcm::Recording>(make_recording());
    const fs::path path = dir_ / name;
    rcm::test::write_rosbag2(path, *recording_, options);
    return files_.emplace(name, path).first->second;
  }

 private:
  fs::path dir_;
  bool keep_ = false;
  std::unique_ptr<rcm::Recording> recording_;
  std::map<std::string, fs::path> files_;
};

BagFiles& bags() {
  static BagFiles files;
  return files;
}

void read_bag(benchmark::State& state, const std::string& name, const Rosbag2WriteOptions& options) {
  const fs::path& path = bags().get(name, options);
  rcm::TopicReadOptions read;
  read.force_topic = kForceTopic;
  std::size_t messages = 0;
  for (auto _ : state) {
    rcm::Rosbag2ReadInfo info;
    const rcm::Recording r = rcm::load_rosbag2_recording(path, read, &info);
    benchmark::DoNotOptimize(r.position.data());
    if (r.num_samples() != static_cast<std::size_t>(kSamples) || !r.has_force())
      state.SkipWithError("the recording did not read back whole");
    messages = info.messages + info.force_messages;
  }
  state.counters["messages/s"] =
      benchmark::Counter(static_cast<double>(messages), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["file_MB"] = static_cast<double>(fs::file_size(path)) / 1e6;
}

Rosbag2WriteOptions mcap(const char* compression) {
  Rosbag2WriteOptions o;
  o.mcap_compression = compression;
  return o;
}

void BM_ReadSqliteJazzy(benchmark::State& state) {
  Rosbag2WriteOptions o;
  o.storage = Rosbag2WriteOptions::Storage::sqlite3;
  o.sqlite_schema = 4;
  read_bag(state, "jazzy.db3", o);
}
void BM_ReadMcapUncompressed(benchmark::State& state) { read_bag(state, "none.mcap", mcap("")); }
void BM_ReadMcapLz4(benchmark::State& state) { read_bag(state, "lz4.mcap", mcap("lz4")); }
void BM_ReadMcapZstd(benchmark::State& state) { read_bag(state, "zstd.mcap", mcap("zstd")); }

}  // namespace

BENCHMARK(BM_ReadSqliteJazzy)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_ReadMcapUncompressed)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_ReadMcapLz4)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_ReadMcapZstd)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

BENCHMARK_MAIN();
