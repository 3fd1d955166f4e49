#pragma once
// Online misalignment estimation (beyond the paper): the joint torque-space
// model of joint.hpp, run as a bank of extended Kalman filters on the offsets
// p = [dr_x, dr_y, D] (incision frame) that update sample by sample, with onset
// detection and a force alarm.
//
//   state      p_k = p_{k-1} + w,  w ~ N(0, Q dt)     (the incision drifts slowly)
//   measurement dtau_k = tau_k - tau_fs,k = h(p_k; q, qd) + v
//
// h is exactly the batch model (compute_joint_model_torque), differentiated with
// ceres::Jet. Three choices make it behave on real data:
// - Free-space model errors are correlated over about a second, so one sample is
//   not an independent measurement: the measurement variance is sigma^2 tau_c/dt,
//   which makes the information gathered per second independent of the sampling
//   rate (200 Hz logs and the 1.5 kHz robot behave alike) and keeps the
//   covariance honest. dt is capped at tau_c: after a gap in the stream a
//   sample is one independent measurement, not the gap's worth of data.
// - (D, r) and (-D, -r) and other poor linearization points are local traps: a
//   small bank of filters starts at several D (as the batch multi-start) and the
//   one with the lowest exponentially forgotten innovation cost is reported.
// - Onset: a CUSUM of the robust log-likelihood ratio of the best filter's
//   one-step prediction against "no misalignment" (p = 0: no stretch, but the
//   shaft's sliding friction in the tissue remains). The prediction uses the
//   state before the sample, so the statistic is not fitted to what it tests.
// - Jumps: the random walk follows a slow drift, but a patient or table that
//   moves shifts the incision at once. A settled filter, its covariance small
//   and near p = 0 blind to first order (the torque about the RCM is the
//   force times the coaxial offset, both proportional to p), would follow in
//   tens of seconds. A CUSUM watches the reported filter's robust innovation
//   cost against its own recent level (its forgotten mean): a sustained excess, in
//   nats per correlation time, means the offsets the filter holds no longer
//   explain the torques. The bank then restarts from the prior (D_starts,
//   initial_*_sd_m), as after reset, and re-converges from the data in a few
//   seconds of motion. The filter reported before stays in the bank: when
//   nothing moved (a transient the free-space model missed) it keeps
//   explaining the torques best and stays reported, where restarted filters
//   would be pulled for seconds to wherever the transient points. While it is
//   reported its level is still a level, so the test runs again after a
//   short holdoff: a real change just after such a restart is caught at once.
//   A residual the model never explained (an unseen payload) keeps its level
//   and does not feed it; rest samples do not either.
// - At rest the free-space model's error is the stiction band, a constant torque
//   that a radial offset would explain just as well (friction memory): rest
//   samples weigh less (sigma times rest_sigma_factor) and do not feed the onset
//   test, which therefore needs the configuration-dependent force of motion.
// The alarm compares the force of the reported model at the current sample with
// a threshold (default 10 N, paper V-E), with hysteresis, once onset is detected.
//
// The model (OnlineEstimator) is immutable; everything that changes lives in an
// OnlineWorkspace of fixed size. compute_online_update() does not allocate.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "rcm/dynamics/regime.hpp"
#include "rcm/dynamics/torque_model.hpp"

#include "rcm/estimation/joint.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/kinematics/incision.hpp"

