// rcm's outputs under abrupt and polite stops, end to end on a small simulated
// session: SIGKILL of `rcm run` at random moments leaves only whole files (and
// the next run removes the temporaries it left); SIGINT and SIGTERM stop
// `rcm run` and `rcm simulate` with what they finished saved, a message saying
// so, and exit status 128 + the signal.
//
// The kill moments are drawn from a seed printed by the test; RCM_KILL_SEED=N
// repeats them.

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "child_process.hpp"
#include "output_checks.hpp"
#include "rcm/io/recording.hpp"
#include "temp_dir.hpp"

// The waits below bound how long a test waits for progress or for an exit
// after a signal; they are generous because the instrumented build on a loaded
// machine runs many times slower, and only stop a test that hangs.

namespace {

using rcm::test::ChildProcess;
using rcm::test::read_text;

class Outputs : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new rcm::test::TempDir("rcm_test_outputs_");
    const std::string log = rcm::test::make_small_session(dir_->path());
    ASSERT_EQ(log, "") << "the small session could not be made";
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::filesystem::path path(const std::string& name) { return dir_->path() / name; }
  // `rcm run` on the small session with the linear model, so that no network
  // is trained; `method` three-step writes the same files as joint in a fifth of the time.
  static std::vector<std::string> run_args(const std::filesystem::path& out, const std::string& method = "joint") {
    return {RCM_CLI_PATH, "run", path("session/session.json").string(), "--model-file", path("model.json").string(),
            "--method", method, "--out", out.string()};
  }
  static rcm::test::TempDir* dir_;
};
rcm::test::TempDir* Outputs::dir_ = nullptr;

std::string describe_defects(const std::filesystem::path& dir) {
  std::string defects;
  for (const auto& f : rcm::test::list_outputs(dir))
    if (const std::string d = rcm::test::find_defect(f); !d.empty()) defects += f.string() + ": " + d + "\n";
  return defects;
}

TEST_F(Outputs, KilledRunLeavesOnlyWholeFiles) {
  const char* given = std::getenv("RCM_KILL_SEED");
  const unsigned seed = given ? static_cast<unsigned>(std::strtoul(given, nullptr, 10)) : std::random_device{}();
  std::cout << "kill seed " << seed << " (RCM_KILL_SEED=" << seed << " repeats these kills)" << std::endl;

  // A whole run first: how long the command takes and what it writes.
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::string> args = run_args(path("run_whole"), "three-step");
  const rcm::test::Exit whole = rcm::test::run_cli({args.begin() + 1, args.end()}, path("run_whole.log"));
  const double run_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_EQ(whole.code, 0) << whole.log;
  ASSERT_EQ(describe_defects(path("run_whole")), "");
  ASSERT_TRUE(rcm::test::list_temporaries(path("run_whole")).empty());

  // One kill at a random moment in each quarter of the run, so that every phase
  // (model, tissue, trials, report, figures) is hit; all into one folder, so
  // that later runs meet what earlier ones left.
  const auto out = path("run_killed");
  const int kills = 4;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> within(0.0, 1.0);
  std::size_t temporaries_seen = 0;
  for (int k = 0; k < kills; ++k) {
    const double delay_s = (k + within(rng)) * run_s / kills;
    ChildProcess child(run_args(out, "three-step"), path("run_killed.log"));
    ASSERT_TRUE(child.started());
    std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
    child.send(SIGKILL, true);  // gnuplot too
    const int code = child.wait(std::chrono::seconds(10));
    std::cout << "kill " << k + 1 << " at " << delay_s << " s: " << (code == -SIGKILL ? "killed" : "had ended")
              << ", " << rcm::test::list_outputs(out).size() << " outputs, "
              << rcm::test::list_temporaries(out).size() << " temporaries" << std::endl;
    EXPECT_EQ(describe_defects(out), "") << "kill " << k + 1 << " at " << delay_s << " s, seed " << seed;
    temporaries_seen += rcm::test::list_temporaries(out).size();
  }
  // The next run removes the temporaries of the killed ones and writes everything.
  std::vector<std::string> again = run_args(out, "three-step");
  const rcm::test::Exit after = rcm::test::run_cli({again.begin() + 1, again.end()}, path("run_after.log"));
  ASSERT_EQ(after.code, 0) << after.log;
  EXPECT_EQ(describe_defects(out), "");
  EXPECT_TRUE(rcm::test::list_temporaries(out).empty()) << temporaries_seen << " temporaries seen after the kills";
  EXPECT_EQ(rcm::test::list_outputs(out).size(), rcm::test::list_outputs(path("run_whole")).size());
}

