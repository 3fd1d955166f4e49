#pragma once
// The tissue model `rcm setup` identified on the calibration, saved beside the
// free-space model (tissue_model.json) so that a monitor or a live node starts
// without identifying it again: the fit, its held-out self-check and its
// bootstrap take seconds to tens of seconds. The file names what it was made
// from (the calibration recording's and the free-space model file's digests,
// D* and q0); loading it for another calibration, model or D* is an InputError,
// never a silent mix.
//
// Format "rcm-tissue-model/1": the JointTissueModel's fields by name, SI units
// (docs/session-format.md).

#include <filesystem>
#include <string>

#include "rcm/estimation/joint.hpp"
#include "rcm/io/session.hpp"

namespace rcm {

struct TissueModelOrigin {
  std::string calibration_digest;       // get_file_digest of the calibration recording
  std::string free_space_model_digest;  // get_file_digest of the saved free-space model
  double calibration_offset_m = 0.0;    // D*
  Eigen::Vector3d q0 = Eigen::Vector3d::Zero();  // the incision frame's configuration
};

// The origin of a tissue model identified on `session`'s calibration with the
// free-space model saved in `free_space_model_file`. Throws InputError when the
// session has no calibration or a file cannot be read.
TissueModelOrigin get_tissue_model_origin(const Session& session, const std::filesystem::path& free_space_model_file);

// Written atomically (rcm/io/atomic_file.hpp).
void save_joint_tissue_model(const std::filesystem::path& path, const JointTissueModel& model,
                             const TissueModelOrigin& origin);

// Throws InputError naming the file and the field when a field is missing or
// malformed, or when the file's origin is not `expected` (D* and q0 compared
// within 1e-9).
JointTissueModel load_joint_tissue_model(const std::filesystem::path& path, const TissueModelOrigin& expected);

}  // namespace rcm
