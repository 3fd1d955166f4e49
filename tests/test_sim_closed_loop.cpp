// The closed-loop bench: the incision's motions, and `rcm simulate --experiment
// closed-loop` end to end (a quick session, the linear free-space model): the
// correction in the loop brings the RCM back onto a moving incision, never by
// a step in the wrong direction, and its outputs follow their shape.

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "rcm/sim/closed_loop.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;

namespace {

TEST(IncisionMotion, StepDriftAndBreathing) {
  const auto motions = rcm::sim::make_default_incision_motions();
  ASSERT_EQ(motions.size(), 3u);
  const auto& step = motions[0];
  const auto& drift = motions[1];
  const auto& breathing = motions[2];
  EXPECT_EQ(step.name, "step");
  EXPECT_TRUE(step.get_misalignment(step.step_time_s - 1e-9).isZero());
  EXPECT_NEAR(step.get_misalignment(step.step_time_s).norm(), 0.010, 1e-12);
  EXPECT_EQ(drift.name, "drift");
  EXPECT_TRUE(drift.get_misalignment(drift.drift_start_s).isZero());
  EXPECT_NEAR(drift.get_misalignment(drift.drift_end_s + 100).norm(), 0.009, 1e-12);
  EXPECT_NEAR(drift.get_misalignment(0.5 * (drift.drift_start_s + drift.drift_end_s)).norm(), 0.0045, 1e-12);
  EXPECT_EQ(breathing.name, "breathing");
  EXPECT_NEAR(breathing.get_misalignment(0.0).z(), 0.006, 1e-15);
  EXPECT_NEAR(breathing.get_misalignment(1.0).z(), 0.009, 1e-12);  // a quarter period at 0.25 Hz
  EXPECT_NEAR(breathing.get_misalignment(3.0).z(), 0.003, 1e-12);
}

int run_cli(const std::string& args, std::string& out) {
  const std::string cmd = std::string(RCM_CLI_PATH) + " " + args + " 2>/dev/null";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  out.clear();
  char buf[4096];
  while (std::size_t n = fread(buf, 1, sizeof buf, pipe.get())) out.append(buf, n);
  const int status = pclose(pipe.release());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(ClosedLoopBench, TheCorrectionBringsTheRcmBackWithoutAWrongMove) {
  rcm::test::TempDir dir("rcm_closed_loop");
  const fs::path out = dir.path() / "bench";
  std::string text;
  ASSERT_EQ(run_cli("simulate --experiment closed-loop --quick --model linear --json --out " + out.string(), text), 0)
      << text;
  const nlohmann::json j = nlohmann::json::parse(text);
  EXPECT_EQ(j["format"], "rcm-closed-loop/1");
  std::ifstream file(out / "closed_loop.json");
  EXPECT_EQ(nlohmann::json::parse(file)["scenarios"], j["scenarios"]);
  EXPECT_TRUE(fs::exists(out / "closed_loop.md"));
  EXPECT_TRUE(fs::exists(out / "session" / "session.json"));
  ASSERT_EQ(j["figures"].size(), 9u);
  for (const auto& f : j["figures"]) EXPECT_TRUE(fs::exists(f.get<std::string>())) << f;

  // The open runs leave the RCM where it was docked: the incision's final offset remains.
  const double final_open[3] = {0.010, 0.009, 0.006};
  int i = 0;
  for (const char* name : {"step", "drift", "breathing"}) {
    SCOPED_TRACE(name);
    const auto& s = j["scenarios"][name];
    const auto& open = s["open"];
    const auto& closed = s["closed"];
    for (const auto* run : {&open, &closed})
      for (const char* key : {"peak_force_n", "rms_force_after_settle_n", "time_to_below_2n_s",
                              "residual_misalignment_m", "wrong_direction_moves"})
        EXPECT_TRUE(run->contains(key)) << key;
    EXPECT_NEAR(open["residual_misalignment_m"].get<double>(), final_open[i++], 0.001);
    EXPECT_TRUE(open["time_to_below_2n_s"].is_null());
    EXPECT_EQ(open["final_shift_base_m"], nlohmann::json({0.0, 0.0, 0.0}));
    // Closed: moves were made, none against the true remaining misalignment,
    // and the RCM ends nearer the incision with less force on the body wall.
    EXPECT_GT(closed["moves"].get<int>(), 0);
    EXPECT_EQ(closed["wrong_direction_moves"].get<int>(), 0);
    EXPECT_LT(closed["residual_misalignment_m"].get<double>(), 0.5 * open["residual_misalignment_m"].get<double>());
    EXPECT_LT(closed["rms_force_after_settle_n"].get<double>(), open["rms_force_after_settle_n"].get<double>());
    EXPECT_LE(closed["peak_force_n"].get<double>(), open["peak_force_n"].get<double>() + 0.5);
    ASSERT_FALSE(closed["advice"].empty());
    EXPECT_EQ(closed["advice"][0]["advice"], "hold: no misalignment detected");
  }
  // A step and a drift end under 2 N for good; the breathing's own motion may not.
  EXPECT_TRUE(j["scenarios"]["step"]["closed"]["time_to_below_2n_s"].is_number());
  EXPECT_TRUE(j["scenarios"]["drift"]["closed"]["time_to_below_2n_s"].is_number());

  // Bad flags are located errors.
  EXPECT_EQ(run_cli("simulate --experiment closed-loop --model nonsense --quick --out " + (dir.path() / "x").string(), text),
            2);
}

}  // namespace
