// The options structs' field tables (rcm/common/options.hpp): JSON -> struct ->
// JSON, located errors for an unknown key, a wrong type and a value out of
// range, the help of every field, the CLI flags and options file made from
// them, and the one rule for the free-space model's default kind.

#include <gtest/gtest.h>

#include <filesystem>
#include <set>
#include <string>

#include "rcm/common/command_line.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/options.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/sim/closed_loop.hpp"
#include "run_cli.hpp"
#include "temp_dir.hpp"
#include "test_dynamics_synthetic.hpp"

namespace {

using nlohmann::json;

// The InputError `f` throws; a failure when it throws none.
template <class F>
rcm::InputError expect_input_error(F&& f) {
  try {
    f();
  } catch (const rcm::InputError& e) {
    return e;
  }
  ADD_FAILURE() << "no InputError";
  return rcm::InputError(rcm::InputLocation{}, "none");
}

// Every table: its defaults pass its own checks, and JSON -> struct -> JSON
// gives the same JSON back.
template <class T>
class EveryOptionsTable : public ::testing::Test {};
using OptionsTypes =
    ::testing::Types<rcm::StudyOptions, rcm::JointEstimatorOptions, rcm::dynamics::FitOptions, rcm::TissueFitOptions,
                     rcm::TissuePairOptions, rcm::JacobianCheckOptions, rcm::ThreeStepOptions,
                     rcm::CoaxialProblemOptions, rcm::RestDetectionOptions, rcm::RecordingReadOptions,
                     rcm::OnlineEstimatorOptions, rcm::OnlineReplayOptions, rcm::CorrectionOptions,
                     rcm::sim::ClosedLoopOptions>;
TYPED_TEST_SUITE(EveryOptionsTable, OptionsTypes);

TYPED_TEST(EveryOptionsTable, DefaultsAreValidAndRoundTrip) {
  const TypeParam defaults;
  EXPECT_NO_THROW(rcm::check_options(defaults, "defaults"));
  const json j = rcm::options_to_json(defaults);
  EXPECT_EQ(rcm::options_to_json(rcm::options_from_json<TypeParam>(j, "defaults.json")), j);
  // One key per field, one help row per leaf field, each with its help.
  const auto& table = rcm::get_option_table<TypeParam>();
  EXPECT_EQ(j.size(), table.fields().size());
  for (const auto& f : table.fields()) {
    EXPECT_TRUE(j.contains(f.name)) << f.name;
    EXPECT_FALSE(f.help.empty()) << f.name;
  }
  for (const auto& d : rcm::describe_options<TypeParam>()) EXPECT_FALSE(d.help.empty()) << d.path;
}

// A JSON document that sets every kind of field to something other than its default.
json non_default_study_json() {
  return json::parse(R"({
    "method": "three-step",
    "model_kind": "mlp",
    "model_file": "models/free_space.json",
    "static_step": "last-hold",
    "tissue_sensitivity_delta_m": 0.002,
    "tissue_sensitivity_steps": 5,
    "verbose": false,
    "joint": {"seed": 9, "D_starts": [0.02, 0.04], "torque_sigma": [0.1, 0.2, 0.3], "bootstrap_replicates": 7},
    "fit": {"max_minutes": 2.5, "velocity_tanh_scales": [0.05], "loss_balance": 0.25, "rigid_body": false},
    "tissue": {"terms": ["x", "x^3"], "bins": 12},
    "tissue_pairs": {"jacobian": {"max_condition": 150.0}},
    "three_step": {"D_initial": 0.025, "coaxial": {"max_theta_rad": 1.0}},
    "read": {"assumed_rate_hz": 250.0, "joint_topic": "/PSM2/measured_js"}
  })");
}