namespace rcm {

struct OnlineEstimatorOptions {
  double D_min = -0.020, D_max = 0.070;  // m, as the batch estimators
  double radial_max = 0.040;             // m, bound of |dr_x|, |dr_y|
  std::vector<double> D_starts = {0.010, 0.030, 0.050};  // one filter each (at most kMaxHypotheses)
  Eigen::Vector3d torque_sigma = Eigen::Vector3d(0.05, 0.05, 0.2);  // free-space model error, N m, N m, N
  double correlation_time_s = 1.0;       // of the free-space model error
  double huber_scale = 3.0;              // innovations beyond this many sigma are down-weighted
  double initial_radial_sd_m = 0.020;
  double initial_D_sd_m = 0.030;
  double drift_sd_m_per_sqrt_s = 2e-4;   // random walk of the incision (patient motion)
  // A gap in the stream accrues the drift of at most this long. The random walk
  // models the incision's slow motion while the arm is watched; a silence says
  // nothing about how long the incision moved, and a prior widened by minutes of
  // drift lets the first samples' correlated free-space error throw a settled
  // estimate by centimetres (the stream soak, docs/reliability.md).
  double max_drift_gap_s = 10.0;
  double hypothesis_memory_s = 10.0;     // forgetting time of each filter's innovation cost
  double onset_threshold = 10.0;         // CUSUM threshold, nats per correlation time
  // The change-point test (0: off, the default): CUSUM threshold on the
  // reported filter's robust innovation cost above its recent level plus
  // jump_allowance, in nats per correlation time. 4 passes a 10 mm step within
  // a few seconds of motion on the closed-loop bench (which turns it on:
  // make_closed_loop_online_options) and never fires there at rest, moving
  // aligned, or on the drift. Off by default: on the study's trials, where the
  // incision does not move, it restarted the bank and left the streamed
  // estimates worse and later settled than without it (the demo table).
  double jump_threshold = 0.0;
  // Nats per sample above that level that count. A matched model's sample
  // cost scatters about its level by about one (a chi-square of 3, halved).
  double jump_allowance = 1.0;
  // After a reset or a restart the test waits this long: a converging bank's
  // costs are not yet a level to compare with (the filter kept from before a
  // restart excepted, while it is reported).
  double jump_holdoff_s = 10.0;
  // ... and this long while the filter kept from before the restart is
  // reported: its level is still a level.
  double kept_holdoff_s = 0.2;
  double alarm_force_n = 10.0;           // paper V-E
  double alarm_clear_fraction = 0.9;     // the alarm clears below this fraction of the threshold
  double max_theta_rad = 80.0 * M_PI / 180.0;
  double rest_angular_speed = 0.01;  // rad/s, joints 1-2: below both (and the next), the arm is at rest
  double rest_linear_speed = 0.002;  // m/s, joint 3
  double rest_sigma_factor = 3.0;
  // Samples closer than this in time are treated as this far apart (dt = 0 at
  // the first sample and repeated stamps would otherwise weigh infinitely).
  double min_dt_s = 1e-4;
  void check() const;
};
const OptionTable<OnlineEstimatorOptions>& get_option_table(OptionTag<OnlineEstimatorOptions>);

// What the estimator says after a sample.
struct OnlineOutput {
  // Samples estimated since the reset. 0: the reset output (the prior's
  // estimate, `time` no sample's), which a pipeline whose model's torque
  // trails returns until the stream is that long. A caller streaming through
  // OnlinePipeline tells a new estimate from a repeated one by this count: a
  // call may bring none (the delay's first samples, or the delay after a gap
  // in the stream), or several (the samples left before a gap, or two when
  // jittered stamps move the delay's target past both); the output is then
  // the last one's, with the alarm events of all.
  std::uint64_t updates = 0;
  double time = 0.0;  // of the sample the estimate is for
  bool used = false;                 // false: the pivot was beyond max_theta_rad
  bool at_rest = false;
  // The reported filter: its start's index in D_starts, or D_starts.size()
  // for the one kept from before the last change-point restart.
  int hypothesis = 0;
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();  // [dr_x, dr_y, D], incision frame
  Eigen::Vector3d sd_m = Eigen::Vector3d::Zero();            // sqrt of the covariance diagonal
  // The covariance of misalignment_m (m^2, incision frame): the spread along
  // a direction that mixes the axes (u^T C u) is not in sd_m, the axes'
  // errors being correlated.
  Eigen::Matrix3d covariance_m2 = Eigen::Matrix3d::Zero();
  Eigen::Vector3d f_inc_base = Eigen::Vector3d::Zero();      // the model's force now, base frame
  double force_norm_n = 0.0;
  double cusum = 0.0;
  // The change-point test: its CUSUM (nats per correlation time), how many
  // restarts it has made since reset, and when the last one was.
  double jump_cusum = 0.0;
  int jumps = 0;
  double jump_time = 0.0;
  // How well the reported filter explains the residual: the forgotten mean of
  // its robust loss rho(|S^-1/2 nu|) per sample since the filter started
  // (normalized for the samples seen), S = H P H^T + diag(sigma^2) the spread
  // the filter predicts for its innovation nu. About 1.5 (half a chi-square of
  // 3) when the model and the free-space model's error scale fit the data; a
  // residual the tissue model cannot explain (a payload the free-space model
  // never saw) raises it once the filter is sure of its offsets. A filter
  // still converging predicts its innovations' spread and is not charged for
  // them: a restart (the change-point test) does not read as a mismatch.
  double fit_cost = 0.0;
  bool onset = false;                // onset detected (at or before this sample)
  double onset_time = 0.0;
  bool alarm = false;                // force above the threshold now
  bool alarm_raised = false;         // ... and this is the sample it rose
  bool alarm_cleared = false;
  // The sample left the free-space model's training regime (dynamics/regime.hpp):
  // which joint and quantity, or a torque residual the models do not explain
  // (fit_cost above RegimeCheckOptions::max_fit_cost for its
  // residual_persistence_s), and whether any. The
  // estimate is computed as always; its torque residual is not covered by what
  // the model saw.
  std::uint32_t regime_flags = 0;
  bool out_of_regime = false;
};

class OnlineEstimator {
 public:
  static constexpr int kMaxHypotheses = 4;  // starts (D_starts)

