#pragma once
// Internal: the rigid-body stage of the linear model's fit (linear_fit.cpp).
// Once the candidate search has fixed each joint's qddot estimate and Dahl
// displacement, the whole model is refitted with the structure of
// rigid_body.hpp: the 19 inertia terms, and the potential of rigid links under
// one gravity direction (7 moments and 2 angles instead of 17 coefficients).

#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "rcm/dynamics/travel_terms.hpp"

namespace rcm::dynamics::detail {

// One joint's estimators, as chosen by the candidate search.
struct JointEstimatorChoice {
  double dahl_displacement = 1e-3;
  double slow_dahl_displacement = 1e-2;  // of the slow Dahl state
  double causal_window_s = 0.0, causal_filter_s = 0.03;  // compute_step's qddot
  double batch_window_s = 0.0;  // the zero-phase qddot regressed on; 0: the causal one
  // The range the Coulomb profile's knots span (the training range).
  double profile_lo = 0.0, profile_hi = 1.0;
  // Where the stiffness column is zero: the middle of that range, for the
  // conditioning (the offset takes the difference back).
  double get_stiffness_origin() const { return 0.5 * (profile_lo + profile_hi); }
  // Whether the statistics of the travel terms (travel_terms.hpp, over the
  // same range) are gathered for this joint.
  bool travel = false;
  double get_travel_displacement(int h) const {
    return kTravelHysteresisFractions[static_cast<std::size_t>(h)] * (profile_hi - profile_lo);
  }
};

// Normal equations of the weighted rows of every joint, parameters in the order
// [gravity 17 | inertia 19 | per joint: armature, viscous, coulomb, offset,
// slow coulomb, sqrt-viscous, stiffness, Coulomb profile at knots 1..K-1]
// (LinearTorqueParameters, K = kCoulombProfileKnots).
// One joint's travel terms against the model's columns: e the travel
// regressor, x the model's row and y the torque (weighted as the rows).
struct TravelStats {
  Eigen::MatrixXd ee;  // sum e e^T
  Eigen::MatrixXd ex;  // sum e x^T
  Eigen::VectorXd ey;  // sum e y
};
struct ModelStats {
  Eigen::MatrixXd A;
  Eigen::VectorXd b;
  double yy = 0.0;
  std::size_t rows = 0;
  // Per joint: empty unless its JointEstimatorChoice::travel was set.
  std::vector<TravelStats> travel;
  ModelStats& operator+=(const ModelStats& o);
  // Weighted sum of squared residuals of theta (full layout).
  double compute_loss(const Eigen::VectorXd& theta) const;
};
constexpr int kRigidBodyShared = 17 + kInertiaTerms;
constexpr int kStiffnessEntry = 6;       // block entry of the stiffness
constexpr int kCoulombProfileFirst = 7;  // block entry of the profile's knot 1
constexpr int kRigidBodyBlock = kCoulombProfileFirst + kCoulombProfileKnots - 1;
inline int rigid_body_block_index(int joint, int k) { return kRigidBodyShared + kRigidBodyBlock * joint + k; }

// Rows weighted by weight[j] per joint; states (Dahl, causal qddot) run from the
// recording's start as in compute_step. Needs M >= 3 outputs.
ModelStats accumulate_rigid_body_stats(const std::vector<Recording>& recordings,
                                       const std::vector<SampleSegment>& segments,
                                       const std::vector<JointEstimatorChoice>& choices,
                                       const std::vector<double>& weight, double sample_period_s);

// The same statistics for several groups of segments at once (the groups may
// overlap), from one pass over each recording.
std::vector<ModelStats> accumulate_rigid_body_stats(const std::vector<Recording>& recordings,
                                                    const std::vector<std::vector<SampleSegment>>& groups,
                                                    const std::vector<JointEstimatorChoice>& choices,
                                                    const std::vector<double>& weight, double sample_period_s);

// Two groups of the samples in `segments` by speed: chunks of about
// chunk_s seconds whose mean normalized joint speed is at most the median
// (slow, group 0) or above it (fast, group 1). Fitting one and scoring the
// other asks what the data cannot show by a later slice of the same motion:
// does the model carry to another speed?
std::vector<std::vector<SampleSegment>> split_by_speed(const std::vector<Recording>& recordings,
                                                       const std::vector<SampleSegment>& segments, int num_outputs,
                                                       double chunk_s = 0.5);

// The travel terms of joint j fitted on what the model theta (full layout)
// leaves of the samples of `stats` (least squares, the ridge of
// solve_bounded_normal_equations for knots the samples do not reach).
Eigen::VectorXd solve_travel_terms(const ModelStats& stats, int j, const Eigen::VectorXd& theta);
// compute_loss of theta with joint j's travel terms c added.
double compute_loss_with_travel(const ModelStats& stats, int j, const Eigen::VectorXd& theta,
                                const Eigen::VectorXd& c);

// How the 19 inertia coefficients are fitted: free, or tied by the bodies of
// a remote-centre arm (rigid_body.hpp, compute_remote_center_map).
enum class InertiaStructure { free, remote_center };

struct RigidBodySolution {
  Eigen::VectorXd theta;                // full layout, gravity = P(g) v
  Eigen::Vector3d gravity_direction;    // unit, base frame (sign free)
  double loss = 0.0;                    // of `stats` it was fitted on
};

// The gravity direction by a grid over the half sphere (5 deg), refined to
// 1 deg, each with the moments and every other parameter by least squares
// (viscous, Coulomb, slow Coulomb and sqrt-viscous >= 0; with the remote-centre
// structure also the sliding mass and the armatures, which are inertias).
// beta: the instrument-axis angle of the remote-centre structure, rad.
// profile_joints: bit j set, joint j has a Coulomb profile; the others' are held at 0.
// stiffness_joints: the same for the stiffness.
RigidBodySolution solve_rigid_body(const ModelStats& stats, int num_outputs,
                                   InertiaStructure structure = InertiaStructure::free, double beta = 0.0,
                                   unsigned profile_joints = 0u, unsigned stiffness_joints = 0u);
// The same at one gravity direction g.
RigidBodySolution solve_rigid_body_at(const ModelStats& stats, int num_outputs, InertiaStructure structure,
                                      double beta, const Eigen::Vector3d& g, unsigned profile_joints = 0u,
                                      unsigned stiffness_joints = 0u);

// The gravity direction whose least-squares solution has the lowest loss: a
// grid over the upper half sphere (g and -g give the same span) every 5 deg
// of polar angle and 15 deg of azimuth, then every degree within 5 deg of
// polar angle and 8 deg of azimuth of the best. solve(g) returns an object
// with a `loss`; the best one is returned (the first on ties).
template <class Solve>
auto search_gravity_direction(Solve solve) -> decltype(solve(Eigen::Vector3d())) {
  constexpr double kDegree = 3.14159265358979323846 / 180.0;
  auto direction = [](double polar, double azimuth) {
    return Eigen::Vector3d(std::sin(polar) * std::cos(azimuth), std::sin(polar) * std::sin(azimuth), std::cos(polar));
  };
  decltype(solve(Eigen::Vector3d())) best{};
  int best_polar = 0, best_azimuth = 0;
  bool first = true;
  for (int polar = 0; polar <= 90; polar += 5)
    for (int azimuth = 0; azimuth < 360; azimuth += (polar == 0 ? 360 : 15)) {
      auto s = solve(direction(polar * kDegree, azimuth * kDegree));
      if (first || s.loss < best.loss) {
        best = std::move(s);
        best_polar = polar;
        best_azimuth = azimuth;
        first = false;
      }
    }
  const int p0 = best_polar, a0 = best_azimuth;
  for (int dp = -5; dp <= 5; ++dp)
    for (int da = -8; da <= 8; ++da) {
      auto s = solve(direction((p0 + dp) * kDegree, (a0 + da) * kDegree));
      if (s.loss < best.loss) best = std::move(s);
    }
  return best;
}

// min |A^(1/2) x - ...|: (A + ridge) x = b with x[i] >= 0 for i in `nonnegative`
// by an active set; the ridge, relative to each diagonal, picks the small-norm
// solution along collinear columns.
Eigen::VectorXd solve_bounded_normal_equations(const Eigen::MatrixXd& A, const Eigen::VectorXd& b,
                                               const std::vector<int>& nonnegative);

}  // namespace rcm::dynamics::detail