TEST(OptionsTable, StudyJsonToStructToJson) {
  const json in = non_default_study_json();
  const rcm::StudyOptions o = rcm::options_from_json<rcm::StudyOptions>(in, "study.json");
  EXPECT_EQ(o.method, "three-step");
  ASSERT_TRUE(o.model_kind.has_value());
  EXPECT_EQ(*o.model_kind, rcm::dynamics::TorqueModelKind::mlp);
  ASSERT_TRUE(o.model_file.has_value());
  EXPECT_EQ(o.model_file->string(), "models/free_space.json");
  EXPECT_EQ(o.static_step, rcm::StaticStep::last_hold);
  EXPECT_EQ(o.tissue_sensitivity_steps, 5);
  EXPECT_FALSE(o.verbose);
  EXPECT_EQ(o.joint.seed, 9u);
  EXPECT_EQ(o.joint.D_starts, (std::vector<double>{0.02, 0.04}));
  EXPECT_EQ(o.joint.torque_sigma, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_DOUBLE_EQ(o.fit.max_minutes, 2.5);
  ASSERT_TRUE(o.fit.velocity_tanh_scales.has_value());
  EXPECT_EQ(*o.fit.velocity_tanh_scales, std::vector<double>{0.05});
  EXPECT_EQ(o.fit.loss_balance, 0.25);
  EXPECT_FALSE(o.fit.rigid_body);
  EXPECT_EQ(o.tissue.terms, (std::vector<rcm::TissueTermKind>{rcm::TissueTermKind::x, rcm::TissueTermKind::cube}));
  EXPECT_EQ(o.tissue.bins, 12u);
  EXPECT_DOUBLE_EQ(o.tissue_pairs.jacobian.max_condition, 150.0);
  EXPECT_EQ(o.three_step.D_initial, 0.025);
  EXPECT_DOUBLE_EQ(o.three_step.coaxial.max_theta_rad, 1.0);
  EXPECT_EQ(o.read.assumed_rate_hz, 250.0);
  EXPECT_EQ(o.read.joint_topic, "/PSM2/measured_js");
  // Back to JSON: every field given comes back as given, the others at their defaults.
  const json out = rcm::options_to_json(o);
  json expected = rcm::options_to_json(rcm::StudyOptions{});
  expected.merge_patch(in);
  EXPECT_EQ(out, expected);
  EXPECT_EQ(rcm::options_to_json(rcm::options_from_json<rcm::StudyOptions>(out, "again.json")), out);
  // null unsets an optional field.
  rcm::StudyOptions cleared = o;
  rcm::apply_options_json(cleared, json{{"model_kind", nullptr}, {"three_step", {{"D_initial", nullptr}}}}, "x");
  EXPECT_FALSE(cleared.model_kind.has_value());
  EXPECT_FALSE(cleared.three_step.D_initial.has_value());
}

// A flag's comma-separated numbers: every cell a whole finite number, or an
// error that names the flag and shows what was given.
TEST(CommandLine, NumberListsAreWholeNumbersOrALocatedError) {
  EXPECT_EQ(rcm::get_flag_name("max_tracking_error"), "--max-tracking-error");
  const rcm::InputLocation flag = rcm::InputLocation::plain("command line", "--max-tracking-error");
  EXPECT_EQ(rcm::parse_number_list("0.05,0.05,5e-3", flag), (std::vector<double>{0.05, 0.05, 0.005}));
  EXPECT_EQ(rcm::parse_number_list("-1", flag), (std::vector<double>{-1.0}));
  for (const char* bad : {"", "abc", "0.05,", ",0.05", "0.05,,1", "0.05x", "nan", "1,inf"}) {
    try {
      rcm::parse_number_list(bad, flag);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const rcm::InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("--max-tracking-error"), std::string::npos) << what;
      EXPECT_NE(what.find("'" + std::string(bad) + "'"), std::string::npos) << what;
    }
  }
}

TEST(OptionsTable, UnknownKeyIsLocated) {
  rcm::StudyOptions o;
  const auto e = expect_input_error(
      [&] { rcm::apply_options_json(o, json::parse(R"({"joint": {"huber": 2}})"), "study.json"); });
  EXPECT_EQ(e.where().file, "study.json");
  EXPECT_EQ(e.where().field, "joint.huber");
  EXPECT_NE(e.reason().find("unknown key"), std::string::npos) << e.what();
  EXPECT_NE(e.reason().find("huber_scale"), std::string::npos) << e.what();  // the known keys are listed
  const auto top = expect_input_error([&] { rcm::apply_options_json(o, json::parse(R"({"mehtod": "joint"})"), "s.json"); });
  EXPECT_EQ(top.where().field, "mehtod");
}

