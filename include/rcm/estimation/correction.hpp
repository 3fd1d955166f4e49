#pragma once
// From estimate to action: what the running misalignment estimate tells the
// arm and the surgical team to do.
//
// The estimate p = [dr_x, dr_y, D] is the incision's position relative to the
// RCM in the incision frame I (docs/formats.md, "Frames and signs"), so the RCM
// move that puts the RCM on the incision is p itself in I, and R_base_inc p in
// the base frame. Three actions:
//
// - hold, first of all, while the model does not explain the joint torques
//   (OnlineOutput::fit_cost above max_fit_cost): a free-space model that
//   misses a payload or a tool makes the estimate confidently wrong, and a
//   shift on it would stretch the tissue further.
// - hold: the RCM is within tolerance of the incision (the 95 % upper bound of
//   the distance is), or the estimate is not sure either way: no advice while
//   the estimate is within tolerance or its interval along the move is wider
//   than the move (2 z sd_u >= |p|, sd_u the standard deviation along p,
//   sqrt(u^T C u) from the estimate's covariance C and the move's direction u).
// - compensate: a software RCM shift toward the incision, for misalignments up
//   to a limit; rate-limited, and never beyond the estimate's lower confidence
//   bound |p| - z sd_u (a shift the estimate is 97.5 % sure does not overshoot).
// - reposition: beyond the limit (or once the software shifts add up to it):
//   manual re-docking advice, the move in the arm's own words.
//
// Hysteresis: hold turns into an action once the estimate has exceeded the
// tolerance with an interval narrower than the move for confirm_s (a
// compensation that stopped at its lower bound resumes on that bound above
// zero alone: its direction is known); an action returns to hold
// once the estimate falls below release_fraction of the tolerance, its lower
// bound reaches zero, or the estimate restarts (OnlineOutput::jumps);
// reposition turns back into compensate only once the upper bound is within
// the limit; a hold "within tolerance" lasts until the upper bound exceeds
// tolerance / release_fraction. The thresholds to start and to stop differ,
// so a noisy estimate near one does not flip the advice at every sample.
//
// The corrector (RcmCorrector) is immutable; its state lives in a fixed-size
// Workspace, and compute_correction() does not allocate. The software shift in
// effect is the caller's to say (the arm knows where its RCM setpoint is; a
// replay of a recording has none): the limit counts it. In closed loop, the
// commanded shift moves the RCM: tell the estimator
// (OnlineEstimator::apply_rcm_shift) so that its offsets stay relative to the
// RCM as it is now.
#include <Eigen/Core>
#include <string>

#include "rcm/estimation/online.hpp"
#include "rcm/kinematics/incision.hpp"

namespace rcm {

struct CorrectionOptions {
  double tolerance_m = 0.0015;         // within this, hold
  double compensate_limit_m = 0.010;   // software shifts up to this (in all, since reset), beyond: re-dock
  double max_rate_m_per_s = 0.005;     // speed of the software shift
  double confidence_z = 1.96;          // the 95 % interval
  // Above this fit cost (OnlineOutput::fit_cost) the model does not explain
  // the residual: hold. 1.5 is a perfect fit; 10 is an RMS innovation of about
  // 2.6 times the spread its filter predicts.
  double max_fit_cost = 10.0;
  double release_fraction = 0.5;       // back to hold below this fraction of the tolerance
  // A sample after a gap in the stream moves the RCM by at most this much time
  // at max_rate: a silence is not a licence to jump.
  double max_step_dt_s = 0.1;
  // An action starts once the estimate has called for it this long without a
  // break. A bank of filters restarted from the prior can be sure of a wrong
  // move for a few tenths of a second, and at 1.5 kHz that is hundreds of
  // steps; a real misalignment stays.
  double confirm_s = 0.5;
  // ... and this long for the first action after a change-point restart of
  // the estimate: a restarted filter can follow a transient the free-space
  // model missed, sure of a wrong move, for a second.
  double restart_confirm_s = 1.5;
  void check() const;  // throws std::invalid_argument
};
const OptionTable<CorrectionOptions>& get_option_table(OptionTag<CorrectionOptions>);

enum class CorrectionAction { hold, compensate, reposition };
const char* to_string(CorrectionAction action);

// Why the corrector holds (none when it acts).
// no_onset: the estimator has not detected a misalignment (or has no finite
// estimate); model_mismatch: the model does not explain the joint torques.
enum class HoldReason { none, no_onset, model_mismatch, not_confident, within_tolerance };
const char* to_string(HoldReason reason);

struct CorrectionOutput {
  double time = 0.0;
  CorrectionAction action = CorrectionAction::hold;
  HoldReason reason = HoldReason::no_onset;
  bool changed = false;  // the action or the reason differs from the previous sample's
  // The RCM move that puts the RCM on the incision (the remaining misalignment).
  Eigen::Vector3d move_inc = Eigen::Vector3d::Zero();
  Eigen::Vector3d move_base = Eigen::Vector3d::Zero();
  // Per-axis 95 % interval of move_inc.
  Eigen::Vector3d move_low_inc = Eigen::Vector3d::Zero();
  Eigen::Vector3d move_high_inc = Eigen::Vector3d::Zero();
  double distance_m = 0.0;       // |move|
  double distance_low_m = 0.0;   // |move| - z sd_u, at least 0
  double distance_high_m = 0.0;  // |move| + z sd_u
  double fit_cost = 0.0;         // the estimate's (OnlineOutput::fit_cost)
  // The software shift of the RCM commanded at this sample (zero unless
  // compensating), and the shift in effect once it is made, base frame.
  Eigen::Vector3d step_base = Eigen::Vector3d::Zero();
  Eigen::Vector3d applied_base = Eigen::Vector3d::Zero();
};

class RcmCorrector {
 public:
  struct Workspace {
    bool started = false;
    double last_time = 0.0;
    int jumps = 0;  // the estimate's restarts seen (OnlineOutput::jumps)
    double sure_since = -1.0;  // when the start condition began to hold (< 0: it does not)
    bool after_restart = false;  // no action since the estimate's last restart
    bool resumable = false;  // a compensation stopped at its lower bound, and nothing since says it is done
    CorrectionOutput output;
  };
  RcmCorrector(const IncisionFrame& incision, const CorrectionOptions& options);
  Workspace create_workspace() const;
  void reset(Workspace& workspace) const;
  // The action after one estimate, given the software shift of the RCM
  // commanded so far (base frame; zero when nothing shifts it). No
  // allocation. Across processes the arm takes a shift a while after it is
  // commanded: `in_effect_base` is the shift the arm reports in effect at the
  // estimate's sample (the estimate is relative to that RCM; default: the
  // commanded one). The part still on its way counts as made, so that a delay
  // slows the correction down but never makes it overshoot.
  const CorrectionOutput& compute_correction(Workspace& workspace, const OnlineOutput& estimate,
                                             const Eigen::Vector3d& applied_base = Eigen::Vector3d::Zero()) const;
  const CorrectionOutput& compute_correction(Workspace& workspace, const OnlineOutput& estimate,
                                             const Eigen::Vector3d& applied_base,
                                             const Eigen::Vector3d& in_effect_base) const;
  const IncisionFrame& incision() const { return incision_; }
  const CorrectionOptions& options() const { return options_; }

