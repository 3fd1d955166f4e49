#pragma once
// Model-based free-space torque (after Wang et al. [21]): rigid-body terms linear
// in parameters plus per-joint friction with a state, fitted by least squares.
//
// Gravity: for a yaw (q1) / pitch (q2) / insertion (q3) arm whose first two axes
// carry every link, the potential energy of any mass distribution and any base
// tilt lies in span{a(q1) b(q2) c(q3)}, a in {1, sin, cos}, b in {1, sin, cos},
// c in {1, q3}; torque_j = dU/dq_j. The 17 coefficients are shared by joints 1-3,
// which is what makes the fit physically consistent across joints.
// Inertia: a constant armature per joint times qddot, plus (fitted by default)
// the configuration-dependent inertia and velocity products of rigid links on
// joints 1-3 (rigid_body.hpp), with the potential then restricted to rigid
// links under one gravity direction. qddot is estimated causally from
// the measured qdot: the slope at the newest sample of a least-squares quadratic
// through the samples of the last acceleration_window_s (0: the backward
// difference of the last two samples), then a first-order low-pass with time
// constant acceleration_filter_s (0: none). Both are chosen per joint at fit time
// on the validation split. Over a whole recording (predict_torque, offline) qddot
// may instead come from a zero-phase estimate, the slope of a least-squares
// polynomial of batch_acceleration_degree (a cubic: flat over the band a
// recording moves in, so the inertia carries to other speeds) through the
// samples within +- batch_acceleration_window_s / 2 of each sample (0: the
// causal estimate); the fit then regresses on that estimate, so the armature is
// not biased by the causal lag. compute_step() takes the causal estimate, or,
// with live_zero_phase, the same zero-phase one as offline: its torque then
// trails its input by output_delay(), the largest half window plus half the
// period of the slowest stream the dVRK sends (kSlowestStreamPeriod), so that the window of
// the sample it is for has arrived at any rate from 100 Hz up, and the live
// torque is the offline one (but for the first half window of the stream).
// Friction per joint: viscous v, an offset, and Coulomb/stiction through a Dahl
// state z in [-1, 1] that moves toward sign(dq) over a characteristic
// displacement x_c and stays put at rest, so the holding torque remembers the
// direction of the last motion (a LuGre model without Stribeck):
//   z <- sign(dq) + (z - sign(dq)) exp(-|dq| / x_c).
// With the rigid-body structure, two more friction terms per joint: a second
// Dahl state, slower than the first, and sqrt(|dq|) sign(dq), friction that
// grows with speed but less than linearly. The slow state's displacement is
// an eighth of the travel in the training data on pitch and insertion
// (kSlowDahlTravelFraction), kSlowDahlFactor x_c on yaw: on the real PSM the
// friction at a point of a path is the same at full and half speed but builds
// over a good part of the stroke, and a slow state at ten times the bristles'
// scale (a millimetre on the insertion) leaves that build-up to the
// rate-dependent terms, which a fit at one speed then scales wrongly to the
// other. On yaw the longer state makes no difference across speeds on the
// real arm and spoils the holding torque after the short approaches of static
// holds on the simulated one.
// Viscous and Coulomb coefficients are kept >= 0 (active set), but for the
// rigid-body fit's viscous one, which may bend a sqrt-viscous one over.
// Where the fitted rate-dependent friction bends over (a negative viscous
// term under the sqrt one: friction that saturates with speed), it is held at
// its value at the fastest speed the fit saw rather than continued past the
// bend (friction_speed_limit): on the real PSM a fit at half speed that
// carries its curve to full speed predicts friction the arm does not show
// there. Friction that grows linearly at the top of the fitted range goes on
// growing.
// And a Coulomb level that varies along each joint's travel: the Dahl state's
// coefficient is coulomb + a piecewise-linear profile over knots equally spaced
// on the training range (zero at the first knot, constant beyond the range),
// kept per joint when it predicts the validation split and the other speed
// better by more than 1 %. On the real PSM the insertion's friction changes
// along the stroke, with the same shape at both speeds and both payloads.
// And, with the rigid-body structure, the insertion's stiffness: a torque
// stiffness * q3 from an elastic element along the stroke (cables, harness),
// which no potential of rigid links holds, since their gravity force along the
// insertion does not depend on q3. On one periodic path such a spring passes
// for a negative inertia that grows as the path slows down, so without it a
// fit at one speed takes the wrong inertia for the other. On yaw and pitch a
// spring is nearly in the span of the gravity terms, and fitted there it
// trades places with them.
// And, per joint where they predict better, the travel terms of
// travel_terms.hpp (a torque and a multi-scale hysteretic friction along the
// travel), fitted after everything else on what it leaves, so that they cannot
// take over the gravity or the inertia: on the real PSM, fitted with them,
// they trade places with the gravity direction and the error at the other
// speed grows.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/torque_model.hpp"

