#pragma once
// What every live node does, whatever its middleware: the parameters, the
// pipeline built from a session and a saved model (as `rcm monitor` builds
// it), and per joint-state message what to publish and what to log. The ROS 1
// node and the DDS node each supply a MonitorSink (their publishers and their
// logger) and feed messages; the decisions (publish every n-th estimate, flags
// on change, status lines, the exit summary) live here once.
//
// Outputs, in the arm's namespace (`<arm>/rcm/...`): misalignment and
// misalignment_sd (Vector3Stamped, incision frame, m), incision_force
// (WrenchStamped, base frame, N), onset, alarm, out_of_regime (Bool, latched),
// rejected_samples (UInt64, latched), correction (Vector3Stamped, base frame,
// m: the RCM move onto the incision) and advice (String, latched: hold,
// compensate or reposition in words, estimation/correction.hpp). The node
// advises: it never moves the arm, so no software shift is in effect; unless
// the arm shifts its RCM in software (software_rcm): then the node commands
// that shift (shift, Vector3Stamped, base frame, m: the shift to hold, in all
// since the node started), gated and rate-limited by the correction, and takes
// it as in effect, as CorrectionLoop does in one process.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/regime.hpp"
#include "rcm/estimation/correction.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/live/live_monitor.hpp"

namespace rcm {

// The node parameters, one declaration for every node (docs/cli-programs.md).
struct MonitorNodeParameters {
  std::string session, model_file;
  std::string tissue_model_file;  // tissue_model.json of `rcm setup`; empty: identified on the calibration
  std::string arm = "PSM1";
  std::vector<std::string> joint_names;  // empty: the first message's order
  double alarm_force_n = OnlineEstimatorOptions{}.alarm_force_n;
  double onset_threshold = OnlineEstimatorOptions{}.onset_threshold;
  int publish_every = 1;
  int queue_size = 1000;
  std::string base_frame, incision_frame;  // empty: <arm>_base, <arm>_incision
  bool dedupe = false;
  int seed = 1;
  double status_period_s = 5.0;
  // The correction's gates (parameters tolerance_m, compensate_limit_m, max_shift_rate_m_per_s).
  CorrectionOptions correction;
  // The estimator's change-point test (OnlineEstimatorOptions::jump_threshold,
  // nats; 0: off), for an incision that may jump.
  double jump_threshold = OnlineEstimatorOptions{}.jump_threshold;
  // The arm moves its RCM setpoint to the shift this node commands (a
  // software-RCM arm, or the simulated PSM with --software-rcm).
  bool software_rcm = false;

  // Throws InputError at `where(name)` for a missing or out-of-range value.
  void check(const std::function<InputLocation(const std::string&)>& where) const;
  std::string get_base_frame() const { return base_frame.empty() ? arm + "_base" : base_frame; }
  std::string get_incision_frame() const { return incision_frame.empty() ? arm + "_incision" : incision_frame; }
  // "<arm>/rcm/" ("rcm/" without an arm) and "<arm>/measured_js".
  std::string get_output_prefix() const { return arm.empty() ? std::string("rcm/") : arm + "/rcm/"; }
  std::string get_input_topic() const { return arm.empty() ? std::string("measured_js") : arm + "/measured_js"; }
};

// Joint names from a comma-separated string ("outer_yaw,outer_pitch,..."; brackets
// and quotes ignored); checked non-empty and unique, errors at `where`.
std::vector<std::string> parse_joint_names(const std::string& text, const InputLocation& where);

// Everything `rcm monitor --session S --model-file M` builds before replaying;
// `description` receives a line on the models for the node's log.
std::unique_ptr<OnlinePipeline> make_monitor_pipeline(const MonitorNodeParameters& parameters,
                                                      std::string* description = nullptr);

enum class MonitorFlag { onset, alarm, out_of_regime };
enum class LogLevel { info, warn, error };

// The middleware's side of a node.
class MonitorSink {
 public:
  virtual ~MonitorSink() = default;
  // misalignment, misalignment_sd and incision_force, all with `stamp_ns`, the
  // time of the sample the estimate is for (LiveMonitor::get_output_time_ns).
  virtual void publish_estimate(std::int64_t stamp_ns, const OnlineOutput& output) = 0;
  virtual void publish_flag(MonitorFlag flag, bool value) = 0;
  virtual void publish_rejected(std::uint64_t total) = 0;
  // correction, with `stamp_ns`: the RCM move onto the incision, base frame.
  // Called just before publish_estimate with the same stamp.
  virtual void publish_correction(std::int64_t stamp_ns, const CorrectionOutput& correction) = 0;
  // advice (latched): the action in words, each time it changes.
  virtual void publish_advice(const std::string& text) = 0;
  // shift, with `stamp_ns`, only with software_rcm: the software shift of the
  // RCM setpoint to hold (base frame, m), after the correction at that stamp.
  // Called just before publish_estimate. A sink for an arm that cannot shift
  // its RCM leaves it out.
  virtual void publish_shift(std::int64_t /*stamp_ns*/, const Eigen::Vector3d& /*shift_base*/) {}
  // `throttle_s` > 0: the sink may drop lines of the same call site closer than that.
  virtual void log(LogLevel level, const std::string& text, double throttle_s = 0.0) = 0;
};

class MonitorNode {
 public:
  // `pipeline` from make_monitor_pipeline; `sink` must outlive the node.
  MonitorNode(const MonitorNodeParameters& parameters, std::unique_ptr<OnlinePipeline> pipeline,
              LiveMonitor::ZeroStamp zero_stamp, MonitorSink& sink);

  // Publishes the latched outputs' initial values and logs what the node does.
  void start(const std::string& input_topic_name);
  // One joint-state message (`stamp_ns` 0 for a zero stamp). No allocation once
  // the first message is accepted, except to log.
  void compute_message(const JointStateView& message, std::int64_t stamp_ns, std::int64_t receive_time_ns);

  const LiveMonitor& get_monitor() const { return monitor_; }
  // The exit summary: counts, per-sample timing, regime, final estimate (lines).
  std::string get_summary() const;

 private:
  struct TimingStats {
    std::uint64_t count = 0;
    double sum_s = 0.0, max_s = 0.0;
    void add(double s);
    double mean_us() const { return count ? 1e6 * sum_s / static_cast<double>(count) : 0.0; }
  };
  void on_first_sample(std::int64_t stamp_ns);
  void on_rejected(LiveMonitor::Verdict verdict, const JointStateView& message, std::int64_t stamp_ns);
  void on_gap(std::int64_t stamp_ns);

  MonitorNodeParameters params_;
  std::unique_ptr<OnlinePipeline> pipeline_;
  LiveMonitor monitor_;
  RcmCorrector corrector_;
  RcmCorrector::Workspace correction_ws_;
  MonitorSink& sink_;
  bool onset_ = false, alarm_ = false, out_of_regime_ = false;
  Eigen::Vector3d shift_base_ = Eigen::Vector3d::Zero();  // the software shift commanded (software_rcm)
  std::uint64_t shift_moves_ = 0;
  std::uint64_t retimed_ = 0;
  std::uint64_t updates_ = 0;  // OnlineOutput::updates of the last estimate handled
  dynamics::RegimeSummary regime_;
  int since_publish_ = 0;
  double next_status_s_ = 0.0;
  TimingStats step_, callback_;
};

}  // namespace rcm
