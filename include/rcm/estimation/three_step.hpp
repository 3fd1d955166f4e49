#pragma once
// Three-step RCM misalignment estimation, paper III-C and Algorithm 1.
//
//   step 1  q0 and the torques of the aligned docking hold (baseline);
//   step 2  the tissue law g from a calibration at a known pure coaxial offset
//           (rcm/tissue, not here);
//   step 3  per trial: (a) total force f_e(D) = J_D^{-T}(tau_h - tau_fs,h), (b) radial
//           force f_r(D) = J_D(q0)^{-T} dtau_r from the static hold at q0, (c) coaxial
//           force f_c = f_e - f_r and D~ = argmin 1/2 sum psi^2 with
//           psi = g(D tan theta) - |f_c(D)|, D in [D_min, D_max], (d) radial offset
//           dp_r = -g^{-1}(|f_r|) f_r / |f_r| in the incision frame.
//
// Step 3c as the paper writes it adds the forces of the coaxial and the radial
// stretch as vectors, which holds for a linear g only: the tissue pulls with
// g(|s|) along its whole stretch s = D tan(theta) e - dp_r (e the pivot's
// direction in the pad plane). With stiffening tissue and an 18 mm radial offset
// that puts D~ 3-5 mm long on the simulated bench. CoaxialForce::total fits
// psi = g(|s(D)|) - |f_e(D)| instead, dp_r(D) being step 3d's answer at D (the
// hold's force scales with 1/D); for a linear g both agree.
//
// Because the columns of J_D are orthogonal, J_D^{-T} dtau = u / D + w with
// u = cos(theta) (a1 dtau_1 / cos^2 q2 + a2 dtau_2) and w = z3 dtau_3 (a1, a2 the
// derivatives of z3): every force is affine in 1/D, so psi and dpsi/dD are exact
// and cheap for the solver.
//
// Sign (derived from the geometry and checked against the simulator): the
// contract's force is the force the instrument applies to the tissue. The tissue
// is anchored at the incision; the instrument drags it away from there, so the
// radial force points from the incision towards the shaft, i.e. against the
// radial offset: dp_r = -g^{-1}(|f_r|) f_r / |f_r|.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "rcm/io/recording.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/tissue/tissue_law.hpp"

