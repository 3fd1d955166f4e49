#include "cli_util.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <iostream>

#include "rcm/common/error.hpp"

namespace rcm::cli {

std::vector<double> parse_number_list(const std::string& text, const std::string& flag) {
  std::vector<double> out;
  std::size_t start = 0;
  InputLocation where;
  where.file = "command line";
  where.field = flag;
  where.kind = InputLocation::Kind::plain;
  while (true) {
    const std::size_t end = std::min(text.find(',', start), text.size());
    std::string item = text.substr(start, end - start);
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    const char* first = item.data() + (item.size() > 0 && item[0] == '+' ? 1 : 0);
    double v = 0.0;
    const auto [ptr, ec] = std::from_chars(first, item.data() + item.size(), v);
    if (item.empty() || ec != std::errc() || ptr != item.data() + item.size() || !std::isfinite(v))
      throw InputError(where, "expected comma-separated finite numbers, got " + quote_token(item));
    out.push_back(v);
    if (end == text.size()) break;
    start = end + 1;
  }
  return out;
}

Eigen::Vector3d parse_vector3(const std::string& text, const std::string& flag) {
  const std::vector<double> v = parse_number_list(text, flag);
  if (v.size() != 3) {
    InputLocation where;
    where.file = "command line";
    where.field = flag;
    where.kind = InputLocation::Kind::plain;
    throw InputError(where, "expected 3 comma-separated numbers, got " + std::to_string(v.size()));
  }
  return {v[0], v[1], v[2]};
}

InputLocation flag_location(const std::string& flag) {
  InputLocation where;
  where.file = "command line";
  where.field = flag;
  where.kind = InputLocation::Kind::plain;
  return where;
}

void print_json(const nlohmann::json& value) { std::cout << value.dump(2) << std::endl; }

std::string format_table(const std::vector<std::string>& header,
                         const std::vector<std::vector<std::string>>& rows) {
  std::vector<std::size_t> width(header.size(), 0);
  for (std::size_t c = 0; c < header.size(); ++c) width[c] = header[c].size();
  for (const auto& row : rows)
    for (std::size_t c = 0; c < row.size() && c < width.size(); ++c) width[c] = std::max(width[c], row[c].size());
  auto line = [&](const std::vector<std::string>& cells) {
    std::string out;
    for (std::size_t c = 0; c < width.size(); ++c) {
      const std::string cell = c < cells.size() ? cells[c] : "";
      if (c > 0) out += "  ";
      out += (c == 0) ? cell + std::string(width[c] - cell.size(), ' ')
                      : std::string(width[c] - cell.size(), ' ') + cell;
    }
    while (!out.empty() && out.back() == ' ') out.pop_back();
    return out + "\n";
  };
  std::string out = line(header);
  std::size_t total = 0;
  for (std::size_t w : width) total += w;
  out += std::string(total + 2 * (width.empty() ? 0 : width.size() - 1), '-') + "\n";
  for (const auto& row : rows) out += line(row);
  return out;
}

nlohmann::json to_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

nlohmann::json to_json_rows(const Eigen::Matrix3d& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) rows.push_back({m(i, 0), m(i, 1), m(i, 2)});
  return rows;
}

}  // namespace rcm::cli
