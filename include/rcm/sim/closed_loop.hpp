#pragma once
// The closed-loop bench: the simulated arm as a software-RCM arm (its pivot a
// setpoint, the same joint-space dynamics) under teleoperation, an incision
// that moves (a step, a slow drift, breathing, a large step), and the online
// estimator with the correction (estimation/correction.hpp) in the loop,
// against the same run with the RCM left where it was docked.
//
// Approximation: moving the pivot changes where the joints pivot, not the
// joint-space dynamics. The tissue sees the pivot move (its damping and axial
// friction), as it sees the patient move.
#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "rcm/common/options.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/io/plot.hpp"
#include "rcm/sim/sim_config.hpp"

namespace rcm::sim {

// Where the incision is relative to where the arm was docked (incision frame):
// offset_m, plus step_m from step_time_s on, plus a drift from drift_start_s to
// drift_end_s, plus breathing (a sine of breathing_amplitude_m).
struct IncisionMotion {
  std::string name;
  Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d step_m = Eigen::Vector3d::Zero();
  double step_time_s = 0.0;
  Eigen::Vector3d drift_m_per_s = Eigen::Vector3d::Zero();
  double drift_start_s = 0.0, drift_end_s = 0.0;
  Eigen::Vector3d breathing_amplitude_m = Eigen::Vector3d::Zero();
  double breathing_hz = 0.0;
  // When the incision starts to leave the RCM: the clock of the force measures.
  double onset_s = 0.0;
  // The software shift the arm allows in this scenario (0: the bench's
  // CorrectionOptions::compensate_limit_m), in both runs.
  double compensate_limit_m = 0.0;
  // How fast the arm may shift its software RCM here (0: the bench's
  // CorrectionOptions::max_rate_m_per_s).
  double max_rate_m_per_s = 0.0;
  Eigen::Vector3d get_misalignment(double t) const;
  // d/dt of get_misalignment, leaving out the step's jump (instantaneous: the
  // tissue's damping is not asked to absorb it).
  Eigen::Vector3d get_misalignment_rate(double t) const;
  // The bench's gates with this scenario's limit and rate where it sets them.
  // Throws std::invalid_argument for a negative limit or rate.
  CorrectionOptions get_correction_options(const CorrectionOptions& bench) const;
};

// step (the patient or table moves 10 mm at 20 s), drift (0.15 mm/s for 60 s
// from 10 s: 9 mm), breathing (a 6 mm offset from the start, with 3 mm of
// breathing at 0.25 Hz along the insertion axis) and large_step (35 mm at
// 20 s: 30 mm deeper, 10 and 15 mm across, on an arm whose software RCM may
// move 50 mm at 20 mm/s; beyond the default 10 mm the corrector advises
// re-docking, and at the default 5 mm/s the move alone takes 7 s).
std::vector<IncisionMotion> make_default_incision_motions();

struct ClosedLoopOptions {
  double duration_s = 90.0;
  double settled_after_s = 30.0;  // from the motion's onset: the RMS force is over what follows
  double force_threshold_n = 2.0;  // time_to_below: from onset until |f| stays below this
  double series_rate_hz = 20.0;    // of the time series kept for the figures
  bool teleoperation = true;       // false: the arm holds at q0 (no motion, no information)
  // The loop as it runs across processes (the simulated PSM, the monitor and
  // the procedure over DDS), one difference at a time:
  // - stream_rate_hz: the rate the estimator reads the arm (0: the
  //   configuration's sensors.log_rate_hz); the physics then runs at the
  //   smallest whole multiple of it at or above the configuration's rate, as
  //   the simulated PSM's does;
  // - loop_delay_s: the arm's time from a sample to the RCM shift it leads to
  //   being in effect on the arm (the sample's way to the estimator, the
  //   estimate, the command's way back). The estimator takes the shift the arm
  //   reports with each sample, and the corrector counts the part on its way
  //   as made (RcmCorrector::compute_correction), as the monitor does; the
  //   moves are metered when they take effect, as across processes;
  // - teleoperation_stream: the draw of the surgeon's motion
  //   (derive_seed(seed, "path:" + stream)); the simulated PSM's n-th spell of
  //   teleoperation is "teleop:n".
  double stream_rate_hz = 0.0;
  double loop_delay_s = 0.0;
  std::string teleoperation_stream = "closed-loop";
  CorrectionOptions correction;
  // Throws std::invalid_argument for a value out of range.
  void check() const;
};
const OptionTable<ClosedLoopOptions>& get_option_table(OptionTag<ClosedLoopOptions>);

struct ClosedLoopRun {
  bool closed = false;
  double peak_force_n = 0.0;             // max |f| from the onset
  double rms_force_after_settle_n = 0.0;
  // From the onset until |f| stays below force_threshold_n to the end (none:
  // it never does, or not for the last 5 s).
  std::optional<double> time_to_below_s;
  double residual_misalignment_m = 0.0;  // mean |incision - RCM| over the last 10 s
  int wrong_direction_moves = 0;         // commanded steps against the true remaining misalignment
  int moves = 0;                         // commanded steps (carried out in the closed run only)
  double max_fit_cost = 0.0;             // the estimate's largest fit cost from the onset
  Eigen::Vector3d final_shift_base = Eigen::Vector3d::Zero();
  // At the end: the estimate (relative to the RCM as it then is), the true
  // misalignment, and the re-docking check's words on that estimate.
  Eigen::Vector3d final_estimate_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d final_truth_m = Eigen::Vector3d::Zero();
  std::string alignment;
  // How well the estimate's 95 % intervals describe its error over the settled
  // part (from the onset plus settled_after_s), per axis [dr_x, dr_y, D]: the
  // RMS of (estimate - truth) / sd (1 for intervals as wide as the errors,
  // below 1 for wider ones) and the share of samples the interval covers.
  Eigen::Vector3d interval_rms_z = Eigen::Vector3d::Zero();
  Eigen::Vector3d interval_coverage = Eigen::Vector3d::Zero();
  // Time series at series_rate_hz: true |f|, true |incision - RCM|, the action.
  std::vector<double> time_s, force_n, misalignment_m;
  std::vector<CorrectionAction> action;
  // Every change of the advice: (time, words).
  std::vector<std::pair<double, std::string>> advice;
};

// The figures of ClosedLoopRun that come from the truth, sample by sample:
// the one home of their definitions, for the bench (run_closed_loop_experiment)
// and for a loop closed across processes (the simulated PSM, the monitor and
// the procedure over DDS). Times are from the run's start.
class ClosedLoopMeter {
 public:
  // `onset_s`: when the incision starts to leave the RCM; `duration_s`: the
  // run's end (time to below counts only a force that stays below over its last 5 s).
  ClosedLoopMeter(double onset_s, double duration_s, const ClosedLoopOptions& options);
  // One sample: the true |f| (N) and the true misalignment left, |incision - RCM| (m).
  void add_sample(double t, double force_n, double remaining_m);
  // A software shift of the RCM (base frame), against the true misalignment
  // left just before it (base frame): a move, and a wrong one if it points away.
  void add_move(const Eigen::Vector3d& step_base, const Eigen::Vector3d& remaining_base);
  // peak_force_n, rms_force_after_settle_n, time_to_below_s,
  // residual_misalignment_m, moves, wrong_direction_moves.
  void get_figures(ClosedLoopRun& run) const;

