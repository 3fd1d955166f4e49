#pragma once
// What the procedure reads in its live segments besides the arm's joints: the
// monitor's estimate (/<arm>/rcm/misalignment) and, against the simulator, the
// bench's truth (/<arm>/sim/incision_force, /<arm>/sim/misalignment,
// /<arm>/sim/rcm_shift), turned into the closed loop's figures by the bench's
// own ClosedLoopMeter.

#include <dds/dds.h>

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "rcm/sim/closed_loop.hpp"

namespace rcm::dds_node {

class LiveObserver {
 public:
  // `R_base_inc`: the incision frame of the docking pose (the simulator's truth is in it).
  LiveObserver(dds_entity_t participant, const std::string& arm, const Eigen::Matrix3d& R_base_inc);

  // Forgets what came before; times count from the first message that comes
  // after (the segment starts now). With a meter, every truth sample feeds it
  // (a closed-loop segment, whose arm publishes its software shift with each sample).
  void start(std::optional<rcm::sim::ClosedLoopMeter> meter);
  // Takes every message waiting.
  void poll();

  std::size_t estimates() const { return estimates_; }
  std::size_t truth_samples() const { return truth_samples_; }
  const std::optional<Eigen::Vector3d>& last_estimate() const { return estimate_; }
  const std::optional<Eigen::Vector3d>& last_truth() const { return truth_; }
  double last_force_n() const { return force_n_; }
  // The meter's figures so far (peak force, time to below, RMS after settling, moves).
  rcm::sim::ClosedLoopRun get_figures() const;

 private:
  struct Pending {
    std::optional<Eigen::Vector3d> force, misalignment, shift;
  };
  void process(std::int64_t stamp, const Pending& p);
  bool is_whole(const Pending& p) const { return p.force && p.misalignment && (!meter_ || p.shift); }

  Eigen::Matrix3d R_;
  dds_entity_t estimate_r_ = 0, force_r_ = 0, misalignment_r_ = 0, shift_r_ = 0;
  std::int64_t origin_ns_ = -1;  // the first stamp after start; -1 before it
  bool dropping_ = false;
  std::optional<rcm::sim::ClosedLoopMeter> meter_;
  std::map<std::int64_t, Pending> pending_;
  std::optional<Eigen::Vector3d> estimate_, truth_, last_shift_, last_remaining_;
  double force_n_ = 0.0;
  std::size_t estimates_ = 0, truth_samples_ = 0;
};

}  // namespace rcm::dds_node
