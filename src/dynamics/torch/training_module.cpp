// The entry point of the training module (training_module.hpp).

#include "rcm/dynamics/training_module.hpp"

#include "rcm/dynamics/training.hpp"

extern "C" __attribute__((visibility("default"))) const rcm::dynamics::TrainingFunctions* rcm_get_training_functions(
    std::uint64_t abi) {
  static const rcm::dynamics::TrainingFunctions functions = [] {
    rcm::dynamics::TrainingFunctions f;
    f.fit_torque_model = &rcm::dynamics::fit_torque_model;
    f.export_torchscript = &rcm::dynamics::export_torchscript;
    f.import_torchscript = &rcm::dynamics::import_torchscript;
    return f;
  }();
  return abi == rcm::dynamics::kTrainingModuleAbi ? &functions : nullptr;
}