namespace rcm {

struct RestDetectionOptions {
  double max_angular_speed = 0.01;  // rad/s, joints 1-2
  double max_linear_speed = 0.002;  // m/s, joint 3
  double max_angle_from_q0 = 0.005;  // rad, joints 1-2
  double max_insertion_from_q0 = 0.002;  // m, joint 3
  double min_duration_s = 0.25;
};
const OptionTable<RestDetectionOptions>& get_option_table(OptionTag<RestDetectionOptions>);

// A contiguous run of samples at rest at q0: [begin, end).
struct RestSegment {
  Eigen::Index begin = 0, end = 0;
  double duration_s = 0.0;
};

// Every run at rest at q0 lasting at least min_duration_s, in time order. Throws
// InputError naming the recording when there is none (e.g. the static file of
// another q0, or a robot still moving).
std::vector<RestSegment> find_rest_segments(const Recording& recording, const Eigen::Vector3d& q0,
                                            const RestDetectionOptions& options = {});
// The last of them: the hold comes after the return motion.
RestSegment find_rest_segment(const Recording& recording, const Eigen::Vector3d& q0,
                              const RestDetectionOptions& options = {});

// How step 3b reads the static file.
//  last_hold  the paper's: the last hold alone.
//  balanced   every hold; per joint, the holds approached from above and from
//             below are averaged separately and the two means averaged. A joint
//             at rest keeps the friction its last motion left (rate-independent,
//             hysteretic friction: anywhere in a band of about +-0.12 N m on the
//             Classic PSM's yaw, 4 N at the incision at D = 30 mm); it changes
//             sign with the direction of approach, so the balanced mean cancels
//             what the free-space model got wrong of it, to first order. With
//             holds from one side only it is the mean of every hold.
enum class StaticStep { last_hold, balanced };
std::string to_string(StaticStep step);
StaticStep parse_static_step(const std::string& text);  // throws std::invalid_argument
const OptionChoices<StaticStep>& get_option_choices(OptionTag<StaticStep>);

// One hold of the static file: its samples and, per joint, the direction of the
// motion that ended there (+1 up, -1 down, 0 when the joint did not come from
// farther than the rest tolerance within the file).
struct HoldApproach {
  RestSegment segment;
  Eigen::Vector3i direction = Eigen::Vector3i::Zero();
  Eigen::Vector3d tau_measured = Eigen::Vector3d::Zero();   // mean measured effort
  Eigen::Vector3d tau_free_space = Eigen::Vector3d::Zero();  // mean predicted tau_fs
};

// Step 3b's torque residual at q0, combined over the holds as `step` says.
struct StaticHold {
  RestSegment segment;                 // the last hold
  std::vector<HoldApproach> holds;     // every hold, in time order
  StaticStep step = StaticStep::balanced;
  Eigen::Vector3d tau_measured = Eigen::Vector3d::Zero();    // combined measured effort
  Eigen::Vector3d tau_free_space = Eigen::Vector3d::Zero();  // combined predicted tau_fs
  // Per joint: true when holds from both directions went into the mean.
  Eigen::Matrix<bool, 3, 1> direction_balanced = Eigen::Matrix<bool, 3, 1>::Constant(false);
  Eigen::Vector3d get_dtau() const { return tau_measured - tau_free_space; }
};

// tau_fs: T x (>=3) free-space prediction for the whole static file, computed
// with the model's state carried through the return motion.
StaticHold compute_static_hold(const Recording& recording, const Eigen::MatrixXd& tau_fs,
                               const Eigen::Vector3d& q0, const RestDetectionOptions& options = {},
                               StaticStep step = StaticStep::balanced);

// Encoder chatter at the hold. A joint at rest on the edge of an encoder count
// makes the measured position toggle between two adjacent counts (seen on the
// simulated bench: 22 toggles of the pitch encoder in the first 0.3 s of a hold,
// while the true joint moved by a few microradians). A free-space model whose
// friction state is driven by position increments (the linear model's Dahl state,
// x_c ~ 15 counts) reads each toggle as a reversal: the holding friction it
// predicts decays from the level the last real motion left towards zero, while
// the real bristles keep it. The hold's tau_fs is then wrong by up to the Coulomb
// level (0.05 N m on the pitch joint, 2 mm of radial error at D = 30 mm).
// Running the model on positions passed through a play (backlash) operator one
// to two counts wide removes the toggles and keeps every real motion (delayed by
// at most half the width).
//
// The smallest nonzero |q(k+1) - q(k)| of each joint (the encoder count for
// quantized recordings; a tiny number, hence a harmless filter, for exact ones).
// 0 for a joint that never moves.
Eigen::VectorXd estimate_position_quantum(const Recording& recording);
// A copy of the recording whose positions went through a play operator of total
// width `width[j]` per joint (0 leaves the joint as it is): y <- clamp(y, q - w/2,
// q + w/2), starting at y = q(0). Velocities and efforts are unchanged.
Recording remove_position_chatter(const Recording& recording, const Eigen::VectorXd& width);

// f = J_D^{-T} dtau at q written as u / D + w (see the file comment). Exact for
// every D != 0; the caller checks conditioning at the D it uses.
struct InverseDecomposition {
  Eigen::Vector3d u = Eigen::Vector3d::Zero();
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
  Eigen::Vector3d evaluate(double D) const { return u / D + w; }
};
InverseDecomposition compute_inverse_decomposition(const IncisionFrame& incision, const Eigen::Vector3d& q,
                                                   const Eigen::Vector3d& dtau);

// The coaxial least-squares problem of one trial (Eq. 16-17), reduced to
// per-sample coefficients.
struct CoaxialProblem {
  std::vector<InverseDecomposition> total;  // f_e of each used sample
  std::vector<double> tan_theta;
  InverseDecomposition radial;              // f_r at q0
  std::vector<Eigen::Index> sample_index;   // which recording samples are used
  // d(stretch)/dD of each used sample when the incision lies on the shaft's axis
  // at q0: z3 / cos(theta) - z_inc (base frame, in the pad plane).
  std::vector<Eigen::Vector3d> stretch_per_D;
  Eigen::Matrix3d R_base_inc = Eigen::Matrix3d::Identity();
};

// Step 3d at D: the radial offset dp_r = -g^{-1}(|f_r|) f_r / |f_r| of the
// hold's in-plane force, in the base frame, and d(dp_r)/dD. g is extended past
// its fitted range (up to 3 x_max) when the hold's force lies outside it.
struct RadialOffset {
  Eigen::Vector3d dp_r_base = Eigen::Vector3d::Zero();
  Eigen::Vector3d d_dp_r_dD = Eigen::Vector3d::Zero();
  Eigen::Vector3d f_radial_inc = Eigen::Vector3d::Zero();  // the hold's force, incision frame
  double f_in_plane = 0.0;
  TissueInverseStatus inverse = TissueInverseStatus::ok;
  bool extrapolated = false;
  std::string message;
};
RadialOffset compute_radial_offset(const CoaxialProblem& problem, const TissueLaw& g, double D);

struct CoaxialProblemOptions {
  // Samples whose pivot exceeds this carry a J_D that amplifies noise without
  // bound (theta -> 90 deg); teleoperation stays far below.
  double max_theta_rad = 80.0 * M_PI / 180.0;
};
const OptionTable<CoaxialProblemOptions>& get_option_table(OptionTag<CoaxialProblemOptions>);

CoaxialProblem make_coaxial_problem(const IncisionFrame& incision, const Recording& trial,
                                    const Eigen::MatrixXd& tau_fs, const Eigen::Vector3d& dtau_radial,
                                    const CoaxialProblemOptions& options = {});

// psi_t(D) for every sample, and dpsi_t/dD when `jacobian` is not null. Returns
// false where the problem is undefined (D == 0).
bool compute_coaxial_residuals(const CoaxialProblem& problem, const TissueLaw& g, double D,
                               double* residuals, double* jacobian);
// CoaxialForce::total's psi_t(D) = g(|D a_t - dp_r(D)|) - |f_e,t(D)| (a_t =
// stretch_per_D[t], dp_r(D) from compute_radial_offset), and its derivative in D
// when `jacobian` is not null. False where undefined (D == 0, g not invertible
// at the hold's force).
bool compute_total_force_residuals(const CoaxialProblem& problem, const TissueLaw& g, double D,
                                   double* residuals, double* jacobian);

struct SolverReport {
  bool converged = false;
  std::string termination;  // Ceres termination type
  std::string message;
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;
  double seconds = 0.0;  // wall time of the solve
  std::string brief_report() const;
};

// How step 3c compares the law with the forces (see the file comment).
//  difference  the paper's: g(D tan theta) against |f_e - f_r|.
//  total       g(|stretch|) against |f_e|, the stretch with step 3d's radial offset.
enum class CoaxialForce { difference, total };
std::string to_string(CoaxialForce mode);
const OptionChoices<CoaxialForce>& get_option_choices(OptionTag<CoaxialForce>);

struct ThreeStepOptions {
  double D_min = -0.020, D_max = 0.070;  // m (paper Eq. 16)
  std::optional<double> D_initial;        // default: middle of the bounds
  double function_tolerance = 1e-6;       // relative change of cost (paper IV-D)
  int max_iterations = 200;
  CoaxialForce coaxial_force = CoaxialForce::total;
  CoaxialProblemOptions coaxial;
  // Throws std::invalid_argument naming the first bad option.
  void check() const;
};
const OptionTable<ThreeStepOptions>& get_option_table(OptionTag<ThreeStepOptions>);

// Step 3c alone: D~ = argmin 1/2 sum psi^2 within [D_min, D_max] from
// options.D_initial (or the middle of the bounds).
double solve_coaxial_offset(const CoaxialProblem& problem, const TissueLaw& g, const ThreeStepOptions& options,
                            SolverReport* report);
// The same with CoaxialForce::total's residuals.
double solve_coaxial_offset_total(const CoaxialProblem& problem, const TissueLaw& g, const ThreeStepOptions& options,
                                  SolverReport* report);

// The problem as JSON ("rcm-coaxial-problem/1": per-sample tan(theta), u, w, the
// radial u0, w0, g, bounds and start), for cross-checking the solver elsewhere
// (bench/scipy_crosscheck.py).
nlohmann::json coaxial_problem_to_json(const CoaxialProblem& problem, const TissueLaw& g,
                                       const ThreeStepOptions& options);

struct ThreeStepResult {
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();  // [dr_x, dr_y, D], incision frame
  SolverReport solver;
  std::size_t samples_used = 0;
  // Radial step at D~: the hold's force in the incision frame, its in-plane
  // magnitude, and how g was inverted.
  Eigen::Vector3d f_radial_inc = Eigen::Vector3d::Zero();
  double f_radial_in_plane = 0.0;
  TissueInverseStatus radial_inverse = TissueInverseStatus::ok;
  bool radial_extrapolated = false;  // |f_r| outside g's fitted range; g extended
  std::string radial_message;
};

// Steps 3c and 3d for one trial. tau_fs_trial: the free-space prediction for the
// trial recording (T x >= 3); dtau_radial: StaticHold::get_dtau() of its hold
// (zero when the trial has no static file: then the radial offset is not
// estimated and stays 0).
ThreeStepResult estimate_three_step(const IncisionFrame& incision, const TissueLaw& g,
                                    const Recording& trial, const Eigen::MatrixXd& tau_fs_trial,
                                    const Eigen::Vector3d& dtau_radial, const ThreeStepOptions& options = {});

}  // namespace rcm
