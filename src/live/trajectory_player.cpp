#include "rcm/live/trajectory_player.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace rcm {

namespace {

constexpr double kNs = 1e-9;

}  // namespace

void PlayerOptions::check(const std::function<InputLocation(const std::string&)>& where) const {
  auto positive_list = [&](const std::vector<double>& v, const char* name) {
    if (v.empty()) throw InputError(where(name), "needs at least one value");
    for (double x : v)
      if (!(x > 0) || !std::isfinite(x)) throw InputError(where(name), "every value must be a finite number > 0");
  };
  positive_list(max_tracking_error, "max_tracking_error");
  positive_list(goal_tolerance, "goal_tolerance");
  if (!(measured_timeout_s > 0)) throw InputError(where("measured_timeout_s"), "must be > 0");
  if (!(start_timeout_s > 0)) throw InputError(where("start_timeout_s"), "must be > 0");
  if (!(move_timeout_s > 0)) throw InputError(where("move_timeout_s"), "must be > 0");
  if (!(settle_s >= 0)) throw InputError(where("settle_s"), "must be >= 0");
  if (!(stall_s >= 0) || !std::isfinite(stall_s)) throw InputError(where("stall_s"), "must be a finite number >= 0");
}

const char* to_string(PlayerPhase phase) {
  switch (phase) {
    case PlayerPhase::starting: return "starting";
    case PlayerPhase::moving: return "moving to the first row";
    case PlayerPhase::streaming: return "streaming";
    case PlayerPhase::done: return "done";
    case PlayerPhase::refused: return "refused";
    case PlayerPhase::stopped: return "stopped";
  }
  return "?";
}

TrajectoryPlayer::TrajectoryPlayer(const JointTrajectory& trajectory, const PlayerOptions& options)
    : trajectory_(trajectory), options_(options) {
  if (trajectory_.num_samples() < 1) throw std::invalid_argument("TrajectoryPlayer: an empty trajectory");
  summary_.rows = trajectory_.num_samples();
  summary_.file_duration_s = trajectory_.time[trajectory_.time.size() - 1] - trajectory_.time[0];
  if (trajectory_.num_samples() >= 2)
    half_row_period_s_ = 0.5 * summary_.file_duration_s / static_cast<double>(trajectory_.num_samples() - 1);
}

TrajectoryPlayer::TrajectoryPlayer(double record_s, const PlayerOptions& options)
    : record_only_(true), record_s_(record_s), options_(options) {
  if (!(record_s > 0)) throw std::invalid_argument("TrajectoryPlayer: record_s must be > 0");
  summary_.file_duration_s = record_s;
}

double TrajectoryPlayer::limit(const std::vector<double>& values, std::size_t joint) const {
  return values[std::min(joint, values.size() - 1)];
}

const PlayerCommand& TrajectoryPlayer::none() {
  command_.kind = PlayerCommand::Kind::none;
  return command_;
}

void TrajectoryPlayer::refuse(const std::string& why) {
  phase_ = PlayerPhase::refused;
  summary_.message = why;
}

void TrajectoryPlayer::stop(const std::string& why, bool hold) {
  phase_ = PlayerPhase::stopped;
  summary_.message = why;
  if (hold && !measured_.empty()) {
    // Hold where the arm is, rather than pulling it on toward a setpoint it cannot follow.
    command_.kind = PlayerCommand::Kind::servo_jp;
    command_.position = measured_;
    command_.velocity.assign(measured_.size(), 0.0);
  }
}

void TrajectoryPlayer::finish() {
  phase_ = PlayerPhase::done;
  summary_.message =
      record_only_ ? fmt::format("recorded {} samples over {:.3f} s of the arm's time", summary_.samples_recorded,
                                 summary_.recorded_span_s)
                   : fmt::format("played {} rows over {:.3f} s of the arm's time (the file: {:.3f} s{}), recorded {} "
                                 "samples",
                                 summary_.rows_sent, summary_.sent_span_s, summary_.file_duration_s,
                                 summary_.stalls > 0 ? fmt::format("; paused {:.3f} s over {} stall{} of the stream",
                                                                   summary_.paused_s, summary_.stalls,
                                                                   summary_.stalls > 1 ? "s" : "")
                                                     : std::string(),
                                 summary_.samples_recorded);
}

