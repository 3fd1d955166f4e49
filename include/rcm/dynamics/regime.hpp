#pragma once
// The regime a free-space model was fitted on, and the per-sample check that the
// arm is still inside it.
//
// A free-space model is trustworthy where its data went: on the real PSM a model
// fitted at one speed mispredicts at twice the velocity and four times the
// acceleration by 0.2-0.3 N m (docs/validation-free-space.md), 6-10 N at the incision at
// D = 30 mm. Every offset the estimator reports downstream of such a torque is
// confidently wrong, so the live path flags each sample whose position,
// velocity or acceleration leaves what the fit saw (with a margin), and the
// reports count them.
//
// Acceleration comes from one causal estimate used both at fit time and live: the
// first-order low-pass (time constant acceleration_filter_s) of the backward
// difference of the measured velocity, in seconds, so any sampling rate gives
// the same figure.

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"

namespace rcm::dynamics {

struct TrainingRegime {
  // Per joint read by the model (its first joints: the linear model's 1-3, a
  // network's every joint); all empty: unknown (a model file
  // written without it, or an imported network), and nothing is checked.
  Eigen::VectorXd position_min, position_max;  // rad, m
  Eigen::VectorXd velocity_min, velocity_max;  // rad/s, m/s
  Eigen::VectorXd acceleration_abs_max;        // rad/s^2, m/s^2, of the estimate above
  double acceleration_filter_s = 0.03;
  std::size_t samples = 0;

  bool empty() const { return position_min.size() == 0; }
  int num_joints() const { return static_cast<int>(position_min.size()); }
};

// The regime of every sample of `recordings` (the data a fit was given), over
// the first `num_joints` joints.
TrainingRegime compute_training_regime(const std::vector<Recording>& recordings, int num_joints,
                                       double acceleration_filter_s = 0.03);

nlohmann::json regime_to_json(const TrainingRegime& regime);
// Throws InputError naming `source` and the field.
TrainingRegime regime_from_json(const nlohmann::json& j, const std::string& source);

// How far beyond the training range a sample may go before it is flagged, as a
// fraction of that range (position) or of the largest magnitude seen (velocity,
// acceleration). Interpolation inside the range is the model's job; these
// margins only forgive the noise at its edges.
struct RegimeCheckOptions {
  double position_margin = 0.05;
  double velocity_margin = 0.10;
  double acceleration_margin = 0.25;
  // A payload the free-space model never saw, or a model fitted on another
  // arm, stays inside the positions and speeds it was fitted on; what gives it
  // away is a torque residual that no incision force explains. The online
  // estimate's fit cost (OnlineOutput::fit_cost, about 1.5 when the models
  // explain the torques; 27-43 in the test stream of
  // OnlinePipeline.FlagsATorqueResidualNoIncisionForceExplains, with 200 g the
  // model never saw) above this for residual_persistence_s flags the samples
  // (kResidualRegimeBit).
  double max_fit_cost = 10.0;
  double residual_persistence_s = 2.0;
  void check() const;
};

// Bit 3 j + k of the flags: joint j (0-based) outside the regime in position
// (k = 0), velocity (1) or acceleration (2). At most kMaxRegimeJoints joints.
// Bit kResidualRegimeBit: the torque residual is not what the models explain.
constexpr int kMaxRegimeJoints = 10;
constexpr int kResidualRegimeBit = 3 * kMaxRegimeJoints;
constexpr int kRegimeBits = kResidualRegimeBit + 1;
enum class RegimeQuantity { position = 0, velocity = 1, acceleration = 2 };
inline std::uint32_t regime_bit(int joint, RegimeQuantity quantity) {
  return std::uint32_t{1} << (3 * joint + static_cast<int>(quantity));
}
inline std::uint32_t get_residual_regime_flag() { return std::uint32_t{1} << kResidualRegimeBit; }
// "joint 1 velocity, joint 3 position"; "" for 0.
std::string describe_regime_flags(std::uint32_t flags);

// Immutable checker; the changing part (last velocity, acceleration estimate)
// lives in its Workspace. compute_flags() does not allocate.
class RegimeMonitor {
 public:
  struct Workspace {
    Eigen::VectorXd last_velocity, acceleration;
    double last_time = 0.0;
    bool started = false;
  };

  // An empty regime gives a monitor that never flags (known() is false).
  RegimeMonitor(TrainingRegime regime, const RegimeCheckOptions& options = {});

  bool known() const { return !regime_.empty(); }
  const TrainingRegime& regime() const { return regime_; }
  Workspace create_workspace() const;
  void reset(Workspace& workspace) const;
  // q, qd: at least regime().num_joints() values.
  std::uint32_t compute_flags(Workspace& workspace, double time, const double* q, const double* qd) const;

 private:
  TrainingRegime regime_;
  Eigen::VectorXd lo_q_, hi_q_, lo_qd_, hi_qd_, max_qdd_;  // the limits with their margins
};

// Samples outside the regime over a stream or a recording.
struct RegimeSummary {
  bool known = false;  // false: the model carries no regime, nothing was checked
  std::size_t samples = 0, flagged = 0;
  // Per bit (3 per joint, then the residual's), samples flagged for it; sized
  // up front so that add() never allocates in a live loop.
  std::vector<std::size_t> counts = std::vector<std::size_t>(kRegimeBits, 0);
  std::optional<double> first_time_s;
  std::uint32_t all_flags = 0;  // union over the samples

  void add(double time, std::uint32_t flags);
  double get_fraction() const { return samples ? static_cast<double>(flagged) / static_cast<double>(samples) : 0.0; }
  // "3.2 % of 12000 samples outside the free-space model's regime (joint 1
  // velocity 2.9 %, ...), first at 4.21 s"; or that none were, or that the model
  // carries no regime.
  std::string to_text() const;
  nlohmann::json to_json() const;
};

RegimeSummary compute_regime_summary(const RegimeMonitor& monitor, const Recording& recording);
// The same over a recording given in chunks: one workspace and one summary
// for all of them, the chunks in order.
void add_regime_samples(const RegimeMonitor& monitor, RegimeMonitor::Workspace& workspace, const Recording& chunk,
                        RegimeSummary& summary);

}  // namespace rcm::dynamics
