#pragma once
// The training module (rcm/dynamics/training_module.hpp), opened the first time
// `rcm` trains a network or converts TorchScript, so that every other command
// starts without LibTorch's libraries.

#include "rcm/dynamics/training_module.hpp"

namespace rcm::cli {

// Opens the module once: $RCM_TRAINING_MODULE when set, else the module
// installed beside this program (<prefix>/<libdir>/rcm/rcm_training.so for
// <prefix>/bin/rcm, the same layout in the build tree). Throws
// std::runtime_error naming the file and the loader's reason when it cannot.
const dynamics::TrainingFunctions& get_training_functions();

}  // namespace rcm::cli