TEST(OptionsTable, WrongTypeIsLocated) {
  struct Case {
    const char* document;
    const char* field;
    const char* says;
  };
  for (const Case& c : {Case{R"({"fit": {"seed": "one"}})", "fit.seed", "expected an integer"},
                        Case{R"({"fit": {"seed": -1}})", "fit.seed", ">= 0"},
                        Case{R"({"verbose": 1})", "verbose", "expected true or false"},
                        Case{R"({"joint": {"torque_sigma": [0.1, "x", 0.3]}})", "joint.torque_sigma[1]",
                             "expected a number"},
                        Case{R"({"joint": {"torque_sigma": [0.1, 0.3]}})", "joint.torque_sigma", "3 numbers"},
                        Case{R"({"joint": {"D_starts": 0.01}})", "joint.D_starts", "expected an array"},
                        Case{R"({"model_kind": "svm"})", "model_kind", "lstm, mlp, linear, hybrid"},
                        Case{R"({"method": "both"})", "method", "joint, three-step"},
                        Case{R"({"tissue": {"terms": ["x", 3]}})", "tissue.terms[1]", "expected"},
                        Case{R"({"read": "dedupe"})", "read", "expected an object"}}) {
    rcm::StudyOptions o;
    const auto e = expect_input_error([&] { rcm::apply_options_json(o, json::parse(c.document), "study.json"); });
    EXPECT_EQ(e.where().file, "study.json") << c.document;
    EXPECT_EQ(e.where().field, c.field) << c.document << ": " << e.what();
    EXPECT_NE(e.reason().find(c.says), std::string::npos) << c.document << ": " << e.what();
  }
}

TEST(OptionsTable, ValuesOutOfRangeAreLocated) {
  rcm::StudyOptions o;
  o.joint.huber_scale = -1.0;
  auto e = expect_input_error([&] { rcm::check_options(o, "StudyOptions"); });
  EXPECT_EQ(e.where().field, "joint.huber_scale");
  EXPECT_NE(e.reason().find("> 0"), std::string::npos) << e.what();
  // A check across fields names its struct.
  o = rcm::StudyOptions{};
  o.joint.D_starts = {0.5};
  e = expect_input_error([&] { rcm::check_options(o, "StudyOptions"); });
  EXPECT_EQ(e.where().field, "joint");
  EXPECT_NE(e.reason().find("D start"), std::string::npos) << e.what();
  // Reading checks the range as it reads.
  e = expect_input_error(
      [&] { rcm::options_from_json<rcm::CorrectionOptions>(json{{"release_fraction", 1.5}}, "c.json"); });
  EXPECT_EQ(e.where().field, "release_fraction");
  EXPECT_NE(e.reason().find("in (0, 1]"), std::string::npos) << e.what();
}

TEST(OptionsTable, FlagSourcesNameTheFlag) {
  rcm::OnlineEstimatorOptions o;
  const auto e = expect_input_error(
      [&] { rcm::set_option(o, "alarm_force_n", -3.0, rcm::OptionSource{"command line", "--alarm-force"}); });
  EXPECT_EQ(e.where().field, "--alarm-force");
  EXPECT_EQ(std::string(e.what()).rfind("command line: --alarm-force: ", 0), 0u) << e.what();
}

