// `rcm dynamics fit|eval` end to end on a small synthetic recording: the model
// file is written, eval prints the JSON shape of docs/formats.md, bad input exits non-zero.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"
#include "test_dynamics_synthetic.hpp"
#include "temp_dir.hpp"

namespace {
struct Run {
  int status;
  std::string out;
};
Run run_shell(const std::string& cmd) {
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  while (std::fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  return {status, out};
}
// `environment`: VAR=value assignments put before the command.
Run run(const std::string& args, bool with_stderr = false, const std::string& environment = "") {
  return run_shell(environment + " " + std::string(RCM_CLI_PATH) + " " + args +
                   (with_stderr ? " 2>&1" : " 2>/dev/null"));
}
}  // namespace

TEST(DynamicsCli, FitLinearThenEvalJson) {
  const auto dir = rcm::test::get_process_temp_dir() / "rcm_test_dynamics_cli";
  std::filesystem::create_directories(dir);
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 40;
  rcm::save_recording(dir / "free.csv", rcm::test::make_synthetic_free_space(so));
  const auto model = (dir / "model.json").string();
  const auto fit = run("dynamics fit --model linear --out " + model + " " + (dir / "free.csv").string() + " --json");
  ASSERT_EQ(fit.status, 0) << fit.out;
  EXPECT_EQ(nlohmann::json::parse(fit.out)["kind"], "linear");
  const auto ev = run("dynamics eval " + model + " " + (dir / "free.csv").string() + " --json");
  ASSERT_EQ(ev.status, 0) << ev.out;
  const auto j = nlohmann::json::parse(ev.out);
  ASSERT_EQ(j["joints"].size(), 3u);
  EXPECT_EQ(j["joints"][0]["index"], 1);
  EXPECT_GT(j["joints"][2]["nrmse_percent"].get<double>(), 0.0);
  EXPECT_LT(j["joints"][2]["nrmse_percent"].get<double>(), 10.0);
  EXPECT_EQ(j["mode"], "batch");
  const auto table = run("dynamics eval " + model + " " + (dir / "free.csv").string());
  EXPECT_NE(table.out.find("NRMSE"), std::string::npos);
  EXPECT_NE(table.out.find("batch (offline)"), std::string::npos) << table.out;
  // Streaming: compute_step sample by sample, causal; the linear model's offline
  // qddot uses later samples (zero phase), so the two must differ.
  const auto st = run("dynamics eval " + model + " " + (dir / "free.csv").string() + " --streaming --json");
  ASSERT_EQ(st.status, 0) << st.out;
  const auto js = nlohmann::json::parse(st.out);
  EXPECT_EQ(js["mode"], "streaming");
  double max_change = 0;
  for (int k = 0; k < 3; ++k)
    max_change = std::max(max_change, std::abs(js["joints"][k]["rmse"].get<double>() -
                                               j["joints"][k]["rmse"].get<double>()));
  EXPECT_GT(max_change, 1e-9);
  EXPECT_NE(run("dynamics fit --model svm --out x.json " + (dir / "free.csv").string()).status, 0);
  EXPECT_NE(run("dynamics eval " + model + " " + (dir / "missing.csv").string()).status, 0);
  // A bad value of a fit flag: non-zero exit, and the message names the flag.
  auto expect_rejected = [&](const std::string& flag, const std::vector<std::string>& values) {
    for (const auto& bad : values) {
      const auto r =
          run("dynamics fit --model lstm " + flag + " " + bad + " --out " + model + " " + (dir / "free.csv").string(),
              true);
      EXPECT_NE(r.status, 0) << flag << " " << bad;
      EXPECT_NE(r.out.find(flag), std::string::npos) << r.out;
    }
  };
  expect_rejected("--direction-features", {"0.01,abc", "0.01,-0.1", "0.01,,0.1", "0", "''"});
  expect_rejected("--acceleration-features", {"0.03,abc", "-0.03", "0", "''"});
  expect_rejected("--loss-balance", {"1.5", "-0.1", "nan", "abc"});
  expect_rejected("--output-delay", {"-0.01", "nan", "inf", "abc"});
  {
    // 5 s at 200 Hz is 1000 samples, more than the burn-in the shifted targets need.
    const auto r = run("dynamics fit --model lstm --output-delay 5 --out " + model + " " + (dir / "free.csv").string(),
                       true);
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.out.find("--output-delay"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("burn-in"), std::string::npos) << r.out;
  }
  for (const char* kind : {"linear", "mlp", "hybrid"}) {
    const auto r = run(std::string("dynamics fit --model ") + kind + " --output-delay 0.04 --out " + model + " " +
                           (dir / "free.csv").string(),
                       true);
    EXPECT_NE(r.status, 0) << kind;
    EXPECT_NE(r.out.find("--output-delay"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("lstm only"), std::string::npos) << r.out;
  }
  // Only the recurrent kinds read them: asking the others is an error, not ignored.
  for (const char* flag : {"--acceleration-features 0.03", "--direction-features 0.1", "--loss-balance 0.5"}) {
    const auto r = run("dynamics fit --model linear " + std::string(flag) + " --out " + model + " " +
                           (dir / "free.csv").string(),
                       true);
    EXPECT_NE(r.status, 0) << flag;
    EXPECT_NE(r.out.find("lstm or hybrid only"), std::string::npos) << r.out;
  }
  std::filesystem::remove_all(dir);
}

#if defined(RCM_CLI_TRAINS_NETWORKS)
// The CLI does not link LibTorch: it opens the training module to train a
// network (and for TorchScript), and a linear fit never opens it.
TEST(DynamicsCli, TrainsANetworkThroughTheTrainingModuleOnly) {
  const auto linked = run_shell(std::string("ldd ") + RCM_CLI_PATH);
  ASSERT_EQ(linked.status, 0);
  EXPECT_EQ(linked.out.find("libtorch"), std::string::npos) << linked.out;
  EXPECT_EQ(linked.out.find("libc10"), std::string::npos) << linked.out;

  const auto dir = rcm::test::get_process_temp_dir() / "rcm_test_dynamics_cli_module";
  std::filesystem::create_directories(dir);
  rcm::test::SyntheticArmOptions so;
  so.duration_s = 20;
  const auto free_csv = (dir / "free.csv").string();
  rcm::save_recording(free_csv, rcm::test::make_synthetic_free_space(so));
  const auto model = (dir / "lstm.json").string(), script = (dir / "lstm.pt").string(),
             imported = (dir / "imported.json").string();

  const auto fit = run("dynamics fit --model lstm --hidden 8 --max-epochs 2 --threads 1 --out " + model +
                       " --torchscript " + script + " --json " + free_csv);
  ASSERT_EQ(fit.status, 0) << fit.out;
  const auto summary = nlohmann::json::parse(fit.out);
  EXPECT_EQ(summary["kind"], "lstm");
  // LibTorch loaded late still binds its sgemm_ to OpenBLAS (the fit warns otherwise).
  for (const auto& w : summary["warnings"]) EXPECT_EQ(w.get<std::string>().find("BLAS"), std::string::npos) << w;
  const auto im = run("dynamics import " + script + " --out " + imported, true);
  ASSERT_EQ(im.status, 0) << im.out;
  const auto a = nlohmann::json::parse(run("dynamics eval " + model + " " + free_csv + " --json").out);
  const auto b = nlohmann::json::parse(run("dynamics eval " + imported + " " + free_csv + " --json").out);
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(a["joints"][k]["rmse"].get<double>(), b["joints"][k]["rmse"].get<double>(),
                1e-4 * a["joints"][k]["rmse"].get<double>());

  // Without the module: the network fit names it; the linear fit does not need it.
  const std::string missing = "RCM_TRAINING_MODULE=" + (dir / "missing.so").string();
  const auto refused = run("dynamics fit --model lstm --out " + model + " " + free_csv, true, missing);
  EXPECT_NE(refused.status, 0);
  EXPECT_NE(refused.out.find("training module"), std::string::npos) << refused.out;
  EXPECT_NE(refused.out.find("missing.so"), std::string::npos) << refused.out;
  const auto linear = run("dynamics fit --model linear --out " + (dir / "linear.json").string() + " " + free_csv,
                          true, missing);
  EXPECT_EQ(linear.status, 0) << linear.out;
  std::filesystem::remove_all(dir);
}
#endif
