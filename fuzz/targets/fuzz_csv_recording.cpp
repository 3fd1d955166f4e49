// The contract's recording CSV (time, position_i, velocity_i, effort_i,
// force_x..z), read by parse_recording as load_recording reads a .csv file.
#include "csv_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  rcm::fuzz::fuzz_csv(data, size, "fuzz.csv", false);
  return 0;
}
