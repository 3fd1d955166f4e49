#include "rcm/estimation/joint_tissue_file.hpp"

#include <cmath>
#include <nlohmann/json.hpp>

#include "rcm/common/error.hpp"
#include "rcm/common/text_file.hpp"
#include "rcm/io/json_file.hpp"

namespace rcm {
namespace {

constexpr const char* kFormat = "rcm-tissue-model/1";

// Reads one file's fields, every error naming the file and the field.
class FieldReader {
 public:
  FieldReader(const std::filesystem::path& path, const nlohmann::json& root) : path_(path.string()), root_(root) {}

  [[noreturn]] void fail(const std::string& field, const std::string& what) const {
    InputLocation where;
    where.file = path_;
    where.field = field;
    where.kind = InputLocation::Kind::json_field;
    throw InputError(where, what);
  }

  const nlohmann::json& get(const std::string& field) const {
    const nlohmann::json* j = &root_;
    std::size_t start = 0;
    while (true) {
      const std::size_t dot = field.find('.', start);
      const std::string key = field.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
      if (!j->is_object() || !j->contains(key)) fail(field, "missing");
      j = &j->at(key);
      if (dot == std::string::npos) return *j;
      start = dot + 1;
    }
  }

  double get_number(const std::string& field) const {
    const nlohmann::json& j = get(field);
    if (!j.is_number()) fail(field, "expected a number");
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail(field, "not finite");
    return v;
  }

  std::string get_string(const std::string& field) const {
    const nlohmann::json& j = get(field);
    if (!j.is_string()) fail(field, "expected a string");
    return j.get<std::string>();
  }

  // A vector of n numbers, or a matrix of rows x cols as rows of numbers.
  Eigen::MatrixXd get_matrix(const std::string& field, int rows, int cols) const {
    const nlohmann::json& j = get(field);
    Eigen::MatrixXd m(rows, cols);
    const bool vector = cols == 1;
    if (!j.is_array() || static_cast<int>(j.size()) != rows)
      fail(field, vector ? "expected " + std::to_string(rows) + " numbers"
                         : "expected " + std::to_string(rows) + " rows of " + std::to_string(cols) + " numbers");
    for (int r = 0; r < rows; ++r) {
      const nlohmann::json& row = j[static_cast<std::size_t>(r)];
      if (!vector && (!row.is_array() || static_cast<int>(row.size()) != cols))
        fail(field + "[" + std::to_string(r) + "]", "expected " + std::to_string(cols) + " numbers");
      for (int c = 0; c < cols; ++c) {
        const nlohmann::json& v = vector ? row : row[static_cast<std::size_t>(c)];
        const std::string at = field + "[" + std::to_string(r) + "]" + (vector ? "" : "[" + std::to_string(c) + "]");
        if (!v.is_number()) fail(at, "expected a number");
        m(r, c) = v.get<double>();
        if (!std::isfinite(m(r, c))) fail(at, "not finite");
      }
    }
    return m;
  }

 private:
  std::string path_;
  const nlohmann::json& root_;
};

nlohmann::json to_json(const Eigen::MatrixXd& m) {
  if (m.cols() == 1) return std::vector<double>(m.data(), m.data() + m.rows());
  nlohmann::json rows = nlohmann::json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index c = 0; c < m.cols(); ++c) row.push_back(m(r, c));
    rows.push_back(row);
  }
  return rows;
}

}  // namespace

TissueModelOrigin get_tissue_model_origin(const Session& session, const std::filesystem::path& free_space_model_file) {
  if (!session.calibration) {
    InputLocation where;
    where.file = session.manifest.string();
    where.field = "calibration";
    where.kind = InputLocation::Kind::json_field;
    throw InputError(where, "missing: a tissue model is identified on a calibration at a known coaxial offset");
  }
  TissueModelOrigin origin;
  origin.calibration_digest = get_file_digest(session.calibration->recording);
  origin.free_space_model_digest = get_file_digest(free_space_model_file);
  origin.calibration_offset_m = session.calibration->coaxial_offset_m;
  origin.q0 = session.q0;
  return origin;
}

