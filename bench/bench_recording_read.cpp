// Speed of reading a recording CSV in chunks (io/recording_reader.hpp): a
// 1.5 kHz dVRK recording of 7 joints with force, 200 000 rows (2 min 13 s),
// read through open_recording() chunk by chunk as the streaming commands do,
// and whole through load_recording(). Counter rows/s.
//
// The file is written once, outside the timed region, into a temporary
// directory removed at exit.

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>

#include "rcm/io/recording_reader.hpp"

namespace fs = std::filesystem;

namespace {

constexpr Eigen::Index kRows = 200000;
constexpr int kJoints = 7;

class CsvFile {
 public:
  CsvFile() {
    dir_ = fs::temp_directory_path() / ("rcm_bench_recording_read_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    path_ = dir_ / "recording.csv";
    rcm::Recording r;
    r.time.resize(kRows);
    r.position.resize(kRows, kJoints);
    r.velocity.resize(kRows, kJoints);
    r.effort.resize(kRows, kJoints);
    r.force = Eigen::MatrixXd(kRows, 3);
    for (Eigen::Index k = 0; k < kRows; ++k) {
      const double t = static_cast<double>(k) / 1500.0;
      r.time[k] = t;
      for (int j = 0; j < kJoints; ++j) {
        const double w = 2.0 * M_PI * (0.13 + 0.071 * j);
        r.position(k, j) = 0.3 * std::sin(w * t + j);
        r.velocity(k, j) = 0.3 * w * std::cos(w * t + j);
        r.effort(k, j) = 0.1 * std::sin(3.1 * w * t) + 0.01 * std::sin(97.0 * t + j);
      }
      for (int i = 0; i < 3; ++i) (*r.force)(k, i) = 2.0 * std::sin(2.0 * M_PI * (0.21 + 0.1 * i) * t);
    }
    rcm::save_recording(path_, r);
  }
  ~CsvFile() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path dir_, path_;
};

const CsvFile& file() {
  static const CsvFile f;
  return f;
}

void set_counters(benchmark::State& state) {
  state.counters["rows/s"] = benchmark::Counter(static_cast<double>(kRows), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["file_MB"] = static_cast<double>(fs::file_size(file().path())) / 1e6;
}

void BM_ReadCsvChunks(benchmark::State& state) {
  const auto rows = static_cast<std::size_t>(state.range(0));
  file();  // written before the timed loop
  for (auto _ : state) {
    const auto reader = rcm::open_recording(file().path(), {}, rows);
    rcm::Recording chunk;
    std::size_t n = 0;
    while (reader->read_chunk(chunk)) n += chunk.num_samples();
    if (n != static_cast<std::size_t>(kRows)) state.SkipWithError("wrong number of rows");
    benchmark::DoNotOptimize(chunk);
  }
  set_counters(state);
}
BENCHMARK(BM_ReadCsvChunks)->Arg(1024)->Arg(8192)->Arg(65536)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

void BM_LoadCsvWhole(benchmark::State& state) {
  file();
  for (auto _ : state) {
    const rcm::Recording r = rcm::load_recording(file().path());
    benchmark::DoNotOptimize(r.time.data());
  }
  set_counters(state);
}
BENCHMARK(BM_LoadCsvWhole)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

void BM_SummarizeCsvChunks(benchmark::State& state) {
  file();
  for (auto _ : state) {
    const auto reader = rcm::open_recording(file().path());
    const rcm::RecordingSummary s =
        rcm::summarize_recording(*reader, [] { return rcm::open_recording(file().path()); });
    benchmark::DoNotOptimize(s.dt_median_s);
  }
  set_counters(state);
}
BENCHMARK(BM_SummarizeCsvChunks)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
