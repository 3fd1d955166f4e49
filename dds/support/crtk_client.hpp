#pragma once
// The client side of an arm's CRTK topics under /<arm>/ (a dVRK PSM's ROS 2
// node, or rcm_sim_psm_dds): measured_js, setpoint_js and operating_state
// read; servo_jp, move_jp and state_command written, with the dVRK's QoS
// (RELIABLE, VOLATILE). And the loop that plays a TrajectoryPlayer on it.

#include <dds/dds.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "dds_io.hpp"
#include "rcm/live/trajectory_player.hpp"

namespace rcm::dds_node {

struct ArmState {
  bool known = false;
  std::string state;  // DISABLED, ENABLED, PAUSED, FAULT
  bool homed = false, busy = false;
};

class CrtkClient {
 public:
  // `arm`: the namespace, "PSM1" for /PSM1/measured_js.
  CrtkClient(dds_entity_t participant, const std::string& arm);
  CrtkClient(const CrtkClient&) = delete;
  CrtkClient& operator=(const CrtkClient&) = delete;

  void send_servo_jp(const std::vector<double>& position, const std::vector<double>& velocity);
  void send_move_jp(const std::vector<double>& position);
  void send_state_command(const std::string& command);

  struct Handlers {
    std::function<void(const ArmState&)> on_state;
    std::function<void(const JointStateView&, std::int64_t stamp_ns)> on_setpoint;
    // age_ns: how long ago the arm wrote it (this machine's wall clock less the writer's timestamp).
    std::function<void(const JointStateView&, std::int64_t stamp_ns, std::int64_t age_ns)> on_measured;
  };
  // Waits up to `timeout_ms` for a message, then hands every waiting one to the
  // handlers: operating_state first, then setpoint_js, then measured_js.
  void wait_and_dispatch(int timeout_ms, const Handlers& handlers);
  // Drops every joint state waiting (the operating state is kept): a player
  // that starts now sees the arm from now on.
  void discard_pending();

  // Every command writer has found the arm's subscriber, and the arm's
  // publishers have found ours.
  bool is_matched() const;
  const ArmState& get_state() const { return state_; }
  // The rate of measured_js by its stamps (the median of the last intervals); 0 before two samples.
  double get_measured_rate_hz() const;
  const std::string& arm() const { return arm_; }
  std::string topic(const std::string& name) const { return "/" + arm_ + "/" + name; }

 private:
  std::string arm_;
  dds_entity_t measured_ = 0, setpoint_ = 0, operating_state_ = 0;
  dds_entity_t servo_ = 0, move_ = 0, state_command_ = 0;
  dds_entity_t waitset_ = 0;
  ArmState state_;
  JointStateBuffer buffer_;
  std::int64_t last_measured_stamp_ = 0;
  std::vector<std::int64_t> intervals_ = std::vector<std::int64_t>(63, 0);
  std::size_t next_interval_ = 0;
  JointStateMessage command_;
  std::string command_text_;
};

// Waits (wall time) until the arm's topics match both ways and, with `power`,
// enables and homes it (state_command "enable", then "home", repeated until the
// arm reports ENABLED, homed and not busy). False after `timeout_s`;
// `why` then says what was missing.
bool wait_for_arm(CrtkClient& arm, bool power, double timeout_s, const std::function<bool()>& interrupted,
                  std::string& why);

// Feeds the arm's messages to `player` and sends its commands until it
// finishes or `interrupted()`; `progress` is called about every
// `progress_period_s` of wall time with the player and the arm's last stamp.
void run_player(CrtkClient& arm, TrajectoryPlayer& player, const std::function<bool()>& interrupted,
                const std::function<void(const TrajectoryPlayer&, std::int64_t stamp_ns)>& progress = {},
                double progress_period_s = 1.0);

}  // namespace rcm::dds_node
