// rosbag2 SQLite files (.db3, every schema rosbag2 has written), read as a
// bare .db3 recording and listed as `rcm inspect` lists it.
#include "rosbag2_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  rcm::fuzz::fuzz_rosbag2_path(rcm::fuzz::write_input("fuzz.db3", data, size), size % 2 == 1);
  return 0;
}
