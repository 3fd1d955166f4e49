// A rosbag2 bag directory's metadata.yaml. The directory also holds the
// storage files of a split bag (bag_0 and bag_1, .mcap and .db3, from
// fuzz/data/bag) so that inputs naming them reach the storage readers; the
// input is only the YAML.
#include <fstream>
#include <iterator>

#include "rosbag2_checks.hpp"

#ifndef RCM_FUZZ_DIR
#error "RCM_FUZZ_DIR must name the fuzz/ source directory"
#endif

namespace {

const std::filesystem::path& bag_dir() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = rcm::fuzz::scratch_dir() / "bag";
    std::filesystem::create_directories(d);
    const std::filesystem::path storage = std::filesystem::path(RCM_FUZZ_DIR) / "data" / "bag";
    for (const char* f : {"bag_0.mcap", "bag_1.mcap", "bag_0.db3", "bag_1.db3"})
      std::filesystem::copy_file(storage / f, d / f);
    return d;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path& dir = bag_dir();
  std::ofstream(dir / "metadata.yaml", std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  rcm::fuzz::fuzz_rosbag2_path(dir, size % 2 == 1);
  return 0;
}
