#include "rcm/common/text_file.hpp"

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <system_error>
#include <vector>

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

namespace {

constexpr std::uint64_t kFnvPrime = 1099511628211ULL;

void add_bytes(std::uint64_t& h, const char* data, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(data[i]);
    h *= kFnvPrime;
  }
}

void add_file(std::uint64_t& h, const std::filesystem::path& path) {
  InputLocation where;
  where.file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(where, "cannot be opened for reading");
  std::vector<char> buffer(std::size_t{1} << 16);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    add_bytes(h, buffer.data(), static_cast<std::size_t>(in.gcount()));
  }
  if (in.bad()) throw InputError(where, "read failed");
}

}  // namespace

std::string get_file_digest(const std::filesystem::path& path) {
  InputLocation where;
  where.file = path.string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(where, "file not found");
  std::uint64_t h = 14695981039346656037ULL;
  if (std::filesystem::is_directory(path, ec)) {
    std::vector<std::filesystem::path> files;
    try {
      for (const auto& entry : std::filesystem::recursive_directory_iterator(path))
        if (entry.is_regular_file()) files.push_back(entry.path());
    } catch (const std::filesystem::filesystem_error& e) {
      throw InputError(where, std::string("cannot be listed: ") + e.code().message());
    }
    std::sort(files.begin(), files.end());
    for (const auto& file : files) {
      const std::string name = std::filesystem::relative(file, path).generic_string();
      add_bytes(h, name.c_str(), name.size() + 1);  // with its NUL: names cannot run into bytes
      add_file(h, file);
    }
  } else {
    add_file(h, path);
  }
  char text[32];
  std::snprintf(text, sizeof text, "fnv1a64:%016" PRIx64, h);
  return text;
}

}  // namespace rcm
