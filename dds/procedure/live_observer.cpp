// The procedure's view of the monitor and of the simulator's truth (live_observer.hpp).

#include "live_observer.hpp"

#include "support/dds_io.hpp"
#include "ros2_msgs.h"

namespace rcm::dds_node {

LiveObserver::LiveObserver(dds_entity_t participant, const std::string& arm, const Eigen::Matrix3d& R_base_inc)
    : R_(R_base_inc) {
  const std::string ns = "/" + arm + "/";
  constexpr int kDepth = 5000;
  estimate_r_ = make_reader(participant, &geometry_msgs_msg_dds__Vector3Stamped__desc, ns + "rcm/misalignment", kDepth);
  force_r_ = make_reader(participant, &geometry_msgs_msg_dds__WrenchStamped__desc, ns + "sim/incision_force", kDepth);
  misalignment_r_ =
      make_reader(participant, &geometry_msgs_msg_dds__Vector3Stamped__desc, ns + "sim/misalignment", kDepth);
  shift_r_ = make_reader(participant, &geometry_msgs_msg_dds__Vector3Stamped__desc, ns + "sim/rcm_shift", kDepth);
}

void LiveObserver::start(std::optional<rcm::sim::ClosedLoopMeter> meter) {
  dropping_ = true;
  poll();  // what came before is dropped
  dropping_ = false;
  origin_ns_ = -1;
  meter_ = std::move(meter);
  pending_.clear();
  estimate_.reset();
  truth_.reset();
  last_shift_.reset();
  last_remaining_.reset();
  force_n_ = 0.0;
  estimates_ = truth_samples_ = 0;
}

void LiveObserver::poll() {
  // The segment's clock starts with the first message after start().
  auto accept = [&](const std_msgs_msg_dds__Header_& h) {
    if (dropping_) return false;
    if (origin_ns_ < 0) origin_ns_ = get_stamp_ns(h);
    return get_stamp_ns(h) >= origin_ns_;
  };
  take_all(estimate_r_, [&](const void* p) {
    const auto& m = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(p);
    if (!accept(m.header)) return;
    estimate_ = Eigen::Vector3d(m.vector.x, m.vector.y, m.vector.z);
    ++estimates_;
  });
  auto keep = [&](const std_msgs_msg_dds__Header_& h) -> Pending* {
    return accept(h) ? &pending_[get_stamp_ns(h)] : nullptr;
  };
  take_all(force_r_, [&](const void* p) {
    const auto& m = *static_cast<const geometry_msgs_msg_dds__WrenchStamped_*>(p);
    if (Pending* q = keep(m.header)) q->force = Eigen::Vector3d(m.wrench.force.x, m.wrench.force.y, m.wrench.force.z);
  });
  take_all(misalignment_r_, [&](const void* p) {
    const auto& m = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(p);
    if (Pending* q = keep(m.header)) q->misalignment = Eigen::Vector3d(m.vector.x, m.vector.y, m.vector.z);
  });
  take_all(shift_r_, [&](const void* p) {
    const auto& m = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(p);
    if (Pending* q = keep(m.header)) q->shift = Eigen::Vector3d(m.vector.x, m.vector.y, m.vector.z);
  });
  // In stamp order, every sample whose force and misalignment (and, in a
  // closed loop, the shift) have all come; an older one still incomplete once
  // a later one is whole will not be completed.
  auto last_whole = pending_.end();
  for (auto it = pending_.begin(); it != pending_.end(); ++it)
    if (is_whole(it->second)) last_whole = it;
  if (last_whole == pending_.end()) return;
  const auto end = std::next(last_whole);  // before last_whole itself is erased
  for (auto it = pending_.begin(); it != end;) {
    if (is_whole(it->second)) process(it->first, it->second);
    it = pending_.erase(it);
  }
}

void LiveObserver::process(std::int64_t stamp, const Pending& p) {
  const double t = static_cast<double>(stamp - origin_ns_) * 1e-9;
  const Eigen::Vector3d& remaining = *p.misalignment;
  force_n_ = p.force->norm();
  truth_ = remaining;
  ++truth_samples_;
  if (!meter_) return;
  if (p.shift) {
    if (last_shift_ && last_remaining_) {
      const Eigen::Vector3d step = *p.shift - *last_shift_;
      if (!step.isZero()) meter_->add_move(step, R_ * *last_remaining_);
    }
    last_shift_ = *p.shift;
  }
  last_remaining_ = remaining;
  meter_->add_sample(t, force_n_, remaining.norm());
}

rcm::sim::ClosedLoopRun LiveObserver::get_figures() const {
  rcm::sim::ClosedLoopRun run;
  run.closed = true;
  if (meter_) meter_->get_figures(run);
  return run;
}

}  // namespace rcm::dds_node