namespace rcm::dynamics {

// The Dahl state above after a displacement dq (joint units) over a characteristic
// displacement x_c > 0, discretized exactly: a motion in one direction leaves
// the same state however finely it is sampled, and dq = 0 leaves it as it is.
inline double compute_dahl_state(double z, double dq, double x_c) {
  if (dq == 0.0) return z;
  const double s = dq > 0 ? 1.0 : -1.0;
  return s + (z - s) * std::exp(-std::abs(dq) / x_c);
}

// When the Dahl states step along a stream: at the samples at least half a
// model period (the period the model was fitted at) after the last step, each
// on the displacement since then. Exact over any displacement (above), the
// state needs no step per sample; but the encoder of a still arm toggles by a
// count (the PSM's, and the simulated one's under its controller), and each
// toggle moves the state back and forth, so a stream sampled faster than the
// fit's data would move it more often than the fit did: on a model fitted at
// 200 Hz and streamed at 1 kHz, the holding torque of a still arm wandered
// 0.05 N m, 0.10 N m and 0.21 N (RMS), a filter sigma. At the fitted rate
// (stamps within half a period of it) and slower, every sample steps; the
// first sample and a time that goes back (another stream) step and restart
// the clock. The model's stream and the fit's samples step by this one rule.
class DahlClock {
 public:
  explicit DahlClock(double period_s = 0.0) : half_period_(0.5 * std::max(period_s, 0.0)) {}
  void reset() { started_ = false; }
  // Whether the states step at a sample taken at `t`.
  bool tick(double t) {
    if (started_ && t >= last_ && t < next_) return false;
    next_ = started_ && t >= last_ ? std::max(next_ + 2.0 * half_period_, t + half_period_) : t + half_period_;
    started_ = true;
    last_ = t;
    return true;
  }

