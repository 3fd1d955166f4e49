#pragma once
// Joint estimation of all three offsets in torque space (beyond the paper).
//
// Instead of inverting J_D, predict the joint-torque residual directly:
//
//   tau - tau_fs ~ J_D(q; s)^T f,   s = D / cos(theta)
//   f = g(|x|) x/|x| + c (ds/dt z3 + s dz3/dt) + F tanh(v / v0) z3
//   x = s z3 - R_I [dr_x, dr_y, D]           (stretch of the incision in the pad plane)
//   v = qd3 - ds/dt                          (the shaft sliding through the incision)
//   g(x) = k1 x + k3 x^3
//
// with the tissue parameters [k1, k3, c, F] identified on the calibration (known
// D*, no radial offset) and the offsets [dr_x, dr_y, D] solved per trial over
// every sample of the trial and of its static file when there is one, by bounded
// robust least squares (Ceres, Huber loss, automatic derivatives). The insertion
// joint stays in the residual: yaw and pitch alone cannot tell (D, r) from (-D, -r).
//
// Uncertainty: the Ceres covariance (scaled by the residual variance) and a
// moving-block residual bootstrap (blocks of ~1 s keep the correlation of
// free-space model errors), giving 95 % intervals per component.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "rcm/estimation/three_step.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/kinematics/incision.hpp"