double TrajectoryPlayer::get_lateness_s(std::int64_t age_ns, std::int64_t stamp_ns, std::int64_t previous_stamp_ns,
                                        std::int64_t wall_ns) {
  if (first_measured_stamp_ns_ < 0) {
    first_measured_stamp_ns_ = stamp_ns;
    first_measured_wall_ns_ = wall_ns;
  }
  if (age_ns < 0) return 0.0;
  // The floor may rise by 1 ms per second of the arm: far faster than two
  // machines' clocks drift apart, far slower than a stall builds up.
  const std::int64_t rise = previous_stamp_ns > 0 ? (stamp_ns - previous_stamp_ns) / 1000 : 0;
  age_floor_ns_ = age_floor_ns_ < 0 ? age_ns : std::min(age_ns, age_floor_ns_ + rise);
  // The arm's clock against the wall (a simulator may run faster), once the
  // two have run long enough to tell.
  const double wall_span = static_cast<double>(wall_ns - first_measured_wall_ns_) * kNs;
  const double scale =
      wall_span > 0.2 ? static_cast<double>(stamp_ns - first_measured_stamp_ns_) * kNs / wall_span : 1.0;
  return static_cast<double>(age_ns - age_floor_ns_) * kNs * scale;
}

bool TrajectoryPlayer::check_measured(const JointStateView& m, std::int64_t stamp_ns) {
  const std::size_t n = names_.empty() ? m.position.size() : names_.size();
  bool ok = n >= 1 && m.position.size() == n && m.velocity.size() == n && m.effort.size() == n && stamp_ns > 0 &&
            stamp_ns > last_stamp_ns_;
  for (std::size_t j = 0; ok && j < n; ++j)
    ok = std::isfinite(m.position[j]) && std::isfinite(m.velocity[j]) && std::isfinite(m.effort[j]);
  if (!ok) ++summary_.rejected;
  return ok;
}

void TrajectoryPlayer::record(const JointStateView& m, std::int64_t stamp_ns) {
  const double t = static_cast<double>(stamp_ns / 1000000000) + static_cast<double>(stamp_ns % 1000000000) * kNs;
  time_.push_back(t);
  position_.insert(position_.end(), m.position.begin(), m.position.end());
  velocity_.insert(velocity_.end(), m.velocity.begin(), m.velocity.end());
  effort_.insert(effort_.end(), m.effort.begin(), m.effort.end());
  ++summary_.samples_recorded;
  summary_.recorded_span_s = t - time_.front();
}

const PlayerCommand& TrajectoryPlayer::compute_operating_state(const std::string& state, bool homed, bool busy,
                                                               std::int64_t wall_ns) {
  if (first_wall_ns_ < 0) first_wall_ns_ = wall_ns;
  none();
  state_ = state;
  homed_ = homed;
  busy_ = busy;
  if ((phase_ == PlayerPhase::moving || phase_ == PlayerPhase::streaming) && state != "ENABLED") {
    stop(fmt::format("the arm left ENABLED: it is now {}{}", state, homed ? "" : " and not homed"), false);
  }
  return command_;
}

void TrajectoryPlayer::add_setpoint(const JointStateView& m, std::int64_t stamp_ns) {
  bool ok = !m.position.empty();
  for (double v : m.position) ok = ok && std::isfinite(v);
  if (!ok) return;
  setpoints_[next_setpoint_].assign(m.position.begin(), m.position.end());
  setpoint_stamps_[next_setpoint_] = stamp_ns;
  next_setpoint_ = (next_setpoint_ + 1) % kSetpoints;
}

const std::vector<double>* TrajectoryPlayer::find_setpoint(std::int64_t stamp_ns, std::size_t joints) const {
  const std::vector<double>* best = nullptr;
  std::int64_t best_stamp = -1;
  for (std::size_t i = 0; i < kSetpoints; ++i)
    if (setpoint_stamps_[i] >= 0 && setpoint_stamps_[i] <= stamp_ns && setpoint_stamps_[i] > best_stamp &&
        setpoints_[i].size() == joints) {
      best = &setpoints_[i];
      best_stamp = setpoint_stamps_[i];
    }
  return best;
}

