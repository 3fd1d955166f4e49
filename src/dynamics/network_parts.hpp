#pragma once
// Internal: what the files of the networks share (networks.cpp: the model
// kinds; network_kernels.cpp: the LSTM and dense kernels; network_io.cpp: the
// parameters in model files).

#include <nlohmann/json.hpp>

#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics::detail {

// Throws std::invalid_argument naming `what` when the layers do not chain.
void check_stack(const DenseStack& stack, const char* what);
// Throws std::invalid_argument when the normalization does not fit `joints` inputs and `outputs` outputs.
void check_normalization(const Normalization& normalization, int joints, int outputs);

// The model file's "parameters" pieces (docs/formats.md, "Free-space model").
nlohmann::json save_stack(const DenseStack& stack);
nlohmann::json save_lstm(const LstmNetwork& network);
nlohmann::json save_normalization(const Normalization& normalization);

}  // namespace rcm::dynamics::detail