namespace rcm {

// What the joint model needs of one sample, precomputed once.
struct JointSample {
  Eigen::Vector3d z3, dz3_dq1, dz3_dq2, z3_dot, dtau;
  double cos_theta = 1.0;
  double qd3 = 0.0;
};

// Samples of a recording (with the free-space prediction tau_fs, T x >= 3) whose
// pivot stays below max_theta_rad.
std::vector<JointSample> make_joint_samples(const IncisionFrame& incision, const Recording& recording,
                                            const Eigen::MatrixXd& tau_fs, double max_theta_rad = 80.0 * M_PI / 180.0);

// [k1 (N/m), k3 (N/m^3), c (N s/m), F (N)]
struct JointTissueModel {
  Eigen::Vector4d parameters = Eigen::Vector4d(800.0, 0.0, 0.0, 0.0);
  std::string family = "linear";  // "linear" (k3 = 0) or "stiffening"
  double axial_velocity_scale = 0.002;  // v0, m/s
  double cost = 0.0;
  double bic = 0.0;
  // Uncertainty of the parameters, from a moving-block bootstrap of the
  // calibration; propagated into every trial's interval.
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
  int bootstrap_replicates = 0;
  // The free-space model's torque error at the working configuration (N m,
  // N m, N), identified on the calibration jointly with the tissue parameters
  // (JointEstimatorOptions::fit_torque_offset; 0 otherwise): holding friction,
  // a gravity or torque offset that the free-space recording did not teach the
  // model. Every residual the estimators use, in trials and online, has it
  // taken off. Its bootstrap covariance is propagated into every trial's interval.
  Eigen::Vector3d torque_offset = Eigen::Vector3d::Zero();
  Eigen::Matrix3d torque_offset_covariance = Eigen::Matrix3d::Zero();
  // The calibration self-check, on data the fit did not use: the models (tissue
  // and torque offset) fitted on one half of the calibration in time re-estimate
  // the offsets of the other half; per component, the RMS over the two halves of
  // their departure from the known [0, 0, D*] ("held-out halves"; a calibration
  // too short to halve is checked on itself, "in-sample"). What model
  // misspecification and free-space model bias left do to an estimate where the
  // truth is known. Neither the covariance nor a residual bootstrap sees such an
  // error, so every trial's interval includes it.
  Eigen::Vector3d calibration_bias_m = Eigen::Vector3d::Zero();
  std::string calibration_check = "held-out halves";
  double calibration_offset_m = 0.0;  // D*, the calibration's known coaxial offset
  double bootstrap_block_s = 0.0;  // block length the calibration bootstrap used
  // d(parameters)/dD* by refitting at D* + calibration_offset_sd_m: how the
  // uncertainty of the known offset moves every trial alike.
  Eigen::Vector4d dparameters_dD_star = Eigen::Vector4d::Zero();
  Eigen::Vector3d dtorque_offset_dD_star = Eigen::Vector3d::Zero();
  double calibration_offset_sd_m = 0.0;
};

struct JointEstimatorOptions {
  double D_min = -0.020, D_max = 0.070;  // m, as the three-step method
  double radial_max = 0.040;             // m, bound of |dr_x|, |dr_y|
  std::vector<double> D_starts = {0.010, 0.030, 0.050};  // multi-start, m
  // Per-joint scale of the torque residual (N m, N m, N): the free-space model's
  // error. Residuals are divided by it.
  Eigen::Vector3d torque_sigma = Eigen::Vector3d(0.05, 0.05, 0.2);
  double huber_scale = 2.0;  // in units of sigma
  int bootstrap_replicates = 60;
  int calibration_bootstrap_replicates = 30;
  double bootstrap_block_s = 1.0;  // shortest block; longer when the residuals' memory is (see joint.cpp)
  // How well the calibration's coaxial offset D* is known (m, one sd). An
  // estimate cannot be more accurate than its reference: the tissue stiffness
  // scales with 1/D*, and with it every radial and coaxial estimate. Set it to
  // the bench's measurement accuracy; 0.1 mm is a careful phantom setup.
  double calibration_offset_sd_m = 1e-4;
  double sample_period_s = 0.005;
  // The free-space model's torque error on the arm as it is now (N m, N m, N),
  // e.g. measured at rest on the aligned baseline, where no tissue force acts:
  // an unmodelled payload or a model fitted on other data shows there. Each
  // trial's interval includes how far its estimate moves when its torque
  // residual is shifted by this much, joint by joint. 0: not known.
  Eigen::Vector3d torque_bias = Eigen::Vector3d::Zero();
  // Identify the free-space model's torque offset on the calibration with the
  // tissue parameters, and take it off every residual
  // (JointTissueModel::torque_offset).
  bool fit_torque_offset = true;
  unsigned seed = 1;
  int max_iterations = 100;
  void check() const;
};
const OptionTable<JointEstimatorOptions>& get_option_table(OptionTag<JointEstimatorOptions>);

// Step 2 in torque space: the tissue parameters on the calibration at the known
// D* (radial offset 0), with the free-space model's torque offset when
// options.fit_torque_offset. Both families are fitted; the stiffening one is
// chosen only when its BIC is lower, counting one effective sample per second of
// data (model errors are correlated over about that long). Then the held-out
// self-check (calibration_bias_m), the sensitivity to D* and the bootstrap.
JointTissueModel fit_joint_tissue_model(const IncisionFrame& incision, const std::vector<JointSample>& calibration,
                                        double D_star, const JointEstimatorOptions& options);

struct JointEstimate {
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();  // [dr_x, dr_y, D]
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();      // from Ceres, scaled
  // 95 % interval: the trial's residual bootstrap combined in quadrature with the
  // tissue parameters' uncertainty propagated through dp/dtissue, with the
  // systematic error seen on the calibration, with the uncertainty of D* and
  // with the free-space model's error measured off the trials (torque_bias).
  Eigen::Vector3d ci_low = Eigen::Vector3d::Zero(), ci_high = Eigen::Vector3d::Zero();
  Eigen::Vector3d sd_bootstrap = Eigen::Vector3d::Zero();  // half-width of the bootstrap interval / 1.96
  Eigen::Vector3d sd_tissue = Eigen::Vector3d::Zero();  // tissue parameters and torque offset
  Eigen::Vector3d sd_systematic = Eigen::Vector3d::Zero();  // |calibration_bias_m| of the tissue model
  // The calibration's error relative to D* (|calibration_bias_m| / D*) times
  // |estimate|: a free-space model that is off scales the force and with it
  // every offset, radial ones too, which a pure coaxial calibration cannot show
  // directly.
  Eigen::Vector3d sd_systematic_scale = Eigen::Vector3d::Zero();
  Eigen::Vector3d sd_calibration_offset = Eigen::Vector3d::Zero();  // through dparameters_dD_star
  Eigen::Vector3d sd_free_space_model = Eigen::Vector3d::Zero();    // through options.torque_bias
  int bootstrap_replicates = 0;
  double bootstrap_block_s = 0.0;  // block length used: twice the residuals' integrated autocorrelation time
  SolverReport solver;
  std::size_t samples = 0;
};

JointEstimate estimate_joint(const IncisionFrame& incision, const JointTissueModel& tissue,
                             const std::vector<JointSample>& samples, const JointEstimatorOptions& options);

// One JointSample from one streamed sample (make_joint_samples uses it too).
// Returns false, leaving `sample` unspecified, when the pivot exceeds
// max_theta_rad. No allocation.
bool compute_joint_sample(const IncisionFrame& incision, const Eigen::Vector3d& q, const Eigen::Vector3d& qd,
                          const Eigen::Vector3d& dtau, double max_theta_rad, JointSample& sample);

// The model's force f_inc_base for one sample: elastic + damping + axial friction.
Eigen::Vector3d compute_joint_model_force(const IncisionFrame& incision, const JointTissueModel& tissue,
                                          const JointSample& sample, const Eigen::Vector3d& misalignment_m);

// The model's torque for one sample (for tests and plots).
Eigen::Vector3d compute_joint_model_torque(const IncisionFrame& incision, const JointTissueModel& tissue,
                                           const JointSample& sample, const Eigen::Vector3d& misalignment_m);

}  // namespace rcm