const PlayerCommand& TrajectoryPlayer::compute_tick(std::int64_t wall_ns) {
  if (first_wall_ns_ < 0) first_wall_ns_ = wall_ns;
  none();
  const double since_start = static_cast<double>(wall_ns - first_wall_ns_) * kNs;
  if (phase_ == PlayerPhase::starting && since_start > options_.start_timeout_s) {
    if (!state_ && last_measured_wall_ns_ < 0)
      refuse(fmt::format("no operating_state and no measured_js from the arm in {:g} s: is it running, on this "
                         "domain and namespace?",
                         options_.start_timeout_s));
    else if (!state_)
      refuse(fmt::format("no operating_state from the arm in {:g} s", options_.start_timeout_s));
    else
      refuse(fmt::format("no measured_js from the arm in {:g} s", options_.start_timeout_s));
  } else if ((phase_ == PlayerPhase::moving || phase_ == PlayerPhase::streaming) && last_measured_wall_ns_ >= 0 &&
             static_cast<double>(wall_ns - last_measured_wall_ns_) * kNs > options_.measured_timeout_s) {
    stop(fmt::format("measured_js stopped: none for {:g} s (the arm holds its last setpoint)",
                     options_.measured_timeout_s),
         false);
  }
  return command_;
}

const PlayerCommand& TrajectoryPlayer::compute_measured(const JointStateView& m, std::int64_t stamp_ns,
                                                        std::int64_t wall_ns, std::int64_t age_ns) {
  if (first_wall_ns_ < 0) first_wall_ns_ = wall_ns;
  none();
  if (finished() || !check_measured(m, stamp_ns)) return command_;
  const std::int64_t previous_stamp_ns = last_stamp_ns_;
  const double late_s = get_lateness_s(age_ns, stamp_ns, previous_stamp_ns, wall_ns);
  last_measured_wall_ns_ = wall_ns;
  last_stamp_ns_ = stamp_ns;
  const std::size_t n = m.position.size();
  if (names_.empty()) {
    names_ = m.name;
    if (names_.size() != n) {
      names_.clear();
      for (std::size_t j = 0; j < n; ++j) names_.push_back(fmt::format("joint_{}", j + 1));
    }
    error_sq_sum_.assign(n, 0.0);
    summary_.max_tracking_error.assign(n, 0.0);
    summary_.rms_tracking_error.assign(n, 0.0);
  }
  measured_.assign(m.position.begin(), m.position.end());

  if (phase_ == PlayerPhase::starting) {
    if (!state_) return command_;  // the state decides; the start timeout ends the wait
    if (*state_ != "ENABLED") {
      refuse(fmt::format("the arm is {}: enable it (state_command \"enable\", or the dVRK console) and home it", *state_));
      return command_;
    }
    if (!homed_) {
      refuse("the arm is ENABLED but not homed: home it (state_command \"home\", or the dVRK console)");
      return command_;
    }
    if (record_only_) {
      phase_ = PlayerPhase::streaming;
      start_stamp_ns_ = stamp_ns;
      record(m, stamp_ns);
      return command_;
    }
    const auto file_joints = static_cast<std::size_t>(trajectory_.num_joints());
    if (file_joints > n) {
      refuse(fmt::format("the trajectory has {} joints, the arm's measured_js {}", file_joints, n));
      return command_;
    }
    held_ = measured_;
    goal_ = held_;
    for (std::size_t j = 0; j < file_joints; ++j) goal_[j] = trajectory_.position(0, static_cast<Eigen::Index>(j));
    phase_ = PlayerPhase::moving;
    move_stamp_ns_ = stamp_ns;
    command_.kind = PlayerCommand::Kind::move_jp;
    command_.position = goal_;
    command_.velocity.clear();
    return command_;
  }

  if (phase_ == PlayerPhase::moving) {
    if (static_cast<double>(stamp_ns - move_stamp_ns_) * kNs > options_.move_timeout_s) {
      stop(fmt::format("the arm did not reach the first row within {:g} s of its time", options_.move_timeout_s),
           false);
      return command_;
    }
    if (busy_) return command_;
    for (std::size_t j = 0; j < n; ++j)
      if (std::abs(measured_[j] - goal_[j]) > limit(options_.goal_tolerance, j)) return command_;
    phase_ = PlayerPhase::streaming;
    start_stamp_ns_ = stamp_ns;
  }

  // Streaming (or recording only). A late message while rows remain pauses
  // the file by the arm time it covers: no row is due on it.
  const bool late = !record_only_ && options_.stall_s > 0 && summary_.rows_sent > 0 &&
                    next_row_ < trajectory_.num_samples() &&
                    late_s > std::max(options_.stall_s, static_cast<double>(stamp_ns - previous_stamp_ns) * kNs);
  if (late) {
    paused_ns_ += stamp_ns - previous_stamp_ns;
    summary_.paused_s = static_cast<double>(paused_ns_) * kNs;
    if (!in_stall_) ++summary_.stalls;
  }
  in_stall_ = late;
  const double elapsed = static_cast<double>(stamp_ns - start_stamp_ns_ - paused_ns_) * kNs;
  // A row (and the end) is due within half a period of the arm: the stamps
  // (whole nanoseconds) and the file's times (decimal seconds) round a period
  // apart, and each pause adds the stamps' rounding to the file's clock.
  // Compared exactly, the clock falls a nanosecond short of a row on one
  // message and finds two rows due on the next, a skipped row each time.
  // A message after a gap too short to pause on sends no row more than half
  // the file's period early.
  const double slack =
      previous_stamp_ns > 0
          ? std::min(0.5 * static_cast<double>(stamp_ns - previous_stamp_ns) * kNs, half_row_period_s_)
          : 1e-9;
  const double end_s = record_only_ ? record_s_ : summary_.file_duration_s + options_.settle_s;
  if (elapsed > end_s + slack) {
    finish();
    return command_;
  }
  record(m, stamp_ns);

  // Tracking error against the arm's own setpoint, else against what was sent.
  const std::vector<double>* setpoint = find_setpoint(stamp_ns, n);
  const std::vector<double>& reference = setpoint ? *setpoint : last_sent_;
  if (reference.size() == n) {
    for (std::size_t j = 0; j < n; ++j) {
      const double e = std::abs(measured_[j] - reference[j]);
      summary_.max_tracking_error[j] = std::max(summary_.max_tracking_error[j], e);
      error_sq_sum_[j] += e * e;
    }
    ++error_count_;
    for (std::size_t j = 0; j < n; ++j) summary_.rms_tracking_error[j] = std::sqrt(error_sq_sum_[j] / error_count_);
    // A recorder commands nothing: whoever moves the arm (a surgeon, the
    // simulator's teleoperation) answers for its tracking, which tissue may
    // pull millimetres off; the error is reported, not acted on.
    for (std::size_t j = 0; !record_only_ && j < n; ++j)
      if (std::abs(measured_[j] - reference[j]) > limit(options_.max_tracking_error, j)) {
        stop(fmt::format("tracking error on {} ({}): {:.4g} beyond --max-tracking-error {:g}; the arm was told to "
                         "hold where it is",
                         names_[j], j + 1, std::abs(measured_[j] - reference[j]),
                         limit(options_.max_tracking_error, j)),
             true);
        return command_;
      }
  }

  if (!record_only_ && !late && next_row_ < trajectory_.num_samples()) {
    // The last row due by the arm's clock; rows due together are skipped but one.
    std::size_t due = next_row_;
    const double t0 = trajectory_.time[0];
    if (trajectory_.time[static_cast<Eigen::Index>(due)] - t0 <= elapsed + slack) {
      while (due + 1 < trajectory_.num_samples() &&
             trajectory_.time[static_cast<Eigen::Index>(due + 1)] - t0 <= elapsed + slack)
        ++due;
      summary_.rows_skipped += due - next_row_;
      const auto k = static_cast<Eigen::Index>(due);
      command_.kind = PlayerCommand::Kind::servo_jp;
      command_.position = held_;
      command_.velocity.assign(n, 0.0);
      for (Eigen::Index j = 0; j < trajectory_.num_joints(); ++j) {
        command_.position[static_cast<std::size_t>(j)] = trajectory_.position(k, j);
        command_.velocity[static_cast<std::size_t>(j)] = trajectory_.velocity(k, j);
      }
      last_sent_ = command_.position;
      if (summary_.rows_sent == 0) first_sent_stamp_ns_ = stamp_ns;
      last_sent_stamp_ns_ = stamp_ns;
      ++summary_.rows_sent;
      summary_.sent_span_s = static_cast<double>(last_sent_stamp_ns_ - first_sent_stamp_ns_) * kNs;
      next_row_ = due + 1;
    }
  }
  if (elapsed >= end_s - slack && (record_only_ || next_row_ >= trajectory_.num_samples())) finish();
  return command_;
}