void save_joint_tissue_model(const std::filesystem::path& path, const JointTissueModel& m,
                             const TissueModelOrigin& origin) {
  const nlohmann::json j = {
      {"format", kFormat},
      {"made_from",
       {{"calibration_digest", origin.calibration_digest},
        {"free_space_model_digest", origin.free_space_model_digest},
        {"calibration_offset_m", origin.calibration_offset_m},
        {"q0", to_json(origin.q0)}}},
      {"family", m.family},
      {"parameters", to_json(m.parameters)},
      {"axial_velocity_scale", m.axial_velocity_scale},
      {"cost", m.cost},
      {"bic", m.bic},
      {"covariance", to_json(m.covariance)},
      {"bootstrap_replicates", m.bootstrap_replicates},
      {"bootstrap_block_s", m.bootstrap_block_s},
      {"torque_offset", to_json(m.torque_offset)},
      {"torque_offset_covariance", to_json(m.torque_offset_covariance)},
      {"calibration_bias_m", to_json(m.calibration_bias_m)},
      {"calibration_check", m.calibration_check},
      {"calibration_offset_m", m.calibration_offset_m},
      {"dparameters_dD_star", to_json(m.dparameters_dD_star)},
      {"dtorque_offset_dD_star", to_json(m.dtorque_offset_dD_star)},
      {"calibration_offset_sd_m", m.calibration_offset_sd_m}};
  save_json_file(path, j);
}

JointTissueModel load_joint_tissue_model(const std::filesystem::path& path, const TissueModelOrigin& expected) {
  const nlohmann::json root = load_json_file(path);
  const FieldReader in(path, root);
  if (in.get_string("format") != kFormat)
    in.fail("format", std::string("expected ") + kFormat + ", got '" + in.get_string("format") + "'");
  // What it was made from first: a model of another calibration is refused
  // before anything of it is read.
  const auto same = [&](const std::string& field, const std::string& file_value, const std::string& now,
                        const char* remedy) {
    if (file_value != now)
      in.fail(field, "made from another " + std::string(remedy) + " (" + file_value + ", now " + now +
                         "): run rcm setup again, or identify the tissue model on the calibration");
  };
  same("made_from.calibration_digest", in.get_string("made_from.calibration_digest"), expected.calibration_digest,
       "calibration recording");
  same("made_from.free_space_model_digest", in.get_string("made_from.free_space_model_digest"),
       expected.free_space_model_digest, "free-space model");
  const double D_star = in.get_number("made_from.calibration_offset_m");
  if (std::abs(D_star - expected.calibration_offset_m) > 1e-9)
    in.fail("made_from.calibration_offset_m", "made at D* = " + std::to_string(D_star) + " m, the session's is " +
                                                 std::to_string(expected.calibration_offset_m) + " m");
  if ((in.get_matrix("made_from.q0", 3, 1) - expected.q0).cwiseAbs().maxCoeff() > 1e-9)
    in.fail("made_from.q0", "made at another q0 than the session's: run rcm setup again");

  JointTissueModel m;
  m.family = in.get_string("family");
  if (m.family != "linear" && m.family != "stiffening")
    in.fail("family", "expected linear or stiffening, got '" + m.family + "'");
  m.parameters = in.get_matrix("parameters", 4, 1);
  m.axial_velocity_scale = in.get_number("axial_velocity_scale");
  if (!(m.axial_velocity_scale > 0)) in.fail("axial_velocity_scale", "must be > 0");
  m.cost = in.get_number("cost");
  m.bic = in.get_number("bic");
  m.covariance = in.get_matrix("covariance", 4, 4);
  const double replicates = in.get_number("bootstrap_replicates");
  if (!(replicates >= 0) || replicates != std::floor(replicates))
    in.fail("bootstrap_replicates", "expected a whole number >= 0");
  m.bootstrap_replicates = static_cast<int>(replicates);
  m.bootstrap_block_s = in.get_number("bootstrap_block_s");
  m.torque_offset = in.get_matrix("torque_offset", 3, 1);
  m.torque_offset_covariance = in.get_matrix("torque_offset_covariance", 3, 3);
  m.calibration_bias_m = in.get_matrix("calibration_bias_m", 3, 1);
  m.calibration_check = in.get_string("calibration_check");
  m.calibration_offset_m = in.get_number("calibration_offset_m");
  m.dparameters_dD_star = in.get_matrix("dparameters_dD_star", 4, 1);
  m.dtorque_offset_dD_star = in.get_matrix("dtorque_offset_dD_star", 3, 1);
  m.calibration_offset_sd_m = in.get_number("calibration_offset_sd_m");
  if (!(m.calibration_offset_sd_m >= 0)) in.fail("calibration_offset_sd_m", "must be >= 0");
  return m;
}

}  // namespace rcm
