// The tissue model rcm setup saves (rcm/estimation/joint_tissue_file.hpp): every
// field read back as written, a file of another calibration, model, D* or q0
// refused with the field named, a malformed field located, and the monitor
// built on it the same as the monitor that identifies it again. File digests
// (rcm/common/text_file.hpp) change with any byte and any name.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/common/text_file.hpp"
#include "rcm/estimation/joint_tissue_file.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/session.hpp"
#include "run_cli.hpp"
#include "temp_dir.hpp"

namespace {

const std::filesystem::path kSession = std::filesystem::path(RCM_LIVE_TEST_DIR) / "session" / "session.json";

// The message of the InputError `f` throws ("" when it throws none).
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const rcm::InputError& e) {
    return e.what();
  }
  return "";
}

rcm::JointTissueModel make_model() {
  rcm::JointTissueModel m;
  m.parameters = Eigen::Vector4d(871.5, 2.5e5, 1.25, 0.375);
  m.family = "stiffening";
  m.axial_velocity_scale = 0.0025;
  m.cost = 123.456;
  m.bic = -9876.5;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m.covariance(r, c) = 0.1 * (r + 1) + 0.01 * (c + 1) + 1.0 / 3.0;
  m.bootstrap_replicates = 30;
  m.bootstrap_block_s = 1.5;
  m.torque_offset = Eigen::Vector3d(0.011, -0.022, 0.3);
  m.torque_offset_covariance = Eigen::Matrix3d::Identity() * 1e-4 + Eigen::Matrix3d::Constant(1.0 / 7.0e5);
  m.calibration_bias_m = Eigen::Vector3d(1e-4, 2e-4, 3e-4);
  m.calibration_check = "held-out halves";
  m.calibration_offset_m = 0.03;
  m.dparameters_dD_star = Eigen::Vector4d(-29000.0, 1.0, 2.0, 3.0);
  m.dtorque_offset_dD_star = Eigen::Vector3d(0.5, -0.25, 0.125);
  m.calibration_offset_sd_m = 1e-4;
  return m;
}

rcm::TissueModelOrigin make_origin() {
  rcm::TissueModelOrigin o;
  o.calibration_digest = "fnv1a64:0123456789abcdef";
  o.free_space_model_digest = "fnv1a64:fedcba9876543210";
  o.calibration_offset_m = 0.03;
  o.q0 = Eigen::Vector3d(0.1, -0.2, 0.12);
  return o;
}

TEST(FileDigest, ChangesWithAnyByteAndAnyName) {
  rcm::test::TempDir dir;
  const auto a = dir.write("a.csv", "time,q1\n0,1\n");
  const auto b = dir.write("b.csv", "time,q1\n0,1\n");
  const auto c = dir.write("c.csv", "time,q1\n0,2\n");
  EXPECT_EQ(rcm::get_file_digest(a), rcm::get_file_digest(b));
  EXPECT_NE(rcm::get_file_digest(a), rcm::get_file_digest(c));
  EXPECT_EQ(rcm::get_file_digest(a).rfind("fnv1a64:", 0), 0u);
  // A folder (a rosbag2 recording): its files' names count as their bytes do.
  std::filesystem::create_directories(dir.path() / "bag1");
  std::filesystem::create_directories(dir.path() / "bag2");
  std::filesystem::copy_file(a, dir.path() / "bag1" / "x.db3");
  std::filesystem::copy_file(a, dir.path() / "bag2" / "y.db3");
  EXPECT_NE(rcm::get_file_digest(dir.path() / "bag1"), rcm::get_file_digest(dir.path() / "bag2"));
  std::filesystem::rename(dir.path() / "bag2" / "y.db3", dir.path() / "bag2" / "x.db3");
  EXPECT_EQ(rcm::get_file_digest(dir.path() / "bag1"), rcm::get_file_digest(dir.path() / "bag2"));
  const std::string e = error_of([&] { rcm::get_file_digest(dir.path() / "absent.csv"); });
  EXPECT_NE(e.find("absent.csv"), std::string::npos) << e;
  EXPECT_NE(e.find("not found"), std::string::npos) << e;
}

TEST(TissueModelFile, ReadsBackEveryFieldAsWritten) {
  rcm::test::TempDir dir;
  const rcm::JointTissueModel m = make_model();
  rcm::save_joint_tissue_model(dir.path() / "tissue_model.json", m, make_origin());
  const rcm::JointTissueModel r = rcm::load_joint_tissue_model(dir.path() / "tissue_model.json", make_origin());
  EXPECT_EQ(r.parameters, m.parameters);
  EXPECT_EQ(r.family, m.family);
  EXPECT_EQ(r.axial_velocity_scale, m.axial_velocity_scale);
  EXPECT_EQ(r.cost, m.cost);
  EXPECT_EQ(r.bic, m.bic);
  EXPECT_EQ(r.covariance, m.covariance);
  EXPECT_EQ(r.bootstrap_replicates, m.bootstrap_replicates);
  EXPECT_EQ(r.bootstrap_block_s, m.bootstrap_block_s);
  EXPECT_EQ(r.torque_offset, m.torque_offset);
  EXPECT_EQ(r.torque_offset_covariance, m.torque_offset_covariance);
  EXPECT_EQ(r.calibration_bias_m, m.calibration_bias_m);
  EXPECT_EQ(r.calibration_check, m.calibration_check);
  EXPECT_EQ(r.calibration_offset_m, m.calibration_offset_m);
  EXPECT_EQ(r.dparameters_dD_star, m.dparameters_dD_star);
  EXPECT_EQ(r.dtorque_offset_dD_star, m.dtorque_offset_dD_star);
  EXPECT_EQ(r.calibration_offset_sd_m, m.calibration_offset_sd_m);
}