TEST_F(Outputs, InterruptedRunSavesTheFinishedTrials) {
  const auto out = path("run_int");
  const auto problems = path("run_int_problems");
  // --export-problems writes one file per trial as it ends: the moment to interrupt.
  std::vector<std::string> args = run_args(out);
  args.insert(args.end(), {"--export-problems", problems.string()});
  ChildProcess child(args, path("run_int.log"));
  ASSERT_TRUE(rcm::test::wait_for([&] { return !rcm::test::list_outputs(problems).empty() || !child.alive(); },
                                  std::chrono::seconds(120)));
  child.send(SIGINT);
  const int code = child.wait(std::chrono::seconds(60));
  const std::string log = child.log();
  EXPECT_EQ(code, 130) << log;
  EXPECT_NE(log.find("rcm: SIGINT: interrupted after"), std::string::npos) << log;
  EXPECT_NE(log.find("saved results.json and report.md of"), std::string::npos) << log;
  EXPECT_NE(log.find("not estimated: "), std::string::npos) << log;
  EXPECT_EQ(describe_defects(out), "");
  const nlohmann::json results = nlohmann::json::parse(read_text(out / "results.json"));
  ASSERT_TRUE(results.contains("interrupted")) << results.dump().substr(0, 400);
  const std::size_t estimated = results["interrupted"]["trials_estimated"];
  EXPECT_GE(estimated, 1u);
  EXPECT_LT(estimated, results["interrupted"]["trials_planned"].get<std::size_t>());
  EXPECT_EQ(results["trials"].size(), estimated);
  for (const auto& t : results["trials"]) EXPECT_TRUE(t["misalignment_m"].is_array());
  EXPECT_NE(read_text(out / "report.md").find("**Interrupted** after"), std::string::npos);
  EXPECT_EQ(nlohmann::json::parse(read_text(out / "free_space_model.json"))["kind"], "linear");
  EXPECT_FALSE(std::filesystem::exists(out / "figures"));
}

TEST_F(Outputs, InterruptedWhileDrawingKeepsResultsAndReport) {
  const auto out = path("run_draw_int");
  ChildProcess child(run_args(out, "three-step"), path("run_draw_int.log"));
  ASSERT_TRUE(rcm::test::wait_for([&] { return std::filesystem::exists(out / "figures") || !child.alive(); },
                                  std::chrono::seconds(120)));
  child.send(SIGINT);
  const int code = child.wait(std::chrono::seconds(60));
  const std::string log = child.log();
  EXPECT_EQ(code, 130) << log;
  EXPECT_NE(log.find("rcm: SIGINT: interrupted after every trial was estimated; saved results.json"), std::string::npos)
      << log;
  EXPECT_EQ(describe_defects(out), "");
  const nlohmann::json results = nlohmann::json::parse(read_text(out / "results.json"));
  EXPECT_FALSE(results.contains("interrupted"));
  // The report lists exactly the figures that exist.
  const std::string report = read_text(out / "report.md");
  for (const char* name : {"fig4a_force", "fig4b_force", "fig4c_decoupled", "table4_estimates"})
    EXPECT_EQ(report.find(std::string("figures/") + name + ".png") != std::string::npos,
              std::filesystem::exists(out / "figures" / (std::string(name) + ".png")))
        << name;
}

TEST_F(Outputs, InterruptedSimulateKeepsTheFinishedRecordings) {
  for (const int signal_number : {SIGINT, SIGTERM}) {
    const std::string name = signal_number == SIGINT ? "simulate_int" : "simulate_term";
    const auto out = path(name);
    ChildProcess child({RCM_CLI_PATH, "simulate", "--quick", "--seed", "3", "--out", out.string()}, path(name + ".log"));
    auto recordings = [&] {
      std::vector<std::filesystem::path> csv;
      for (const auto& f : rcm::test::list_outputs(out))
        if (f.extension() == ".csv") csv.push_back(f);
      return csv;
    };
    ASSERT_TRUE(rcm::test::wait_for([&] { return !recordings().empty() || !child.alive(); }, std::chrono::seconds(120)));
    child.send(signal_number);
    const int code = child.wait(std::chrono::seconds(60));
    const std::string log = child.log();
    EXPECT_EQ(code, 128 + signal_number) << log;
    EXPECT_NE(log.find("rcm: " + std::string(signal_number == SIGINT ? "SIGINT" : "SIGTERM") +
                       ": interrupted while simulating"),
              std::string::npos)
        << log;
    EXPECT_NE(log.find("session.json not written"), std::string::npos) << log;
    EXPECT_FALSE(std::filesystem::exists(out / "session.json"));
    EXPECT_FALSE(recordings().empty());
    EXPECT_EQ(describe_defects(out), "");
    // Each finished recording is named in the message.
    for (const auto& f : recordings())
      if (f.filename().string().find("_truth") == std::string::npos)
        EXPECT_NE(log.find(f.filename().string()), std::string::npos) << f << "\n" << log;
    EXPECT_EQ(rcm::test::find_defect(out / "sim_config.json"), "");
  }
}

}  // namespace