 private:
  double onset_s_, duration_s_, settled_after_s_, threshold_n_;
  double peak_n_ = 0.0, sum_sq_after_settle_ = 0.0, last_above_s_ = -1.0, residual_sum_ = 0.0;
  std::size_t after_settle_ = 0;
  int residual_count_ = 0, moves_ = 0, wrong_ = 0;
};

struct ClosedLoopScenario {
  IncisionMotion motion;
  ClosedLoopRun open, closed;
};

// The online estimator's options on the closed-loop bench: the study's, with
// the change-point test on (a threshold of 4), since the incision jumps there.
OnlineEstimatorOptions make_closed_loop_online_options(const JointEstimatorOptions& joint);

// Runs every motion open and closed loop with `pipeline` (prepared on this
// config's session: free-space model, incision frame at q0, tissue model).
std::vector<ClosedLoopScenario> run_closed_loop_experiment(const SimConfig& config, const OnlinePipeline& pipeline,
                                                           const std::vector<IncisionMotion>& motions,
                                                           const ClosedLoopOptions& options);

// closed_loop.json: {"scenarios": {"step": {"open": {...}, "closed": {...}}, ...}}
// with peak_force_n, rms_force_after_settle_n, time_to_below_2n_s (null if
// never), residual_misalignment_m, wrong_direction_moves per run.
nlohmann::json to_json(const std::vector<ClosedLoopScenario>& scenarios, const ClosedLoopOptions& options);
std::string format_closed_loop_table(const std::vector<ClosedLoopScenario>& scenarios);
// Three figures per scenario (stem_force, stem_misalignment, stem_advice): true
// |f| and true misalignment against time in both runs, and the action.
std::vector<PlotFiles> save_closed_loop_plots(const std::filesystem::path& stem, const ClosedLoopScenario& scenario);

}  // namespace rcm::sim
