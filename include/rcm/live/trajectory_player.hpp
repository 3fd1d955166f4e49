#pragma once
// Plays a joint trajectory on an arm that speaks CRTK (a dVRK, or the
// simulated PSM) and records what the arm measured, without any middleware:
// the program feeds it the arm's messages and sends the commands it returns
// (dds/ does so over DDS).
//
//   1. Start: the arm's operating_state must say ENABLED and homed, and its
//      measured_js must arrive; otherwise the player refuses and says why.
//   2. Move: one move_jp to the trajectory's first row (joints the file lacks
//      are held where the first measured_js had them); wait until the arm is
//      there (goal_tolerance) and not busy.
//   3. Stream: row k as a servo_jp once the arm's clock (the stamps of its
//      measured_js) has run the file's time_k - time_0 since streaming began:
//      paced by the arm's own time, whatever its speed against the wall, one
//      row per measured_js at most. Every measured_js from the first row on is
//      recorded (time: its header stamp) until the arm's clock passes the last
//      row by settle_s.
//   4. Stalls: a measured_js that comes late (its age beyond the freshest
//      ones' by more than stall_s of the arm's time, or by a period of the arm
//      when that is longer) was written while this program could not answer:
//      the arm held the last row all along. The player answers none of the late
//      ones and pauses the file by their time, so the arm resumes from the row
//      it holds instead of jumping to where the file is now. Recorded as usual.
//
// A record-only player (no trajectory) skips 2 and 3 and records for a given
// duration of the arm's time, whatever moves the arm (a surgeon at the
// console, the simulator's teleoperation).
//
// Safety stops, checked on every message and tick: the operating state leaves
// ENABLED; no measured_js for measured_timeout_s of wall time; while playing,
// a joint's tracking error (measured against the arm's setpoint_js, or against
// the last row sent when the arm publishes no setpoint) beyond
// max_tracking_error (a recorder reports it only). A
// stop ends streaming; after a tracking error it commands the arm to hold
// where it is. A bad measured_js (lengths, NaN, a stamp zero or not after the
// last) is rejected and counted, never recorded.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "rcm/common/error.hpp"
#include "rcm/io/joint_state_map.hpp"
#include "rcm/io/joint_trajectory.hpp"
#include "rcm/io/recording.hpp"

namespace rcm {

struct PlayerOptions {
  // Per joint of the arm, in its order (rad or m); joints beyond the list use its last value.
  std::vector<double> max_tracking_error = {0.05, 0.05, 0.005, 0.2};
  std::vector<double> goal_tolerance = {0.01, 0.01, 0.001, 0.01};  // at the first row, per joint likewise
  double measured_timeout_s = 1.0;  // wall time without a measured_js that stops the player
  double start_timeout_s = 10.0;    // wall time to hear the arm's state and measured_js
  double move_timeout_s = 60.0;     // arm time to reach the first row
  double settle_s = 0.0;            // arm time recorded after the last row
  double stall_s = 0.005;           // arm time a measured_js may come late before the file pauses (0: never)
  // Throws InputError at `where(name)` for a value out of range.
  void check(const std::function<InputLocation(const std::string&)>& where) const;
};

enum class PlayerPhase { starting, moving, streaming, done, refused, stopped };
const char* to_string(PlayerPhase phase);

// What to send the arm now.
struct PlayerCommand {
  enum class Kind { none, move_jp, servo_jp } kind = Kind::none;
  std::vector<double> position, velocity;  // every joint of the arm, its order
};

struct PlayerSummary {
  std::size_t rows = 0;            // in the trajectory
  std::size_t rows_sent = 0;       // servo_jp sent
  std::size_t rows_skipped = 0;    // rows due together with a later one (the file faster than measured_js)
  std::size_t samples_recorded = 0;
  std::size_t rejected = 0;        // measured_js not recorded: malformed, or a stamp not after the last
  std::size_t stalls = 0;          // runs of late measured_js the file paused over
  double paused_s = 0.0;           // arm time the file paused, in all (part of sent_span_s)
  double file_duration_s = 0.0;    // last row's time - first row's
  double sent_span_s = 0.0;        // arm time from the first row sent to the last
  double recorded_span_s = 0.0;    // first to last recorded stamp
  std::vector<double> max_tracking_error, rms_tracking_error;  // per joint of the arm
  std::string message;             // why the player refused or stopped, or what it did
};

class TrajectoryPlayer {
 public:
  // Plays `trajectory` (its joints are the arm's first ones, in order).
  TrajectoryPlayer(const JointTrajectory& trajectory, const PlayerOptions& options);
  // Records `record_s` of the arm's time without commanding it.
  TrajectoryPlayer(double record_s, const PlayerOptions& options);

