// MCAP files (rosbag2's default storage since Iron), read as a bare .mcap
// recording and listed as `rcm inspect` lists it.
#include "rosbag2_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  rcm::fuzz::fuzz_rosbag2_path(rcm::fuzz::write_input("fuzz.mcap", data, size), size % 2 == 1);
  return 0;
}
