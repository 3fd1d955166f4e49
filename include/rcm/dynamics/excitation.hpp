#pragma once
// Excitation trajectories for free-space data collection (`rcm excite`,
// docs/methods.md, "Excitation design").
//
// A finite Fourier series per joint (Swevers et al.), joints 1-3:
//   q_j(t) = q0_j + c_j + sum_{k=1..H} a_jk / (w k) sin(w k t) - b_jk / (w k) cos(w k t),
//   w = 2 pi / T, T = duration / periods,
// so qd_j = sum a_jk cos(w k t) + b_jk sin(w k t). It starts and ends at rest
// at q0 by constraining the coefficients, not by a window: c_j = sum_k b_jk /
// (w k) puts q(0) at q0, a_j1 = -sum_{k>1} a_jk gives qd(0) = 0 and b_j1 =
// -sum_{k>1} k b_jk gives qdd(0) = 0; the series is T-periodic, so the same
// holds at every multiple of T, the end of the trajectory included. The
// remaining 2 (H - 1) coefficients per joint are free.
//
// They are chosen to make the `linear` model's regressor well conditioned
// (the gravity regressor, LinearTorqueModel::compute_gravity_regressor, the
// rigid-body inertia regressor, compute_inertia_regressor, and per joint the
// armature, viscous, Coulomb (Dahl state) and offset columns, as the fit
// stacks them), with every joint asked to reverse its velocity a given number
// of times per period and to reach a share of its room on both sides of q0
// (penalties, not constraints). Ceres' GradientProblemSolver (L-BFGS) minimises
// log cond + penalties for leaving the limits, for too few reversals and for
// too little of the room reached, from a random start drawn with a fixed seed; the optimum is then
// scaled about q0 per joint (position, velocity and acceleration are linear
// in the coefficients) so that every written sample is within the limits.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "rcm/common/options_fwd.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm::dynamics {

struct ExcitationOptions {
  double duration_s = 30.0;  // whole trajectory, from rest at q0 to rest at q0
  double rate_hz = 200.0;    // samples written
  // Wanted fundamental period; the series repeats duration / period_s times,
  // rounded to a whole number (at least once), so that it ends at rest.
  double period_s = 10.0;
  int harmonics = 5;
  std::uint64_t seed = 1;
  Eigen::Vector3d q0 = Eigen::Vector3d(0.0, 0.0, 0.12);  // start and end, rad, rad, m
  // Kept free inside the robot description's joint limits at each end.
  Eigen::Vector3d position_margin = Eigen::Vector3d(0.10, 0.10, 0.01);
  // rad/s, rad/s, m/s and rad/s^2, rad/s^2, m/s^2: what the model is later
  // asked to cover, not limits read from a data sheet. A periodic
  // identification path on a real Classic PSM1 moving freely reaches 1.5 rad/s,
  // 8 rad/s^2, 0.3 m/s and 2 m/s^2; teleoperation on the simulated bench
  // reaches 2.1 rad/s on the pitch. A recording slower than the motions the
  // model is later run on leaves them outside its regime (regime.hpp).
  Eigen::Vector3d velocity_max = Eigen::Vector3d(2.0, 2.0, 0.3);
  Eigen::Vector3d acceleration_max = Eigen::Vector3d(8.0, 8.0, 2.0);
  int min_reversals = 4;           // velocity reversals per joint and period
  // Share of the room between q0 and each limit (less the margin) that every
  // joint is asked to reach on both sides, so that the recording covers the
  // positions later motions visit around q0 (a penalty, as the reversals).
  // At 0.5 a two-minute design left the pitch short of the bench's
  // teleoperation below q0 (`rcm setup` said so); 0.8 reaches it.
  double position_coverage = 0.8;
  // Share of each joint's speed limit (both directions) and acceleration limit
  // that the motion is asked to reach: the regime is the speeds the recording
  // went through, not the limits it was allowed, and conditioning alone is
  // content with a slow motion (a penalty, as the position coverage).
  double speed_coverage = 0.8;
  int samples_per_period = 200;    // where the objective is evaluated
  int max_iterations = 100;        // L-BFGS iterations
  // Throws std::invalid_argument naming the first bad field.
  void check() const;
};
const OptionTable<ExcitationOptions>& get_option_table(OptionTag<ExcitationOptions>);

// The box a trajectory must stay in, joints 1-3.
struct ExcitationLimits {
  Eigen::Vector3d position_min, position_max;  // the robot's limits less the margin
  Eigen::Vector3d velocity_max, acceleration_max;
};
ExcitationLimits get_excitation_limits(const PsmModel& robot, const ExcitationOptions& options);

// Throws InputError at `where` (the field or flag that gave q0, index
// appended) when q0 is not strictly inside the limits.
void check_excitation_start(const ExcitationLimits& limits, const Eigen::Vector3d& q0, const InputLocation& where);

// The series above, immutable: a (3 x H), b (3 x H), c and q0 per joint.
class ExcitationSeries {
 public:
  ExcitationSeries() = default;
  ExcitationSeries(const Eigen::Vector3d& q0, double period_s, Eigen::Matrix3Xd a, Eigen::Matrix3Xd b);
  // The coefficients that start and end at rest from the 2 (H - 1) free ones
  // per joint, x = [a_j2..a_jH, b_j2..b_jH] for j = 1..3.
  static ExcitationSeries from_free_coefficients(const Eigen::Vector3d& q0, double period_s, int harmonics,
                                                 const Eigen::VectorXd& x);
  static int count_free_coefficients(int harmonics) { return 3 * 2 * (harmonics - 1); }