Recording TrajectoryPlayer::get_recording(const std::string& source) const {
  Recording r;
  r.source = source;
  const auto T = static_cast<Eigen::Index>(time_.size());
  const auto N = static_cast<Eigen::Index>(names_.size());
  r.time = Eigen::Map<const Eigen::VectorXd>(time_.data(), T);
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  r.position = Eigen::Map<const RowMajor>(position_.data(), T, N);
  r.velocity = Eigen::Map<const RowMajor>(velocity_.data(), T, N);
  r.effort = Eigen::Map<const RowMajor>(effort_.data(), T, N);
  return r;
}

nlohmann::json to_json(const PlayerSummary& s, const std::vector<std::string>& names) {
  nlohmann::json max = nlohmann::json::object(), rms = nlohmann::json::object();
  for (std::size_t j = 0; j < s.max_tracking_error.size() && j < names.size(); ++j) {
    max[names[j]] = s.max_tracking_error[j];
    rms[names[j]] = s.rms_tracking_error[j];
  }
  nlohmann::json pacing = nullptr;
  if (s.rows_sent > 1 && s.file_duration_s > 0) pacing = (s.sent_span_s - s.file_duration_s) / s.file_duration_s;
  return {{"rows", s.rows},
          {"rows_sent", s.rows_sent},
          {"rows_skipped", s.rows_skipped},
          {"samples_recorded", s.samples_recorded},
          {"rejected", s.rejected},
          {"stalls", s.stalls},
          {"paused_s", s.paused_s},
          {"file_duration_s", s.file_duration_s},
          {"sent_span_s", s.sent_span_s},
          {"recorded_span_s", s.recorded_span_s},
          {"pacing_error", pacing},
          {"max_tracking_error", max},
          {"rms_tracking_error", rms},
          {"message", s.message}};
}