 private:
  IncisionFrame incision_;
  CorrectionOptions options_;
};

// One call per sample for a closed loop: the pipeline's estimate, then the
// correction. The caller says which software shift of the RCM is in effect
// (base frame, the arm's setpoint minus the docked RCM); whatever changed since
// the last call is passed to the estimator (apply_rcm_shift) before the sample,
// so the estimate stays relative to the RCM as it is, whether or not the arm
// carried out the last step. No allocation per sample.
class CorrectionLoop {
 public:
  struct Workspace {
    OnlinePipeline::Workspace pipeline;
    RcmCorrector::Workspace corrector;
    Eigen::Vector3d known_shift_base = Eigen::Vector3d::Zero();
  };
  CorrectionLoop(OnlinePipeline pipeline, RcmCorrector corrector);
  Workspace create_workspace() const;
  void reset(Workspace& workspace) const;
  // As OnlinePipeline::compute_sample; returns the correction, whose estimate
  // is get_online_output(workspace.pipeline.estimator). `applied_base`: the
  // shift commanded so far; `in_effect_base`: the one the arm had at this
  // sample (RcmCorrector::compute_correction; default: the commanded one).
  const CorrectionOutput& compute_sample(Workspace& workspace, double time, const double* q, const double* qd,
                                         const double* effort, const Eigen::Vector3d& applied_base) const;
  const CorrectionOutput& compute_sample(Workspace& workspace, double time, const double* q, const double* qd,
                                         const double* effort, const Eigen::Vector3d& applied_base,
                                         const Eigen::Vector3d& in_effect_base) const;
  const OnlinePipeline& pipeline() const { return pipeline_; }
  const RcmCorrector& corrector() const { return corrector_; }

 private:
  OnlinePipeline pipeline_;
  RcmCorrector corrector_;
};

// The advice in words a surgical team uses, along the arm's axes: "re-dock:
// move the RCM 23 mm deeper along the instrument, 8 mm toward +x_base".
// Allocates: call it when the action changes, or at a display cadence.
std::string describe_correction(const CorrectionOutput& correction, const RcmCorrector& corrector);

// The move alone, in those words ("23 mm deeper along the instrument, 8 mm
// toward +x_base"); components under 1 mm are left out.
std::string describe_rcm_move(const Eigen::Vector3d& move_inc, const IncisionFrame& incision);

// After re-docking: the new baseline's incision frame and a short motion give a
// fresh estimate; is the RCM now on the incision?
struct AlignmentCheck {
  bool aligned = false;       // the 95 % upper bound of the distance is within tolerance
  bool confident = false;     // the estimate is sure of a move (lower bound > 0 and interval narrower than it)
  double within_m = 0.0;      // 95 % upper bound of the distance
  std::string message;        // "aligned within 1.6 mm" or what remains
};
AlignmentCheck check_alignment(const OnlineOutput& estimate, const IncisionFrame& incision,
                               const CorrectionOptions& options);

}  // namespace rcm
