#include "rcm/common/text_file.hpp"

#include <fstream>
#include <sstream>
#include <system_error>

#include "rcm/common/error.hpp"

namespace rcm {

std::string read_text_file(const std::filesystem::path& path) {
  InputLocation where;
  where.file = path.string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(where, "file not found");
  if (std::filesystem::is_directory(path, ec)) throw InputError(where, "is a directory, expected a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(where, "cannot be opened for reading");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

}  // namespace rcm
