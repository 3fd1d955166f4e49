#pragma once
// The functions of training.hpp that the `rcm` program calls, as a table that
// the training module (a shared library built from rcm::torch) hands to the
// program that loads it. Debian's LibTorch loads some three hundred shared
// libraries (OpenCV, FFmpeg, ...) before main; a program that opens the module
// only when it trains a network or converts TorchScript starts without them.
// Programs that link rcm::torch call training.hpp directly.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics {

struct TrainingFunctions {
  FitResult (*fit_torque_model)(TorqueModelKind kind, const std::vector<Recording>& recordings,
                                const FitOptions& options) = nullptr;
  void (*export_torchscript)(const LstmTorqueModel& model, const std::filesystem::path& path) = nullptr;
  std::unique_ptr<LstmTorqueModel> (*import_torchscript)(const std::filesystem::path& path) = nullptr;
};

// The module and the program pass rcm's own types to each other: both must be
// built from the same sources. A change of this number, or of the size of a
// type the table passes, makes an older module refuse a newer program.
constexpr std::uint64_t kTrainingModuleAbi =
    1u | (std::uint64_t{sizeof(FitResult)} << 8) | (std::uint64_t{sizeof(FitOptions)} << 24) |
    (std::uint64_t{sizeof(Recording)} << 40) | (std::uint64_t{sizeof(TrainingFunctions)} << 56);

}  // namespace rcm::dynamics

// The module's one exported symbol: the table, or null when `abi` is not the
// module's kTrainingModuleAbi. Its code resolves rcm::core's symbols in the
// program that loads it, which must export them (one copy of the library, so
// that, among others, the interrupt flag set by the program's SIGINT handler is
// the one the training loop reads).
extern "C" const rcm::dynamics::TrainingFunctions* rcm_get_training_functions(std::uint64_t abi);
