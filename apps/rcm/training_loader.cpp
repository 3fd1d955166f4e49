#include "training_loader.hpp"

#include <dlfcn.h>
#include <fmt/format.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <stdexcept>
#include <string>

namespace rcm::cli {
namespace {

std::filesystem::path get_module_path() {
  if (const char* path = std::getenv("RCM_TRAINING_MODULE"); path != nullptr && *path != '\0') return path;
  std::error_code ec;
  const auto program = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw std::runtime_error("cannot locate the rcm program (/proc/self/exe: " + ec.message() + ")");
  // RCM_TRAINING_MODULE_RELATIVE: the module's path relative to the program's directory.
  return program.parent_path() / RCM_TRAINING_MODULE_RELATIVE;
}

const dynamics::TrainingFunctions& open_training_module() {
  const std::filesystem::path path = get_module_path();
  // Never closed: the models it creates keep pointers into its code.
  void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr) {
    throw std::runtime_error(fmt::format("cannot open the training module {} (LibTorch), which fitting lstm, mlp and "
                                         "hybrid models and TorchScript need: {}",
                                         path.string(), dlerror()));
  }
  using Entry = const dynamics::TrainingFunctions* (*)(std::uint64_t);
  auto entry = reinterpret_cast<Entry>(dlsym(handle, "rcm_get_training_functions"));
  const dynamics::TrainingFunctions* functions = entry ? entry(dynamics::kTrainingModuleAbi) : nullptr;
  if (functions == nullptr) {
    throw std::runtime_error(fmt::format("{} is not the training module of this rcm ({}): reinstall rcm",
                                         path.string(), entry ? "built from other sources" : "no entry point"));
  }
  return *functions;
}

}  // namespace

const dynamics::TrainingFunctions& get_training_functions() {
  // A failure is not cached: the next call reports it again.
  static std::mutex mutex;
  static const dynamics::TrainingFunctions* functions = nullptr;
  const std::lock_guard<std::mutex> lock(mutex);
  if (functions == nullptr) functions = &open_training_module();
  return *functions;
}

}  // namespace rcm::cli
