#pragma once
// The gravity regressor's column count under the short name the fitting
// files' matrix algebra uses (one definition: files may share a translation
// unit).

#include "rcm/dynamics/linear_model.hpp"

namespace rcm::dynamics::detail {

inline constexpr int G = LinearTorqueModel::kGravityTerms;

}  // namespace rcm::dynamics::detail