  // Each message as it comes: header stamp (ns, the arm's clock) and the wall
  // time it came (ns, a steady clock). The returned command is valid until the next call.
  // `age_ns`: how long ago the arm wrote the message, on the wall (the time
  // it came less the writer's own timestamp; a constant offset between the two
  // machines' clocks does no harm); negative when the middleware does not say,
  // and then no stall is seen.
  const PlayerCommand& compute_operating_state(const std::string& state, bool homed, bool busy, std::int64_t wall_ns);
  const PlayerCommand& compute_measured(const JointStateView& message, std::int64_t stamp_ns, std::int64_t wall_ns,
                                        std::int64_t age_ns = -1);
  void add_setpoint(const JointStateView& message, std::int64_t stamp_ns);
  // Timeouts, between messages.
  const PlayerCommand& compute_tick(std::int64_t wall_ns);

  PlayerPhase phase() const { return phase_; }
  bool finished() const {
    return phase_ == PlayerPhase::done || phase_ == PlayerPhase::refused || phase_ == PlayerPhase::stopped;
  }
  const PlayerSummary& summary() const { return summary_; }
  // What was recorded, as a recording of every joint of the arm (source `source`).
  Recording get_recording(const std::string& source) const;
  // The arm's joint names, from its first measured_js (empty before it).
  const std::vector<std::string>& joint_names() const { return names_; }

 private:
  bool check_measured(const JointStateView& m, std::int64_t stamp_ns);
  void refuse(const std::string& why);
  void stop(const std::string& why, bool hold);
  void finish();
  void record(const JointStateView& m, std::int64_t stamp_ns);
  double limit(const std::vector<double>& values, std::size_t joint) const;
  const PlayerCommand& none();

  JointTrajectory trajectory_;
  bool record_only_ = false;
  double record_s_ = 0.0;
  PlayerOptions options_;
  PlayerPhase phase_ = PlayerPhase::starting;
  PlayerCommand command_;
  PlayerSummary summary_;
  std::vector<std::string> names_;
  // The arm's latest state.
  std::optional<std::string> state_;
  bool homed_ = false, busy_ = false;
  std::int64_t first_wall_ns_ = -1, last_measured_wall_ns_ = -1, last_stamp_ns_ = 0;
  std::int64_t start_stamp_ns_ = 0, move_stamp_ns_ = 0, first_sent_stamp_ns_ = 0, last_sent_stamp_ns_ = 0;
  // Stalls: the freshest age seen (let rise slowly, so that two clocks'
  // drift is not taken for lateness), the arm's clock against the wall, and
  // the arm time the file paused.
  std::int64_t age_floor_ns_ = -1, first_measured_stamp_ns_ = -1, first_measured_wall_ns_ = -1;
  std::int64_t paused_ns_ = 0;
  // Half the file's mean row period: the most a row may be sent ahead of its time.
  double half_row_period_s_ = std::numeric_limits<double>::infinity();
  bool in_stall_ = false;
  double get_lateness_s(std::int64_t age_ns, std::int64_t stamp_ns, std::int64_t previous_stamp_ns,
                        std::int64_t wall_ns);
  std::size_t next_row_ = 0;
  std::vector<double> held_, goal_, last_sent_, measured_;
  // The arm's recent setpoint_js, by stamp: each measured_js is held against
  // the setpoint of its own period (or the last one before it), whatever the
  // order the two topics arrive in.
  static constexpr std::size_t kSetpoints = 256;
  std::vector<std::vector<double>> setpoints_ = std::vector<std::vector<double>>(kSetpoints);
  std::vector<std::int64_t> setpoint_stamps_ = std::vector<std::int64_t>(kSetpoints, -1);
  std::size_t next_setpoint_ = 0;
  const std::vector<double>* find_setpoint(std::int64_t stamp_ns, std::size_t joints) const;
  std::vector<double> error_sq_sum_;
  std::size_t error_count_ = 0;
  // The recording, row by row.
  std::vector<double> time_, position_, velocity_, effort_;
};

// The summary as JSON: rows, rows_sent, rows_skipped, samples_recorded,
// rejected, stalls, paused_s, file_duration_s, sent_span_s, recorded_span_s,
// pacing_error (the sent span's relative difference from the file's duration,
// pauses included; null when nothing was streamed), max_tracking_error and rms_tracking_error ({joint: value}),
// message.
nlohmann::json to_json(const PlayerSummary& summary, const std::vector<std::string>& joint_names);
// The same in lines for a terminal.
std::string format_player_summary(const PlayerSummary& summary, const std::vector<std::string>& joint_names);

// The trajectory of a static hold at `q` (every joint the file gives) for
// `seconds`, rows at `rate_hz`: the baseline is a file like any other.
JointTrajectory make_hold_trajectory(const Eigen::VectorXd& q, double seconds, double rate_hz);

}  // namespace rcm