  struct Hypothesis {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
    double cost = 0.0;  // exponentially forgotten mean of the robust loss of the innovation
    // The same loss of the innovation against its predicted spread (the
    // free-space model's error and the filter's own uncertainty, H P H^T),
    // forgotten alike with its own weight: since the filter started, so that
    // a filter restarted from the prior is not charged for converging.
    double fit = 0.0;
    double fit_weight = 0.0;
  };
  struct Workspace {
    // The restarted starts, then (after a change-point restart) the filter
    // reported before it.
    std::array<Hypothesis, kMaxHypotheses + 1> hypotheses;
    int num_hypotheses = 0;
    double jump_armed_at = 0.0;  // the change-point test runs from this time on
    double kept_armed_at = 0.0;  // ... or from this time on while the kept filter is reported
    double cost_weight = 0.0;  // the forgotten weight of the samples in the costs
    bool started = false;
    double last_time = 0.0;
    OnlineOutput output;
  };

  OnlineEstimator(const IncisionFrame& incision, const JointTissueModel& tissue, const OnlineEstimatorOptions& options);

  Workspace create_workspace() const;
  void reset(Workspace& workspace) const;

  // One sample: time (s, increasing), joints 1-3 position and velocity, and the
  // torque residual tau - tau_fs (N m, N m, N). No allocation.
  const OnlineOutput& compute_update(Workspace& workspace, double time, const Eigen::Vector3d& q,
                                     const Eigen::Vector3d& qd, const Eigen::Vector3d& dtau) const;

  // The RCM itself moved by shift_base (base frame; a software RCM shift, e.g.
  // estimation/correction.hpp's): every filter's offsets, relative to the RCM,
  // move by -R_base_inc^T shift_base. The shift is known, so the covariances stay.
  void apply_rcm_shift(Workspace& workspace, const Eigen::Vector3d& shift_base) const;
  const IncisionFrame& incision() const { return incision_; }
  const JointTissueModel& tissue() const { return tissue_; }
  const OnlineEstimatorOptions& options() const { return options_; }

 private:
  void restart_hypotheses(Workspace& workspace, int incumbent) const;

  IncisionFrame incision_;
  JointTissueModel tissue_;
  OnlineEstimatorOptions options_;
  Eigen::Vector3d measurement_variance_;  // sigma^2 tau_c (divided by dt per sample)
};

inline const OnlineOutput& get_online_output(const OnlineEstimator::Workspace& workspace) { return workspace.output; }

// The same options as a batch estimate, so that the two agree on bounds and scales.
OnlineEstimatorOptions make_online_options(const JointEstimatorOptions& joint);

// The whole per-sample path of a live robot: measured joint state and effort in,
// the free-space model stepped with its state carried, the residual into the
// estimator. What the ROS node and `rcm monitor` run. No allocation per sample.
class OnlinePipeline {
 public:
  struct Workspace {
    std::unique_ptr<dynamics::TorqueModelWorkspace> model;
    OnlineEstimator::Workspace estimator;
    std::vector<double> tau_fs;  // num_outputs
    // The last samples [time, q 1-3, qd 1-3, effort 1-3, RCM shift 1-3 (what
    // apply_rcm_shift had declared before the sample)] for a model whose
    // torque trails its input (get_output_delay_s() > 0): as many as that
    // delay spans at 2 kHz, and at least d + 1; empty without a delay.
    std::vector<double> delay_line;
    int delay_next = 0, delay_filled = 0;
    int delay_back = 1;  // the last pick's distance from the newest sample (find_delayed_sample's hint)
    // The time of the last sample estimated since the stream (re)started
    // (NaN: none), so that no sample is estimated twice; a time that goes
    // back ends the stream and starts another.
    double delay_last_time = std::numeric_limits<double>::quiet_NaN();
    // With a delay: the RCM shifts declared so far, and those the estimator
    // has taken (it reaches a shift with the first sample taken after it).
    Eigen::Vector3d shift_declared_base = Eigen::Vector3d::Zero();
    Eigen::Vector3d shift_applied_base = Eigen::Vector3d::Zero();
    dynamics::RegimeMonitor::Workspace regime;
    // Since when the fit cost has been above the regime's max_fit_cost (NaN: not).
    double residual_since = std::numeric_limits<double>::quiet_NaN();
  };

  // Throws std::invalid_argument when the model predicts fewer than 3 joints.
  OnlinePipeline(std::shared_ptr<const dynamics::TorqueModel> model, OnlineEstimator estimator,
                 const dynamics::RegimeCheckOptions& regime_options = {});

