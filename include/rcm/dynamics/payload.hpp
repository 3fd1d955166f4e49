#pragma once
// A payload change on the insertion stage (another instrument, a camera, a
// clip): the sliding body's mass, first moment and inertia change. Under the
// rigid-body potential (rigid_body.hpp) that body contributes
//   U = g . Rz(q1) Rx(q2) (h + q3 m e),
// e the instrument axis in the frame of the potential's moments, so the
// payload's gravity torque is linear in four numbers: its first moment h (3)
// and its mass m along e, both times |g| and in the sign convention of the
// model's gravity direction. The frame's axes are the fit's (any fixed
// rotation about z and joint offsets move into the moments), so e is read
// from the fitted model: the direction of its own sliding body's moment v2.
// A short recording with the payload re-identifies, on a linear model fitted
// without it, the whole potential of the rigid links (the seven moments of
// rigid_body.hpp) under a gravity direction searched again, and the
// payload's inertia about the yaw and pitch axes as changes of those joints'
// armatures; the payload is reported as the change of the moments (its first
// moment, and its weight along e). The direction is searched again because
// one excitation path identifies it only weakly (on the real PSM the fits of
// two payloads on one arm differ by 20-30 deg) and the payload's torque on
// yaw and pitch depends on it. On the real PSM a mass on the insertion stage
// sits about half a metre up the instrument from the RCM, and without its
// inertia the refitted model misses a good part of the yaw and pitch torque
// at full speed (docs/validation-free-space.md). Friction and the configuration-dependent
// inertia are kept.

#include <Eigen/Core>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/io/recording.hpp"

namespace rcm::dynamics {

constexpr int kPayloadTerms = 4;

// dtau / d(payload) at q for gravity direction g (unit, base frame) and
// instrument axis e (unit, the moments' frame): joints 1-3 by the four terms
// [h_x, h_y, h_z, m] above.
void compute_payload_regressor(const Eigen::Vector3d& g, const Eigen::Vector3d& e, const double* q,
                               Eigen::Matrix<double, 3, kPayloadTerms>& Y);

// The instrument axis e of a model with the rigid-body structure: the
// direction of its sliding body's moment v2 (the moments that reproduce its
// potential). Throws InputError for a model without the structure or whose
// potential has no sliding body to align a payload with.
Eigen::Vector3d get_instrument_axis(const LinearTorqueParameters& parameters);

struct PayloadRefitOptions {
  // Below this reciprocal condition number of the nine terms' normal matrix
  // (scaled to unit columns) the recording does not move the arm enough to
  // tell them apart: an InputError says which, instead of a guess.
  double min_reciprocal_condition = 1e-6;
};

struct PayloadRefit {
  std::unique_ptr<LinearTorqueModel> model;  // the input model with its potential and the payload's inertia refitted
  Eigen::Matrix<double, kPayloadTerms, 1> payload;  // [h_x, h_y, h_z, m] times |g| (N m, N): the moments' change
  Eigen::Vector2d inertia = Eigen::Vector2d::Zero();  // added to the yaw and pitch armatures (kg m^2)
  Eigen::Vector3d instrument_axis = Eigen::Vector3d::Zero();  // e, the moments' frame
  Eigen::Vector3d gravity_direction = Eigen::Vector3d::Zero();  // searched again with the payload (unit, base frame)
  Eigen::Vector3d rms_before = Eigen::Vector3d::Zero();  // per joint, on the recordings given
  Eigen::Vector3d rms_after = Eigen::Vector3d::Zero();
  double reciprocal_condition = 0.0;
  std::size_t samples = 0;
  nlohmann::json to_json() const;
};

// Re-identifies the payload from `recordings` (free-space motion with the new
// payload) on `model`, a linear model with the rigid-body structure (its
// gravity direction and sliding body). Linear least squares on the residual of
// the model's whole-recording prediction, at each gravity direction of the
// fit's search (detail::search_gravity_direction). Throws InputError for a
// model without the structure, fewer than three joints, no samples, or a
// recording that does not identify the nine terms.
PayloadRefit refit_payload(const LinearTorqueModel& model, const std::vector<Recording>& recordings,
                           const PayloadRefitOptions& options = {});

}  // namespace rcm::dynamics
