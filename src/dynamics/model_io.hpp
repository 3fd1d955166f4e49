#pragma once
// Internal: encoding of weight arrays in model files. An array is
// {"shape": [rows, cols], "dtype": "f32"|"f64", "data": base64 of little-endian
// values in row-major order}; base64 keeps save -> load bit-exact.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

namespace rcm::dynamics::detail {

nlohmann::json encode_array(const Eigen::MatrixXf& m);
nlohmann::json encode_array(const Eigen::MatrixXd& m);
nlohmann::json encode_vector(const Eigen::VectorXf& v);
nlohmann::json encode_vector(const Eigen::VectorXd& v);

// `field` names the JSON path for messages; `source` the file.
Eigen::MatrixXf decode_array_f(const nlohmann::json& j, const std::string& source, const std::string& field);
Eigen::MatrixXd decode_array_d(const nlohmann::json& j, const std::string& source, const std::string& field);
Eigen::VectorXf decode_vector_f(const nlohmann::json& j, const std::string& source, const std::string& field,
                                Eigen::Index expected_size = -1);
Eigen::VectorXd decode_vector_d(const nlohmann::json& j, const std::string& source, const std::string& field,
                                Eigen::Index expected_size = -1);

// Throws InputError "source: field F: ..." 
[[noreturn]] void fail(const std::string& source, const std::string& field, const std::string& what);
const nlohmann::json& require(const nlohmann::json& j, const char* key, const std::string& source,
                              const std::string& field);

}  // namespace rcm::dynamics::detail

namespace rcm::dynamics {
struct TorqueModelInfo;
class TorqueModel;
namespace detail {
std::unique_ptr<TorqueModel> load_linear_parameters(TorqueModelInfo info, const nlohmann::json& p,
                                                    const std::string& source);
std::unique_ptr<TorqueModel> load_network_parameters(TorqueModelInfo info, int kind, const nlohmann::json& p,
                                                     const std::string& source);
}  // namespace detail
}  // namespace rcm::dynamics
