#pragma once
// Torque along a joint's travel that the rigid-body model leaves: a torque
// that depends on where the joint is (elastic elements, cable routing), and a
// friction made of several Dahl elements (a generalized Maxwell-slip model)
// whose break-away displacements span a thousandth to half of the travel, each
// with a level that varies along the travel. On the real PSM the pitch torque
// the rigid-body model leaves has the same shape along the travel at both
// speeds and all four payloads, and builds up over every scale of the distance
// moved since the last reversal (docs/methods.md). Every term is a function
// of the path in joint space, not of the speed along it, so it carries to any
// speed the path is run at.
//
// The regressor of one joint at position q, over the range [lo, hi] the knots
// span (constant beyond it):
//   [ hat_0(q) .. hat_{Kt-1}(q) | z_h hat'_k(q), h = 0..H-1, k = 0..Kh-1 ]
// hat: the piecewise-linear basis of Kt (or Kh) knots equally spaced over
// [lo, hi] (compute_knot_weights), z_h the Dahl state of element h
// (compute_dahl_state over its displacement). The torque is the regressor
// times [travel_torque row | travel_hysteresis row] (linear_model.hpp).

#include <array>

namespace rcm::dynamics {

// Knots of the torque along the travel and of each element's level, and the
// elements' displacements as fractions of the travel, that a fit places.
constexpr int kTravelTorqueKnots = 8;
constexpr int kTravelHysteresisKnots = 6;
constexpr std::array<double, 7> kTravelHysteresisFractions = {0.001, 0.003, 0.01, 0.03, 0.1, 0.25, 0.5};
constexpr int kTravelHysteresisElements = static_cast<int>(kTravelHysteresisFractions.size());
constexpr int kTravelColumns = kTravelTorqueKnots + kTravelHysteresisElements * kTravelHysteresisKnots;

// The regressor above into row[0 .. torque_knots + elements * hysteresis_knots);
// z holds the elements' states. torque_knots, hysteresis_knots >= 2, lo < hi.
void compute_travel_regressor(double q, double lo, double hi, const double* z, int elements, int torque_knots,
                              int hysteresis_knots, double* row);

}  // namespace rcm::dynamics
