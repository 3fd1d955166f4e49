// What `rostopic echo -p /PSM1/measured_js` writes (%time in ns,
// field.position0.., field.header.*, quoted joint names), read by
// parse_recording.
#include "csv_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  rcm::fuzz::fuzz_csv(data, size, "fuzz_rostopic.csv", true);
  return 0;
}