std::string format_player_summary(const PlayerSummary& s, const std::vector<std::string>& names) {
  std::string t = s.message + "\n";
  if (s.rows > 0)
    t += fmt::format("  rows sent {} of {} ({} skipped), over {:.4f} s of the arm's time against the file's {:.4f} s{}{}\n",
                     s.rows_sent, s.rows, s.rows_skipped, s.sent_span_s, s.file_duration_s,
                     s.rows_sent > 1 && s.file_duration_s > 0
                         ? fmt::format(" ({:+.3f} %)", 100.0 * (s.sent_span_s - s.file_duration_s) / s.file_duration_s)
                         : std::string(),
                     s.stalls > 0 ? fmt::format(", paused {:.4f} s over {} stall{}", s.paused_s, s.stalls,
                                                              s.stalls > 1 ? "s" : "")
                                  : std::string());
  t += fmt::format("  measured_js recorded {} over {:.4f} s, {} rejected\n", s.samples_recorded, s.recorded_span_s,
                   s.rejected);
  if (!s.max_tracking_error.empty()) {
    t += "  tracking error, max / RMS:";
    for (std::size_t j = 0; j < s.max_tracking_error.size() && j < names.size(); ++j)
      t += fmt::format(" {} {:.3g} / {:.3g}{}", names[j], s.max_tracking_error[j], s.rms_tracking_error[j],
                       j + 1 < s.max_tracking_error.size() ? ";" : "");
    t += "\n";
  }
  return t;
}

JointTrajectory make_hold_trajectory(const Eigen::VectorXd& q, double seconds, double rate_hz) {
  if (!(seconds > 0) || !(rate_hz > 0)) throw std::invalid_argument("make_hold_trajectory: seconds and rate must be > 0");
  const auto rows = static_cast<Eigen::Index>(std::llround(seconds * rate_hz)) + 1;
  JointTrajectory t;
  t.source = fmt::format("a hold of {:g} s", seconds);
  t.time.resize(rows);
  t.position.resize(rows, q.size());
  t.velocity = Eigen::MatrixXd::Zero(rows, q.size());
  for (Eigen::Index k = 0; k < rows; ++k) {
    t.time[k] = static_cast<double>(k) / rate_hz;
    t.position.row(k) = q.transpose();
  }
  return t;
}

}  // namespace rcm
