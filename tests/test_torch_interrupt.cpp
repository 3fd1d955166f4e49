// `rcm dynamics fit` stopped by SIGINT while an LSTM trains: the model of the
// best epoch finished is saved whole (and says it was interrupted), the
// message says what was saved, and the exit status is 130.

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <string>

#include "child_process.hpp"
#include "output_checks.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "temp_dir.hpp"

namespace {

TEST(TorchInterrupt, InterruptedFitSavesTheBestEpoch) {
  rcm::test::TempDir dir("rcm_test_torch_interrupt_");
  const rcm::test::Exit sim = rcm::test::run_cli(
      {"simulate", "--quick", "--seed", "1", "--free-space-s", "60", "--out", (dir.path() / "session").string()},
      dir.path() / "simulate.log");
  ASSERT_EQ(sim.code, 0) << sim.log;
  const auto model = dir.path() / "model.json";
  // Early stopping would need far more epochs than the test waits for.
  rcm::test::ChildProcess fit({RCM_CLI_PATH, "dynamics", "fit", "--model", "lstm", "--hidden", "8", "--window", "50",
                               "--streams", "8", "--max-epochs", "100000", "--threads", "1", "--out", model.string(),
                               (dir.path() / "session" / "free_space.csv").string()},
                              dir.path() / "fit.log");
  // The second finished epoch is the moment: some training done, the rest not.
  ASSERT_TRUE(rcm::test::wait_for(
      [&] { return fit.log().find("epoch   2") != std::string::npos || !fit.alive(); }, std::chrono::seconds(120)))
      << fit.log();
  fit.send(SIGINT);
  const int code = fit.wait(std::chrono::seconds(60));
  const std::string log = fit.log();
  EXPECT_EQ(code, 130) << log;
  EXPECT_NE(log.find("rcm: SIGINT: interrupted after "), std::string::npos) << log;
  EXPECT_NE(log.find("(the best validation loss so far) to " + model.string()), std::string::npos) << log;
  ASSERT_EQ(rcm::test::find_defect(model), "");
  const nlohmann::json saved = nlohmann::json::parse(rcm::test::read_text(model));
  EXPECT_EQ(saved["kind"], "lstm");
  const auto loaded = rcm::dynamics::load_torque_model(model);
  EXPECT_EQ(loaded->info().training.value("interrupted", false), true) << loaded->info().training.dump();
  EXPECT_GE(loaded->info().training["best_epoch"].get<int>(), 1);
  EXPECT_TRUE(rcm::test::list_temporaries(dir.path()).empty());
}

}  // namespace
