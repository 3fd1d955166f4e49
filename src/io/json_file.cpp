#include "rcm/io/json_file.hpp"

#include <cstdio>
#include <fstream>
#include <sstream>
#include <system_error>

#include "rcm/common/error.hpp"

namespace rcm {

nlohmann::json load_json_file(const std::filesystem::path& path) {
  const std::string text = read_text_file(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    // nlohmann reports a byte offset; users need line and column.
    InputLocation where;
    where.file = path.string();
    const std::size_t byte = std::min<std::size_t>(e.byte == 0 ? 0 : e.byte - 1, text.size());
    std::size_t line = 1, col = 1;
    for (std::size_t i = 0; i < byte; ++i) {
      if (text[i] == '\n') {
        ++line;
        col = 1;
      } else {
        ++col;
      }
    }
    where.line = line;
    where.column = col;
    std::string msg = e.what();
    // Drop nlohmann's "[json.exception.parse_error.101] parse error at line 1, column 2: " prefix.
    const auto pos = msg.find(": ");
    if (pos != std::string::npos) msg = msg.substr(pos + 2);
    if (msg.size() > 160) msg = msg.substr(0, 160) + "...";
    throw InputError(where, "invalid JSON: " + msg);
  } catch (const nlohmann::json::exception& e) {
    // e.g. out_of_range.406 for a number such as 1e999
    InputLocation where;
    where.file = path.string();
    std::string msg = e.what();
    const auto pos = msg.find("] ");
    if (pos != std::string::npos) msg = msg.substr(pos + 2);
    if (msg.size() > 160) msg = msg.substr(0, 160) + "...";
    throw InputError(where, "invalid JSON: " + msg);
  }
}

void save_json_file(const std::filesystem::path& path, const nlohmann::json& value) {
  write_file_atomic(path, value.dump(2) + "\n");
}

}  // namespace rcm
