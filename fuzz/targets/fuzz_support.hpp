#pragma once
// What the fuzz targets share: the entry point they define, a scratch
// directory for readers that take a path, and the contract every reader is
// held to: for any bytes it returns or throws its documented input error.
// Anything else escaping (std::out_of_range, a JSON or YAML exception,
// std::bad_alloc) reaches std::terminate, which libFuzzer and the replay
// program both report as a crash naming the exception.

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <string>

#include "rcm/common/error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace rcm::fuzz {

// A directory of this process (under /dev/shm when it exists, so that the
// readers' file I/O costs no disk), removed when the process exits normally.
const std::filesystem::path& scratch_dir();

// Writes `size` bytes to scratch_dir()/name, replacing what the file held, and
// returns its path. The same name is reused by every input.
std::filesystem::path write_input(const std::string& name, const std::uint8_t* data, std::size_t size);
std::filesystem::path write_input(const std::string& name, const std::string& text);

// A property of accepted input that does not hold: abort with the reason, so
// that the input is kept as a crash (bad data the reader let through).
[[noreturn]] inline void fail_property(const char* what) {
  std::fprintf(stderr, "fuzz property violated: %s\n", what);
  std::abort();
}
#define RCM_FUZZ_CHECK(cond) ((cond) ? (void)0 : ::rcm::fuzz::fail_property(#cond))

// Runs `read`; rcm::InputError is the accepted way to reject the input.
// Returns true when `read` returned normally.
template <class F>
bool accepts(F&& read) {
  try {
    read();
    return true;
  } catch (const InputError&) {
    return false;
  }
}

}  // namespace rcm::fuzz