// The kind fitted when none is named: one rule, linear, whether or not the
// program can train networks.
TEST(DefaultModelKind, LinearInEveryProgram) {
  EXPECT_EQ(rcm::dynamics::get_default_model_kind(), rcm::dynamics::TorqueModelKind::linear);
  EXPECT_FALSE(rcm::StudyOptions{}.model_kind.has_value());
  EXPECT_EQ(rcm::get_linear_torque_model_fitter().resolve_kind(std::nullopt), rcm::dynamics::TorqueModelKind::linear);
  EXPECT_EQ(rcm::get_linear_torque_model_fitter().resolve_kind(rcm::dynamics::TorqueModelKind::mlp),
            rcm::dynamics::TorqueModelKind::mlp);

  // The study fits the default kind when StudyOptions leaves it unset, with a
  // fitter that trains networks or not.
  rcm::test::TempDir dir("rcm_test_options_");
  rcm::test::SyntheticArmOptions arm;
  arm.duration_s = 20.0;
  const auto csv = dir.path() / "free.csv";
  rcm::save_recording(csv, rcm::test::make_synthetic_free_space(arm));
  rcm::Session session;
  session.manifest = dir.path() / "session.json";
  session.free_space = {csv};
  rcm::StudyOptions options;
  options.verbose = false;
  options.fit.verbose = false;
  for (const bool networks : {false, true}) {
    std::optional<rcm::dynamics::TorqueModelKind> asked;
    const rcm::TorqueModelFitter fitter(
        [&asked](rcm::dynamics::TorqueModelKind kind, const std::vector<rcm::Recording>& recordings,
                 const rcm::dynamics::FitOptions& fit) {
          asked = kind;
          return rcm::dynamics::fit_linear_torque_model(recordings, fit);
        },
        networks);
    rcm::fit_free_space_step(session, options, fitter);
    ASSERT_TRUE(asked.has_value());
    EXPECT_EQ(*asked, rcm::dynamics::TorqueModelKind::linear);
  }
}

// `rcm run --help` and `rcm monitor --help` list every field of StudyOptions
// (their --options file), with its help.
TEST(OptionsCli, HelpListsEveryFieldOfTheStudyOptions) {
  for (const char* command : {"run", "monitor"}) {
    std::string out;
    ASSERT_EQ(rcm::test::run_cli(std::string(command) + " --help", out), 0) << out;
    for (const auto& d : rcm::describe_options<rcm::StudyOptions>()) {
      EXPECT_NE(out.find("  " + d.path + " "), std::string::npos) << command << ": " << d.path;
      EXPECT_NE(out.find(d.help), std::string::npos) << command << ": " << d.help;
    }
  }
}

// A flag's help, range and default come from its field.
TEST(OptionsCli, FlagsTakeTheirHelpAndChecksFromTheTable) {
  std::string out;
  ASSERT_EQ(rcm::test::run_cli("monitor --help", out), 0);
  const auto tolerance = rcm::describe_option<rcm::CorrectionOptions>("tolerance_m");
  EXPECT_NE(out.find(tolerance.help), std::string::npos) << out;
  EXPECT_NE(out.find("default " + tolerance.value), std::string::npos) << out;
  // Out of range: exit 2, the flag named.
  EXPECT_EQ(rcm::test::run_cli("monitor --session x.json rec.csv --tolerance -0.01", out), 2);
  EXPECT_NE(out.find("--tolerance"), std::string::npos) << out;
  EXPECT_EQ(rcm::test::run_cli("run x.json --max-train-minutes 0", out), 2);
  EXPECT_NE(out.find("--max-train-minutes"), std::string::npos) << out;
  // A flag no command has, or a missing required one: bad input too.
  EXPECT_EQ(rcm::test::run_cli("monitor --session x.json rec.csv --trial rec.csv", out), 2);
  EXPECT_NE(out.find("--trial"), std::string::npos) << out;
  EXPECT_EQ(rcm::test::run_cli("monitor rec.csv", out), 2);
  EXPECT_NE(out.find("--session"), std::string::npos) << out;
}

TEST(OptionsCli, OptionsFileErrorsNameTheFileAndTheField) {
  rcm::test::TempDir dir("rcm_test_options_");
  const auto file = dir.write("study.json", R"({"joint": {"bootstrap_replicates": "many"}})");
  std::string out;
  EXPECT_EQ(rcm::test::run_cli("run x.json --options " + file.string(), out), 2);
  EXPECT_NE(out.find(file.string() + ": field joint.bootstrap_replicates: expected an integer"), std::string::npos)
      << out;
  const auto unknown = dir.write("unknown.json", R"({"three_step": {"D_start": 0.02}})");
  EXPECT_EQ(rcm::test::run_cli("run x.json --options " + unknown.string(), out), 2);
  EXPECT_NE(out.find(unknown.string() + ": field three_step.D_start: unknown key"), std::string::npos) << out;
}

}  // namespace