 private:
  double half_period_;
  bool started_ = false;
  double last_ = 0.0, next_ = 0.0;  // the last step's time; the next step is at a sample from next_ on
};

// The slow Dahl state's characteristic displacement: on pitch and insertion, as
// a fraction of the joint's travel in the training data (at least x_c); on the
// other joints, and in model files that do not store it, in units of x_c.
constexpr double kSlowDahlTravelFraction = 0.125;
constexpr double kSlowDahlFactor = 10.0;
// Knots of the Coulomb profile a fit places over each joint's training range.
constexpr int kCoulombProfileKnots = 6;
// Degree of the local polynomial a fit takes the zero-phase qddot from (the
// slope of a cubic; see LinearTorqueParameters::batch_acceleration_degree).
constexpr int kZeroPhaseAccelerationDegree = 3;
// Piecewise-linear interpolation at x between K >= 2 knots equally spaced over
// [lo, hi], constant beyond: the value is (1 - w) c[k] + w c[k + 1].
inline void compute_knot_weights(double x, double lo, double hi, int K, int& k, double& w) {
  const double u = (x - lo) / (hi - lo) * (K - 1);
  if (!(u > 0)) {  // also NaN: the first knot
    k = 0, w = 0.0;
  } else if (u >= K - 1) {
    k = K - 2, w = 1.0;
  } else {
    k = static_cast<int>(u), w = u - k;
  }
}

// sqrt(|v|) sign(v).
inline double compute_sqrt_velocity(double v) { return v >= 0 ? std::sqrt(v) : -std::sqrt(-v); }

struct LinearTorqueParameters {
  Eigen::VectorXd gravity;            // 17 shared potential coefficients (joints 1-3)
  Eigen::VectorXd armature;           // per output joint
  Eigen::VectorXd viscous;            // per output joint
  Eigen::VectorXd coulomb;            // per output joint, multiplies the Dahl state
  Eigen::VectorXd offset;             // per output joint
  Eigen::VectorXd dahl_displacement;  // x_c per output joint (rad or m), > 0
  // Causal qddot estimate per output joint (see above). Left empty, they take the
  // defaults of model files written before they existed: window 0 (backward
  // difference) and a 30 ms low-pass.
  Eigen::VectorXd acceleration_window_s;  // s, >= 0
  Eigen::VectorXd acceleration_filter_s;  // s, >= 0
  // Zero-phase qddot of predict_torque() per output joint; empty: all 0 (causal).
  Eigen::VectorXd batch_acceleration_window_s;  // s, >= 0
  // Degree of the polynomial whose slope that is: 3 (cubic), or 2 (quadratic,
  // what model files without the field were fitted with).
  int batch_acceleration_degree = kZeroPhaseAccelerationDegree;
  // Rigid-body inertia of joints 1-3 (rigid_body.hpp, kInertiaTerms values;
  // each joint's qddot as for its armature); empty: none, as in files written
  // before it existed or fitted with FitOptions::rigid_body off.
  Eigen::VectorXd inertia;
  // The gravity direction the fit found (unit, base frame, sign free), for
  // information: `gravity` already holds the potential it implies. Empty when
  // the potential was fitted free.
  Eigen::VectorXd gravity_direction;
  // Per output joint, with the rigid-body structure (empty: none): the
  // coefficient of the slow Dahl state and of compute_sqrt_velocity(qd).
  Eigen::VectorXd coulomb_slow;
  Eigen::VectorXd sqrt_viscous;
  // The slow Dahl state's characteristic displacement per output joint (joint
  // units, > 0), with coulomb_slow; empty: kSlowDahlFactor x dahl_displacement
  // (model files written before it was stored).
  Eigen::VectorXd dahl_displacement_slow;
  // Per output joint (empty: none for any): beyond this |qd| the
  // rate-dependent friction (viscous, sqrt_viscous) keeps its value there
  // (above); 0: no limit. The fit sets the largest |qd| it saw on the joints
  // whose viscous coefficient is negative.
  Eigen::VectorXd friction_speed_limit;
  // Per output joint (empty: none): the Coulomb level's change along the travel
  // at K >= 2 knots equally spaced over [coulomb_profile_range(j, 0),
  // coulomb_profile_range(j, 1)] (M x K, joint units, first column 0), added to
  // `coulomb` by compute_knot_weights.
  Eigen::MatrixXd coulomb_profile;
  Eigen::MatrixXd coulomb_profile_range;  // M x 2, lo < hi
  // Per output joint (empty: none): torque per unit of the joint's position
  // (N m/rad or N/m); `offset` is the torque at q = 0.
  Eigen::VectorXd stiffness;
  // Per output joint (all four empty: none for any): the travel terms of
  // travel_terms.hpp over [travel_range(j, 0), travel_range(j, 1)] (M x 2, lo
  // < hi): the torque at Kt >= 2 knots (travel_torque, M x Kt), and H >= 1
  // Dahl elements of displacement travel_hysteresis_displacement (M x H, joint
  // units, > 0) whose levels at Kh >= 2 knots are travel_hysteresis (M x H Kh,
  // element h at columns h Kh ..). A joint whose row of both is zero has none.
  Eigen::MatrixXd travel_range;
  Eigen::MatrixXd travel_torque;
  Eigen::MatrixXd travel_hysteresis_displacement;
  Eigen::MatrixXd travel_hysteresis;
  // compute_step() takes the zero-phase qddot of the joints whose
  // batch_acceleration_window_s > 0, its torque trailing by output_delay()
  // (above); false: the causal estimate, no delay (model files without the
  // field).
  bool live_zero_phase = false;
};

// The longest zero-phase window run live (s): its delay and window then fit
// the workspace's ring at 2 kHz. Fits choose at most 0.4 s.
constexpr double kMaxLiveZeroPhaseWindow = 4.0;

class LinearTorqueModel final : public TorqueModel {
 public:
  static constexpr int kGravityTerms = 17;
  LinearTorqueModel(TorqueModelInfo info, LinearTorqueParameters parameters);
  TorqueModelKind kind() const override { return TorqueModelKind::linear; }
  std::unique_ptr<TorqueModelWorkspace> create_workspace() const override;
  void reset_state(TorqueModelWorkspace& workspace) const override;
  void compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                    double* tau) const override;
  int output_delay() const override { return live_delay_samples_; }
  // With live_zero_phase, every sample a call ran, in order; -1 otherwise.
  StepRuns get_step_runs(const TorqueModelWorkspace& workspace) const override;
  nlohmann::json save_parameters() const override;
  // compute_step() over the recording, with the zero-phase qddot for the joints
  // whose batch_acceleration_window_s > 0 (and a time axis that never decreases).
  Eigen::MatrixXd predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                   const Eigen::MatrixXd& velocity) const override;
  std::unique_ptr<TorqueSequencePredictor> create_sequence_predictor() const override;
  const LinearTorqueParameters& parameters() const { return parameters_; }
  // The coefficient of joint j's Dahl state at position q: `coulomb` plus the
  // profile there (compute_knot_weights), or `coulomb` alone without one.
  double get_coulomb_level(int j, double q) const;

  // dU/dq_j of the 17 gravity basis functions at q (joints 1-3), j = 0..2.
  static void compute_gravity_regressor(const double* q, Eigen::Matrix<double, 3, kGravityTerms>& Y);

 private:
  // compute_step() with qddot taken from `qdd` (num_outputs values) for the
  // joints whose batch_acceleration_window_s > 0, when `qdd` is not null, and
  // from the causal estimate otherwise.
  void compute_step_with_acceleration(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                      const double* qdd, double* tau) const;
  // compute_step() with live_zero_phase: the sample joins the workspace's ring,
  // and the samples up to the one the delay points at are run in order.
  void compute_delayed_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                            double* tau) const;
  // The torque of one sample whose qddot is in the workspace; advances the
  // friction states.
  // The torque of a sample taken at `t` (the Dahl states step by DahlClock).
  void compute_torque(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                      double* tau) const;
  friend class LinearSequencePredictor;
  LinearTorqueParameters parameters_;
  bool has_extra_friction_ = false;  // coulomb_slow and sqrt_viscous present
  // [travel_torque | travel_hysteresis] per joint, and which joints have a
  // nonzero row (the others skip the travel terms).
  Eigen::MatrixXd travel_coefficients_;
  std::vector<bool> has_travel_;
  int live_delay_samples_ = 0;       // output_delay()
};

// Least squares on the training split; x_c and the causal and zero-phase qddot
// estimates chosen per joint on the validation split from grids; final
// coefficients from train + validation, regressed on the zero-phase qddot.
FitResult fit_linear_torque_model(const std::vector<Recording>& recordings, const FitOptions& options);

}  // namespace rcm::dynamics
