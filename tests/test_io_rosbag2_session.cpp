// A session recorded as rosbag2 runs like the same session in CSV: a simulated
// session is converted recording by recording into a mix of rosbag2 layouts
// (MCAP zstd, lz4 and uncompressed; a Humble SQLite directory; a Jazzy SQLite
// directory split in two files; a bare .db3), named by a second manifest, and
// `rcm run` must estimate the same misalignment for every trial from both.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>

#include <nlohmann/json.hpp>

#include "run_cli.hpp"
#include "temp_dir.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/rosbag2.hpp"
#include "support/rosbag2_writer.hpp"

namespace fs = std::filesystem;
using rcm::test::Rosbag2WriteOptions;

namespace {

// Temporary directories of this file are named rcm_test_rosbag2_session_<n>.
struct TempDir : rcm::test::TempDir {
  TempDir() : rcm::test::TempDir("rcm_test_rosbag2_session_") {}
};

constexpr const char* kForceTopic = "/PSM1/body/measured_cf";

using rcm::test::run_cli;

nlohmann::json read_json(const fs::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

// The layouts a lab may hand over, in turn: name suffix and options.
struct Layout {
  const char* suffix;  // ".mcap", ".db3" or "" (a directory)
  Rosbag2WriteOptions options;
  bool split_in_two = false;
};

std::vector<Layout> layouts() {
  std::vector<Layout> out;
  for (const char* compression : {"zstd", "lz4", ""}) {
    Layout l{".mcap", {}};
    l.options.mcap_compression = compression;
    l.options.mcap_chunk_bytes = 256 * 1024;
    out.push_back(l);
  }
  Layout humble{"", {}};
  humble.options.storage = Rosbag2WriteOptions::Storage::sqlite3;
  humble.options.sqlite_schema = 3;
  humble.options.metadata_version = 5;
  out.push_back(humble);
  Layout jazzy{"", {}, true};
  jazzy.options.storage = Rosbag2WriteOptions::Storage::sqlite3;
  jazzy.options.sqlite_schema = 4;
  jazzy.options.metadata_version = 9;
  out.push_back(jazzy);
  Layout bare{".db3", {}};
  bare.options.storage = Rosbag2WriteOptions::Storage::sqlite3;
  bare.options.sqlite_schema = 3;
  out.push_back(bare);
  return out;
}

}  // namespace

TEST(Rosbag2Session, RunGivesTheSameEstimatesAsFromCsv) {
  TempDir dir;
  const fs::path sim = dir.path() / "sim";
  std::string out;
  ASSERT_EQ(run_cli("simulate --quick --no-truth --threads 2 --out " + sim.string(), out), 0) << out;
  const nlohmann::json csv_session = read_json(sim / "session.json");

  // Every recording the manifest names, converted in turn to the next layout.
  const std::vector<Layout> all = layouts();
  std::size_t converted = 0;
  std::vector<bool> layout_used(all.size(), false);
  auto convert = [&](nlohmann::json& name) {
    const std::string csv = name.get<std::string>();
    const rcm::Recording rec = rcm::load_recording(sim / csv);
    const std::size_t which = converted++ % all.size();
    const Layout& layout = all[which];
    layout_used[which] = true;
    Rosbag2WriteOptions o = layout.options;
    if (layout.split_in_two) o.split_every = (rec.num_samples() + 1) / 2;
    const std::string bag = "bags/" + fs::path(csv).stem().string() + layout.suffix;
    fs::create_directories(sim / "bags");
    rcm::test::write_rosbag2(sim / bag, rec, o);
    name = bag;
  };
  nlohmann::json bag_session = csv_session;
  for (auto& f : bag_session["free_space"]) convert(f);
  if (bag_session.contains("calibration")) convert(bag_session["calibration"]["recording"]);
  if (bag_session.contains("baseline")) convert(bag_session["baseline"]);
  for (auto& t : bag_session["trials"]) {
    convert(t["recording"]);
    if (t.contains("static")) convert(t["static"]);
  }
  ASSERT_GE(converted, all.size());
  for (std::size_t i = 0; i < all.size(); ++i) EXPECT_TRUE(layout_used[i]) << i;
  {
    std::ofstream manifest(sim / "session_rosbag2.json");
    manifest << bag_session.dump(2);
  }
  // The split Jazzy directory really is two files.
  rcm::Rosbag2ReadInfo info;
  rcm::load_rosbag2_recording(sim / bag_session["trials"][0]["static"].get<std::string>(), {}, &info);
  EXPECT_EQ(info.files.size(), 2u);
  EXPECT_EQ(info.sqlite_schema, 4);

  // The paper's method with the linear model: seconds, and deterministic.
  const std::string flags = " --model linear --method three-step --seed 1";
  ASSERT_EQ(run_cli("run " + (sim / "session.json").string() + flags + " --out " + (dir.path() / "csv_run").string(), out), 0)
      << out;
  ASSERT_EQ(run_cli("run " + (sim / "session_rosbag2.json").string() + flags + " --force-topic " + kForceTopic +
                        " --out " + (dir.path() / "bag_run").string(),
                    out),
            0)
      << out;
  const nlohmann::json a = read_json(dir.path() / "csv_run" / "results.json");
  const nlohmann::json b = read_json(dir.path() / "bag_run" / "results.json");
  ASSERT_EQ(a["trials"].size(), csv_session["trials"].size());
  ASSERT_EQ(b["trials"].size(), a["trials"].size());
  for (std::size_t i = 0; i < a["trials"].size(); ++i) {
    const auto& ta = a["trials"][i];
    const auto& tb = b["trials"][i];
    SCOPED_TRACE(ta["name"].get<std::string>());
    EXPECT_EQ(tb["name"], ta["name"]);
    EXPECT_EQ(tb["samples_used"], ta["samples_used"]);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(tb["misalignment_m"][k].get<double>(), ta["misalignment_m"][k].get<double>(), 1e-9) << k;
      // The force columns came through the WrenchStamped topic.
      EXPECT_NEAR(tb["force_rmse_n"][k].get<double>(), ta["force_rmse_n"][k].get<double>(), 1e-9) << k;
    }
    EXPECT_NEAR(tb["error_m"].get<double>(), ta["error_m"].get<double>(), 1e-9);
  }
}
