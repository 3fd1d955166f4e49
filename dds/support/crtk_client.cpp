// The CRTK client and the player's loop (crtk_client.hpp).

#include "crtk_client.hpp"

#include <algorithm>
#include <thread>

namespace rcm::dds_node {

namespace {

constexpr int kStateDepth = 100;      // the dVRK's publishers keep their last 100
constexpr int kMeasuredDepth = 5000;  // the player must record every sample: seconds of history at 1.5 kHz

}  // namespace

CrtkClient::CrtkClient(dds_entity_t participant, const std::string& arm) : arm_(arm) {
  measured_ = make_reader(participant, &sensor_msgs_msg_dds__JointState__desc, topic("measured_js"), kMeasuredDepth);
  setpoint_ = make_reader(participant, &sensor_msgs_msg_dds__JointState__desc, topic("setpoint_js"), kStateDepth);
  operating_state_ =
      make_reader(participant, &crtk_msgs_msg_dds__OperatingState__desc, topic("operating_state"), kStateDepth);
  servo_ = make_writer(participant, &sensor_msgs_msg_dds__JointState__desc, topic("servo_jp"), kStateDepth);
  move_ = make_writer(participant, &sensor_msgs_msg_dds__JointState__desc, topic("move_jp"), kStateDepth);
  state_command_ =
      make_writer(participant, &crtk_msgs_msg_dds__StringStamped__desc, topic("state_command"), kStateDepth);
  waitset_ = check(dds_create_waitset(participant), "waitset");
  for (dds_entity_t r : {measured_, setpoint_, operating_state_}) {
    check(dds_set_status_mask(r, DDS_DATA_AVAILABLE_STATUS), "status");
    check(dds_waitset_attach(waitset_, r, r), "attach");
  }
}

void CrtkClient::send_servo_jp(const std::vector<double>& p, const std::vector<double>& v) {
  const dds_return_t rc =
      dds_write(servo_, command_.fill(get_wall_ns(), p.data(), p.size(), v.data(), v.size(), nullptr, 0));
  if (rc < 0) dds_fail("servo_jp", rc);
}

void CrtkClient::send_move_jp(const std::vector<double>& p) {
  const dds_return_t rc = dds_write(move_, command_.fill(get_wall_ns(), p.data(), p.size(), nullptr, 0, nullptr, 0));
  if (rc < 0) dds_fail("move_jp", rc);
}

void CrtkClient::send_state_command(const std::string& command) {
  command_text_ = command;
  crtk_msgs_msg_dds__StringStamped_ m{};
  m.header = make_header(get_wall_ns());
  m.string = command_text_.data();
  const dds_return_t rc = dds_write(state_command_, &m);
  if (rc < 0) dds_fail("state_command", rc);
}

bool CrtkClient::is_matched() const {
  return is_matched_writer(servo_) && is_matched_writer(move_) && is_matched_writer(state_command_) &&
         is_matched_reader(measured_) && is_matched_reader(operating_state_);
}

void CrtkClient::wait_and_dispatch(int timeout_ms, const Handlers& h) {
  const dds_return_t woke = dds_waitset_wait(waitset_, nullptr, 0, DDS_MSECS(timeout_ms));
  if (woke < 0) dds_fail("wait", woke);
  take_all(operating_state_, [&](const void* s) {
    const auto& m = *static_cast<const crtk_msgs_msg_dds__OperatingState_*>(s);
    state_.known = true;
    state_.state = m.state ? m.state : "";
    state_.homed = m.is_homed;
    state_.busy = m.is_busy;
    if (h.on_state) h.on_state(state_);
  });
  take_all(setpoint_, [&](const void* s) {
    const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(s);
    if (!h.on_setpoint) return;
    buffer_.assign(m);
    h.on_setpoint(buffer_.view(), get_stamp_ns(m.header));
  });
  take_all(measured_, [&](const void* s, std::int64_t source_ns) {
    const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(s);
    const std::int64_t stamp = get_stamp_ns(m.header);
    if (last_measured_stamp_ > 0 && stamp > last_measured_stamp_) {
      intervals_[next_interval_] = stamp - last_measured_stamp_;
      next_interval_ = (next_interval_ + 1) % intervals_.size();
    }
    last_measured_stamp_ = stamp;
    if (!h.on_measured) return;
    buffer_.assign(m);
    h.on_measured(buffer_.view(), get_stamp_ns(m.header), get_wall_ns() - source_ns);
  });
}

double CrtkClient::get_measured_rate_hz() const {
  std::vector<std::int64_t> seen;
  for (std::int64_t d : intervals_)
    if (d > 0) seen.push_back(d);
  if (seen.empty()) return 0.0;
  std::nth_element(seen.begin(), seen.begin() + static_cast<std::ptrdiff_t>(seen.size() / 2), seen.end());
  return 1e9 / static_cast<double>(seen[seen.size() / 2]);
}

void CrtkClient::discard_pending() { wait_and_dispatch(0, Handlers{}); }

bool wait_for_arm(CrtkClient& arm, bool power, double timeout_s, const std::function<bool()>& interrupted,
                  std::string& why) {
  const std::int64_t start = get_steady_ns();
  auto elapsed = [&] { return static_cast<double>(get_steady_ns() - start) * 1e-9; };
  std::int64_t matched_at = -1, last_sent = -1;
  std::string last_command;
  bool heard_measured = false;
  CrtkClient::Handlers h;
  h.on_measured = [&](const JointStateView&, std::int64_t, std::int64_t) { heard_measured = true; };
  while (!interrupted()) {
    arm.wait_and_dispatch(20, h);
    const ArmState& s = arm.get_state();
    if (matched_at < 0 && arm.is_matched()) matched_at = get_steady_ns();
    // Discovery runs both ways on its own: a writer that has found the arm's
    // subscriber may not yet be known to it. A moment more, then commands.
    const bool ready_to_send = matched_at >= 0 && get_steady_ns() - matched_at > 300000000;
    if (ready_to_send && s.known && heard_measured) {
      if (!power || (s.state == "ENABLED" && s.homed && !s.busy)) return true;
      // Each command once, again every 2 s while the arm has not taken it.
      const std::string next = s.state == "ENABLED" ? (s.homed || s.busy ? "" : "home") : "enable";
      if (!next.empty() && s.state != "FAULT" &&
          (next != last_command || get_steady_ns() - last_sent > 2000000000)) {
        arm.send_state_command(next);
        last_command = next;
        last_sent = get_steady_ns();
      }
    }
    if (elapsed() > timeout_s) {
      if (matched_at < 0) why = "the arm's topics under /" + arm.arm() + "/ did not match (is it running, on this domain?)";
      else if (!s.known) why = "no operating_state from " + arm.topic("operating_state");
      else if (!heard_measured) why = "no measured_js from " + arm.topic("measured_js");
      else why = "the arm did not become ENABLED and homed: it is " + s.state + (s.homed ? "" : ", not homed");
      return false;
    }
  }
  why = "interrupted";
  return false;
}

void run_player(CrtkClient& arm, TrajectoryPlayer& player, const std::function<bool()>& interrupted,
                const std::function<void(const TrajectoryPlayer&, std::int64_t)>& progress, double progress_period_s) {
  std::int64_t last_progress = get_steady_ns(), last_stamp = 0;
  auto send = [&](const PlayerCommand& c) {
    if (c.kind == PlayerCommand::Kind::servo_jp) arm.send_servo_jp(c.position, c.velocity);
    else if (c.kind == PlayerCommand::Kind::move_jp) arm.send_move_jp(c.position);
  };
  CrtkClient::Handlers h;
  h.on_state = [&](const ArmState& s) { send(player.compute_operating_state(s.state, s.homed, s.busy, get_steady_ns())); };
  h.on_setpoint = [&](const JointStateView& m, std::int64_t stamp) { player.add_setpoint(m, stamp); };
  h.on_measured = [&](const JointStateView& m, std::int64_t stamp, std::int64_t age_ns) {
    last_stamp = stamp;
    send(player.compute_measured(m, stamp, get_steady_ns(), age_ns));
  };
  arm.discard_pending();
  // The state the arm last reported counts before the first message of this player.
  if (arm.get_state().known) {
    const ArmState& s = arm.get_state();
    send(player.compute_operating_state(s.state, s.homed, s.busy, get_steady_ns()));
  }
  while (!player.finished() && !interrupted()) {
    arm.wait_and_dispatch(5, h);
    send(player.compute_tick(get_steady_ns()));
    if (progress && static_cast<double>(get_steady_ns() - last_progress) * 1e-9 >= progress_period_s) {
      last_progress = get_steady_ns();
      progress(player, last_stamp);
    }
  }
}

}  // namespace rcm::dds_node
