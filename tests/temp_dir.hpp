#pragma once
// A fresh directory under the system's temporary directory for one test,
// removed with everything in it when the object goes away.

#include <filesystem>
#include <fstream>
#include <random>
#include <string>

namespace rcm::test {

class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "rcm_test_") {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() / (prefix + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  // Writes `text` to `name` in the directory (binary, as given).
  std::filesystem::path write(const std::string& name, const std::string& text) const {
    const std::filesystem::path p = path_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p;
  }

 private:
  std::filesystem::path path_;
};

// A directory of this test process's own, removed when the process exits:
// tests of two checkouts, or two ctest runs, on one machine never write the
// same file.
inline const std::filesystem::path& get_process_temp_dir() {
  static const TempDir dir("rcm_test_process_");
  return dir.path();
}

}  // namespace rcm::test