TEST(TissueModelFile, RefusesAModelOfAnotherCalibrationModelOrPose) {
  rcm::test::TempDir dir;
  const auto path = dir.path() / "tissue_model.json";
  rcm::save_joint_tissue_model(path, make_model(), make_origin());
  auto refused_at = [&](const std::string& field, auto change) {
    rcm::TissueModelOrigin now = make_origin();
    change(now);
    const std::string e = error_of([&] { rcm::load_joint_tissue_model(path, now); });
    EXPECT_NE(e.find("tissue_model.json"), std::string::npos) << e;
    EXPECT_NE(e.find(field), std::string::npos) << e;
  };
  refused_at("made_from.calibration_digest", [](auto& o) { o.calibration_digest = "fnv1a64:0000000000000000"; });
  refused_at("made_from.free_space_model_digest", [](auto& o) { o.free_space_model_digest.back() = '1'; });
  refused_at("made_from.calibration_offset_m", [](auto& o) { o.calibration_offset_m = 0.031; });
  refused_at("made_from.q0", [](auto& o) { o.q0[2] += 1e-3; });
}

TEST(TissueModelFile, MalformedFieldsAreLocated) {
  rcm::test::TempDir dir;
  const auto path = dir.path() / "tissue_model.json";
  rcm::save_joint_tissue_model(path, make_model(), make_origin());
  const nlohmann::json good = rcm::load_json_file(path);
  auto error_with = [&](auto change) {
    nlohmann::json j = good;
    change(j);
    rcm::save_json_file(path, j);
    return error_of([&] { rcm::load_joint_tissue_model(path, make_origin()); });
  };
  std::string e = error_with([](nlohmann::json& j) { j.erase("covariance"); });
  EXPECT_NE(e.find("field covariance: missing"), std::string::npos) << e;
  e = error_with([](nlohmann::json& j) { j["parameters"] = {1.0, 2.0, 3.0}; });
  EXPECT_NE(e.find("field parameters: expected 4 numbers"), std::string::npos) << e;
  e = error_with([](nlohmann::json& j) { j["torque_offset_covariance"][1][2] = "x"; });
  EXPECT_NE(e.find("field torque_offset_covariance[1][2]: expected a number"), std::string::npos) << e;
  e = error_with([](nlohmann::json& j) { j["family"] = "quadratic"; });
  EXPECT_NE(e.find("field family"), std::string::npos) << e;
  e = error_with([](nlohmann::json& j) { j["format"] = "rcm-tissue-model/2"; });
  EXPECT_NE(e.find("field format"), std::string::npos) << e;
  e = error_with([](nlohmann::json& j) { j["bootstrap_replicates"] = 2.5; });
  EXPECT_NE(e.find("field bootstrap_replicates"), std::string::npos) << e;
}

// rcm setup writes tissue_model.json; the monitor built on it has the tissue
// model the monitor identifies itself, field for field.
TEST(TissueModelFile, TheMonitorOnWhatSetupSavedIsTheMonitorThatIdentifiesIt) {
  rcm::test::TempDir dir;
  const std::string options =
      dir.write("o.json", R"({"joint": {"calibration_bootstrap_replicates": 3}})").string();
  std::string out;
  ASSERT_EQ(rcm::test::run_cli("setup " + kSession.string() + " --out " + dir.path().string() + " --options " + options,
                               out),
            0)
      << out;
  ASSERT_TRUE(std::filesystem::exists(dir.path() / "tissue_model.json")) << out;
  EXPECT_NE(out.find("--tissue-model-file"), std::string::npos) << out;

  const rcm::Session session = rcm::load_session(kSession);
  rcm::StudyOptions o;
  o.verbose = false;
  o.joint.calibration_bootstrap_replicates = 3;
  o.model_file = dir.path() / "free_space_model.json";
  const rcm::TorqueModelFitter none = rcm::get_linear_torque_model_fitter({});
  const rcm::MonitorSetup identified = rcm::prepare_monitor(session, o, none);
  o.tissue_model_file = dir.path() / "tissue_model.json";
  const rcm::MonitorSetup loaded = rcm::prepare_monitor(session, o, none);
  EXPECT_EQ(loaded.tissue.parameters, identified.tissue.parameters);
  EXPECT_EQ(loaded.tissue.family, identified.tissue.family);
  EXPECT_EQ(loaded.tissue.torque_offset, identified.tissue.torque_offset);
  EXPECT_EQ(loaded.tissue.covariance, identified.tissue.covariance);
  EXPECT_EQ(loaded.tissue.torque_offset_covariance, identified.tissue.torque_offset_covariance);
  EXPECT_EQ(loaded.tissue.calibration_bias_m, identified.tissue.calibration_bias_m);
  EXPECT_EQ(loaded.tissue.dparameters_dD_star, identified.tissue.dparameters_dD_star);
  EXPECT_EQ(loaded.joint_options.torque_sigma, identified.joint_options.torque_sigma);

  // Another free-space model (the same numbers, another file) is refused.
  std::filesystem::copy_file(dir.path() / "free_space_model.json", dir.path() / "other.json");
  std::ofstream(dir.path() / "other.json", std::ios::app) << "\n";
  o.model_file = dir.path() / "other.json";
  std::string e = error_of([&] { rcm::prepare_monitor(session, o, none); });
  EXPECT_NE(e.find("made_from.free_space_model_digest"), std::string::npos) << e;
  // Without a saved free-space model there is nothing to check it against.
  o.model_file.reset();
  e = error_of([&] { rcm::prepare_monitor(session, o, none); });
  EXPECT_NE(e.find("tissue_model_file"), std::string::npos) << e;
  EXPECT_NE(e.find("model_file"), std::string::npos) << e;
}

}  // namespace
