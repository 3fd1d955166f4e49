#pragma once
// Small helpers shared by the subcommands: parsing of vector flags, JSON and
// table output.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"

namespace rcm::cli {

// "0.3,-0.2,0.12" -> vector; throws InputError naming the flag on any defect.
std::vector<double> parse_number_list(const std::string& text, const std::string& flag);
Eigen::Vector3d parse_vector3(const std::string& text, const std::string& flag);

// The location of a command-line flag, for messages: "command line: --q: ...".
InputLocation flag_location(const std::string& flag);

// One JSON object on stdout, then a newline.
void print_json(const nlohmann::json& value);

// A plain text table: header row, a rule, rows; columns right-aligned.
std::string format_table(const std::vector<std::string>& header,
                         const std::vector<std::vector<std::string>>& rows);

// Thrown by a command whose work succeeded with an outcome scripts branch on
// (`rcm setup`: not ready), after its output is written; main returns `code`.
struct ExitStatus {
  int code = 1;
};

nlohmann::json to_json(const Eigen::Vector3d& v);
nlohmann::json to_json_rows(const Eigen::Matrix3d& m);

}  // namespace rcm::cli