  void compute_state(double t, Eigen::Vector3d& q, Eigen::Vector3d& qd, Eigen::Vector3d& qdd) const;
  // The same series with joint j's motion about q0 scaled by s[j].
  ExcitationSeries get_scaled(const Eigen::Vector3d& s) const;

  const Eigen::Vector3d& q0() const { return q0_; }
  double period_s() const { return period_s_; }
  int harmonics() const { return static_cast<int>(a_.cols()); }
  const Eigen::Matrix3Xd& a() const { return a_; }
  const Eigen::Matrix3Xd& b() const { return b_; }

 private:
  Eigen::Vector3d q0_ = Eigen::Vector3d::Zero(), c_ = Eigen::Vector3d::Zero();
  double period_s_ = 1.0, omega_ = 2.0 * 3.14159265358979323846;
  Eigen::Matrix3Xd a_, b_;
};

// Workspace of the regressor's conditioning: the Gram matrix of the stacked
// rows of joints 1-3 over samples added in time order. Columns: gravity (17),
// inertia (kInertiaTerms), then per joint armature (qdd), viscous (qd),
// Coulomb (the Dahl state, compute_dahl_state, with displacement
// dahl_displacement[j]) and offset, without the insertion's offset, which is
// the gravity regressor's q3 column. The linear fit's slow Dahl and
// sqrt-velocity columns are left out: on any motion they nearly repeat the
// Coulomb and viscous ones and would set the condition number alone.
class RegressorConditioning {
 public:
  static constexpr int kColumns = 17 + kInertiaTerms + 4 * 3 - 1;
  explicit RegressorConditioning(const Eigen::Vector3d& dahl_displacement);
  // Clears the sums and the Dahl states (rest, z = 0).
  void reset();
  // Moves the Dahl states to q without adding a row (a warm-up).
  void compute_dahl_step(const Eigen::Vector3d& q);
  void add_sample(const Eigen::Vector3d& q, const Eigen::Vector3d& qd, const Eigen::Vector3d& qdd);
  // sqrt(largest / smallest eigenvalue) of the Gram matrix with its columns
  // scaled to unit norm (units drop out); infinity when a column is zero.
  double get_condition_number() const;
  // log of it with the smallest eigenvalue floored at 1e-20 of the largest
  // (finite for any motion: what the optimiser descends).
  double get_log_condition_number() const;
  std::size_t get_samples() const { return samples_; }

 private:
  Eigen::Vector3d dahl_displacement_, z_, q_last_;
  bool has_last_ = false;
  std::size_t samples_ = 0;
  Eigen::Matrix<double, kColumns, kColumns> gram_;
  Eigen::Matrix<double, 3, kColumns> rows_;
  Eigen::Matrix<double, 3, 17> Yg_;
  Eigen::Matrix<double, 3, kInertiaTerms> Yi_;
};

// The Dahl displacement the excitation's objective and reports use: 3e-4 of
// each joint's position range (the linear fit's usual choice of x_c).
Eigen::Vector3d get_excitation_dahl_displacement(const ExcitationLimits& limits);

// The condition number above over samples (T x >= 3, joints 1-3 used), in
// order, the Dahl states starting at rest.
double compute_regressor_condition_number(const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity,
                                          const Eigen::MatrixXd& acceleration, const Eigen::Vector3d& dahl_displacement);

// Sign changes of each column of `velocity`; values within `floor_fraction` of
// the column's largest magnitude count as zero (skipped): 1e-9 for a designed
// path (rounding at rest), a tenth or so for a measured one (noise at rest is
// no reversal).
std::vector<int> count_velocity_reversals(const Eigen::MatrixXd& velocity, double floor_fraction = 1e-9);

// The solver's outcome.
struct ExcitationSummary {
  bool converged = false;
  std::string termination;  // Ceres termination type
  std::string message;
  int iterations = 0;
  double initial_condition_number = 0.0;  // the random start, within the limits, on the written samples
  double condition_number = 0.0;          // the result, on the written samples
  bool limits_satisfied = false;          // every written sample within the limits
  Eigen::Vector3d limit_scale = Eigen::Vector3d::Ones();  // the per-joint scaling into the limits (1: none)
  int periods = 1;
  double period_s = 0.0;
  double seconds = 0.0;
  std::string brief_report() const;
};

struct ExcitationTrajectory {
  ExcitationSeries series;
  ExcitationLimits limits;
  Eigen::VectorXd time;  // 0, 1 / rate, ..., duration
  Eigen::MatrixXd position, velocity, acceleration;  // samples x 3
  std::vector<int> reversals;  // per joint, over the samples
  ExcitationSummary summary;
};

// Samples `series` at rate_hz from 0 to duration_s (both included).
void compute_excitation_samples(const ExcitationSeries& series, double duration_s, double rate_hz,
                                ExcitationTrajectory& out);

// Designs the trajectory. Options are checked first (std::invalid_argument);
// q0 outside the limits is an InputError at "ExcitationOptions: field q0".
ExcitationTrajectory design_excitation(const PsmModel& robot, const ExcitationOptions& options);

}  // namespace rcm::dynamics