  Workspace create_workspace() const;
  void reset(Workspace& workspace) const;

  // q, qd, effort: at least model.num_joints() values (joint 3 in m, m/s, N).
  // With a model whose torque trails by get_output_delay_s() (d samples at its
  // training rate), the update is for the sample that long before, with its
  // own joint state and effort (OnlineOutput::time says which); until the
  // stream is that long, calls return the reset output.
  const OnlineOutput& compute_sample(Workspace& workspace, double time, const double* q, const double* qd,
                                     const double* effort) const;

  // The RCM moved by shift_base before the next sample (OnlineEstimator::
  // apply_rcm_shift). With a model whose torque trails, the estimate is for a
  // sample taken that long before, with the RCM where it was then: the
  // estimator takes the shift when it reaches the first sample taken after it,
  // and until then each output's misalignment_m is given relative to the RCM
  // as it is now (less the shifts still to come).
  void apply_rcm_shift(Workspace& workspace, const Eigen::Vector3d& shift_base) const;
  const dynamics::TorqueModel& model() const { return *model_; }
  const OnlineEstimator& estimator() const { return estimator_; }
  // Built from the model's training regime; known() is false when it has none.
  const dynamics::RegimeMonitor& regime_monitor() const { return regime_; }

 private:
  std::shared_ptr<const dynamics::TorqueModel> model_;
  OnlineEstimator estimator_;
  dynamics::RegimeMonitor regime_;
  double max_fit_cost_, residual_persistence_s_;

  // One estimator update for a sample with the model's torque tau_fs; with a
  // delay line, shift_base is the RCM shift declared before that sample.
  void update_estimate(Workspace& workspace, double time, const double* q, const double* qd, const double* effort,
                       const double* tau_fs, const double* shift_base = nullptr) const;
  // The output of the call, its misalignment relative to the RCM as it is now.
  const OnlineOutput& finish_output(Workspace& workspace) const;
};

// A whole recording streamed through a pipeline, as `rcm monitor` and the study
// replay it, with the measures of its accuracy and timing.
struct OnlineAlarm {
  double raised_s = 0.0;
  std::optional<double> cleared_s;
  double peak_force_n = 0.0;
};
struct OnlineReplay {
  std::size_t samples = 0;
  // Samples estimated, each once: all but the last of a delay (a model whose
  // torque trails estimates the sample that long before the newest).
  std::size_t estimates = 0;
  OnlineOutput final_output;
  std::optional<double> motion_start_s;  // first sample with |qd_1,2| > motion_speed
  std::optional<double> onset_s;
  // From the first motion, how long until the running estimate stays within
  // settle_band_m of its final value for good.
  std::optional<double> settled_after_s;
  std::vector<OnlineAlarm> alarms;
  double peak_force_n = 0.0;
  double mean_update_s = 0.0, max_update_s = 0.0;  // wall clock per sample, pipeline included
  dynamics::RegimeSummary regime;  // samples outside the free-space model's training regime
};
struct OnlineReplayOptions {
  double settle_band_m = 0.005;
  double motion_speed = 0.01;  // rad/s
};
const OptionTable<OnlineReplayOptions>& get_option_table(OptionTag<OnlineReplayOptions>);
OnlineReplay replay_online(const OnlinePipeline& pipeline, const Recording& recording,
                           const OnlineReplayOptions& options = {},
                           const std::function<void(const OnlineOutput&)>& on_sample = {});

// The same over a recording given in chunks (io/recording_reader.hpp), in
// memory that does not grow with its length: add() every chunk in order, then
// finish() gives what replay_online() gives over the whole recording. The
// settling time needs the whole run's trace: it goes to a temporary file (32
// bytes per sample), read back only where the estimate left the band last.
class OnlineReplayer {
 public:
  OnlineReplayer(const OnlinePipeline& pipeline, const OnlineReplayOptions& options = {},
                 std::function<void(const OnlineOutput&)> on_sample = {});
  ~OnlineReplayer();
  OnlineReplayer(const OnlineReplayer&) = delete;
  OnlineReplayer& operator=(const OnlineReplayer&) = delete;
  // Throws InputError when the chunk has fewer joints than the model reads.
  void add(const Recording& chunk);
  OnlineReplay finish();

 private:
  struct Trace;
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const OnlinePipeline& pipeline_;
  OnlineReplayOptions options_;
  std::function<void(const OnlineOutput&)> on_sample_;
  OnlinePipeline::Workspace ws_;
  std::unique_ptr<Trace> trace_;
  OnlineReplay out_;
  RowMajor q_, qd_, effort_;
  double total_s_ = 0.0;
  std::uint64_t updates_ = 0;
};

}  // namespace rcm
