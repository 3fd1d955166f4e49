#include "rcm/sim/simulated_psm.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/bench.hpp"

namespace rcm::sim {

namespace {

// The normalized quintic from rest to rest, and its rate, at x in [0, 1].
double quintic(double x) { return x * x * x * (10.0 + x * (-15.0 + 6.0 * x)); }
double quintic_rate(double x) { return 30.0 * x * x * (1.0 - x) * (1.0 - x); }

// A rest-to-rest quintic over `distance` within a peak speed and a peak
// acceleration: its peak speed is 15/8 distance / T, its peak acceleration
// 10 / sqrt(3) distance / T^2.
double get_quintic_duration(double distance, double velocity_max, double acceleration_max) {
  const double d = std::abs(distance);
  return std::max(1.875 * d / velocity_max, std::sqrt(5.773502691896258 * d / acceleration_max));
}

bool parse_number(const std::string& word, double& value) {
  char* end = nullptr;
  value = std::strtod(word.c_str(), &end);
  return end && *end == '\0' && !word.empty();
}

}  // namespace

const std::array<const char*, kPsmJoints>& get_psm_joint_names() {
  static const std::array<const char*, kPsmJoints> names = {"outer_yaw",  "outer_pitch",       "outer_insertion",
                                                            "outer_roll", "outer_wrist_pitch", "outer_wrist_yaw"};
  return names;
}

const char* to_string(PsmOperatingState state) {
  switch (state) {
    case PsmOperatingState::disabled: return "DISABLED";
    case PsmOperatingState::enabled: return "ENABLED";
    case PsmOperatingState::paused: return "PAUSED";
    case PsmOperatingState::fault: return "FAULT";
  }
  return "?";
}

const char* to_string(PsmCommandVerdict verdict) {
  switch (verdict) {
    case PsmCommandVerdict::accepted: return "accepted";
    case PsmCommandVerdict::wrong_joint_count: return "wrong joint count";
    case PsmCommandVerdict::not_finite: return "not finite";
    case PsmCommandVerdict::beyond_limits: return "beyond the joint limits";
    case PsmCommandVerdict::jump: return "jump";
    case PsmCommandVerdict::not_ready: return "not ready (not ENABLED or not homed)";
    case PsmCommandVerdict::unknown_command: return "unknown command";
    case PsmCommandVerdict::refused: return "refused";
  }
  return "?";
}

void SimulatedPsmOptions::check(const std::function<InputLocation(const std::string&)>& where) const {
  if (!(rate_hz >= 10.0 && rate_hz <= 5000.0)) throw InputError(where("rate_hz"), "must be in [10, 5000] Hz");
  if (!(teleop_idle_s > 0)) throw InputError(where("teleop_idle_s"), "must be > 0");
  if (!(max_shift_rate_m_per_s > 0)) throw InputError(where("max_shift_rate_m_per_s"), "must be > 0");
  if (!(max_shift_m > 0)) throw InputError(where("max_shift_m"), "must be > 0");
  if (!((move_velocity_max.array() > 0).all() && move_velocity_max.allFinite()))
    throw InputError(where("move_velocity_max"), "must be > 0 on every joint");
  if (!((move_acceleration_max.array() > 0).all() && move_acceleration_max.allFinite()))
    throw InputError(where("move_acceleration_max"), "must be > 0 on every joint");
  if (!((max_servo_step.array() > 0).all() && max_servo_step.allFinite()))
    throw InputError(where("max_servo_step"), "must be > 0 on every joint");
  if (!(servo_velocity_hold_s > 0 && std::isfinite(servo_velocity_hold_s)))
    throw InputError(where("servo_velocity_hold_s"), "must be > 0");
  if (!((wrist_limit_rad.array() > 0).all() && wrist_limit_rad.allFinite()))
    throw InputError(where("wrist_limit_rad"), "must be > 0 on every joint");
}

namespace {

SimConfig with_physics_rate(SimConfig config, double physics_rate_hz) {
  config.controller.physics_rate_hz = physics_rate_hz;
  return config;
}

}  // namespace

SimulatedPsm::SimulatedPsm(const SimConfig& config, const SimulatedPsmOptions& options)
    : options_(options),
      substeps_(get_physics_steps_per_period(config, options.rate_hz)),
      config_(with_physics_rate(config, options.rate_hz * substeps_)),
      arm_(config_),
      motions_(make_default_incision_motions()) {
  options_.check([](const std::string& name) { return InputLocation::plain("SimulatedPsmOptions", name); });
  validate_config(config_, "simulated PSM configuration");
  const PsmModel robot = load_robot_model(config_.robot);
  home_.setZero();
  home_.head<3>() = config_.protocol.q0;
  for (int j = 0; j < 3; ++j) {
    q_min_[j] = robot.joints()[static_cast<std::size_t>(j)].q_min;
    q_max_[j] = robot.joints()[static_cast<std::size_t>(j)].q_max;
  }
  q_min_.tail<3>() = -options_.wrist_limit_rad;
  q_max_.tail<3>() = options_.wrist_limit_rad;
}

SimulatedPsmState SimulatedPsm::create_state(std::uint64_t seed) const {
  SimulatedPsmState s;
  s.arm = make_bench_arm_state(arm_, home_.head<3>());
  s.setpoint = home_;
  s.rng.seed(derive_seed(seed, "noise:simulated-psm"));
  s.velocity_rng.seed(derive_seed(seed, "noise:simulated-psm:velocity"));
  s.teleop_count = 0;
  s.seed = seed;
  fill_sample(s);
  return s;
}

ReferenceSample SimulatedPsm::get_reference(const SimulatedPsmState& s, double t, PsmVector& setpoint) const {
  ReferenceSample r;
  switch (s.motion) {
    case PsmMotion::hold:
      r.q = setpoint.head<3>();
      break;
    case PsmMotion::servo:
      r.q = setpoint.head<3>();
      if (t - s.servo_time < options_.servo_velocity_hold_s) r.qd = s.setpoint_velocity.head<3>();
      break;
    case PsmMotion::move:
    case PsmMotion::home: {
      r = s.move.evaluate(t);
      const double x = std::clamp((t - s.move.t0) / s.move.duration, 0.0, 1.0);
      setpoint.head<3>() = r.q;
      setpoint.tail<3>() = s.move_from.tail<3>() + (s.move_to.tail<3>() - s.move_from.tail<3>()) * quintic(x);
      break;
    }
    case PsmMotion::teleop:
      r = s.teleop.evaluate(t - s.teleop_start);
      setpoint.head<3>() = r.q;
      break;
  }
  return r;
}

void SimulatedPsm::start_move(SimulatedPsmState& s, const PsmVector& goal, PsmMotion motion) const {
  PsmVector setpoint = s.setpoint;
  ReferenceSample from = get_reference(s, s.time, setpoint);
  from.q = setpoint.head<3>();
  double T = 0.05;
  for (int j = 0; j < kPsmJoints; ++j) {
    const int limit = j < 3 ? j : 0;  // the wrist moves within joint 1's limits
    T = std::max(T, get_quintic_duration(goal[j] - setpoint[j], options_.move_velocity_max[limit],
                                         options_.move_acceleration_max[limit]));
  }
  s.move = QuinticMove::make(s.time, T, from, goal.head<3>());
  s.move_from = setpoint;
  s.move_to = goal;
  s.setpoint = setpoint;
  s.motion = motion;
}

void SimulatedPsm::start_teleop(SimulatedPsmState& s) const {
  const Eigen::Vector3d& q0 = config_.protocol.q0;
  ++s.teleop_count;
  s.teleop = ReferenceTrajectory();
  s.teleop.add_hold(0.0, s.setpoint.head<3>());
  double T = 0.05;
  for (int j = 0; j < 3; ++j)
    T = std::max(T, get_quintic_duration(q0[j] - s.setpoint[j], options_.move_velocity_max[j],
                                         options_.move_acceleration_max[j]));
  s.teleop.add_move(0.0, T, q0);
  // An hour of the bench's surgeon motion per idle spell: a new draw each time.
  s.teleop.add_path(T, std::make_shared<const TeleopPath>(
                           config_.trajectory, q0,
                           derive_seed(s.seed, "path:teleop:" + std::to_string(s.teleop_count)), 3600.0));
  s.teleop_start = s.time;
  s.motion = PsmMotion::teleop;
}

void SimulatedPsm::update_incision(SimulatedPsmState& s, double t) const {
  if (options_.software_rcm) {
    Eigen::Vector3d delta = s.shift_target_base - s.shift_base;
    const double max_step = options_.max_shift_rate_m_per_s * arm_.dt;
    const double n = delta.norm();
    if (n > max_step) delta *= max_step / n;
    s.shift_base += delta;
    s.shift_rate_base = delta / arm_.dt;
  }
  if (!s.tissue) return;
  Eigen::Vector3d m = s.placed_m, rate = Eigen::Vector3d::Zero();
  if (s.incision_motion) {
    m += s.incision_motion->get_misalignment(t - s.motion_start);
    rate += s.incision_motion->get_misalignment_rate(t - s.motion_start);
  }
  const Eigen::Matrix3d& R = s.tissue->R_base_inc;
  set_tissue_misalignment(*s.tissue, m - R.transpose() * s.shift_base, rate - R.transpose() * s.shift_rate_base);
}

void SimulatedPsm::fill_sample(SimulatedPsmState& s) const {
  const SensorParams& S = arm_.sensors;
  PsmSample& out = s.sample;
  out.time = s.time;
  out.state = s.state;
  out.homed = s.homed;
  out.busy = s.motion == PsmMotion::move || s.motion == PsmMotion::home;
  out.setpoint = s.setpoint;
  out.setpoint_velocity = s.setpoint_velocity;
  const bool powered = s.state == PsmOperatingState::enabled || s.state == PsmOperatingState::paused;
  if (powered) {
    out.position.head<3>() = s.step.q_meas;
    out.velocity.head<3>() =
        compute_published_velocity(S, s.step.v_meas, s.arm.plant.qmd, s.velocity_rng, s.normal);
    out.effort.head<3>() = compute_sensed_effort(S, s.step.tau, s.rng, s.normal);
  } else {
    out.position.head<3>() = compute_measured_position(S, s.arm.plant.qm);
    out.velocity.head<3>().setZero();
    out.effort.head<3>() = compute_sensed_effort(S, Eigen::Vector3d::Zero(), s.rng, s.normal);
  }
  // The wrist reads what it is told; its current sensors are as noisy as the yaw's.
  out.position.tail<3>() = s.setpoint.tail<3>();
  out.velocity.tail<3>() = powered ? Eigen::Vector3d(s.setpoint_velocity.tail<3>()) : Eigen::Vector3d::Zero();
  for (int j = 3; j < kPsmJoints; ++j) out.effort[j] = S.noise ? S.effort_noise[0] * s.normal(s.rng) : 0.0;
  out.tissue_engaged = s.tissue.has_value();
  out.f_inc_base = powered ? s.step.tissue.f_inc_base : Eigen::Vector3d::Zero();
  out.misalignment_m = s.tissue ? s.tissue->misalignment_m : Eigen::Vector3d::Zero();
  out.shift_base = s.shift_base;
}

void SimulatedPsm::compute_step(SimulatedPsmState& s) const {
  if (s.motion == PsmMotion::servo) {
    if (s.servo_this_period == 0) ++s.servo_gap;
    else s.counters.servo_superseded += static_cast<std::uint64_t>(s.servo_this_period - 1);
  } else {
    s.servo_gap = 0;
  }
  s.servo_this_period = 0;
  for (int i = 0; i < substeps_; ++i) {
    const double t = static_cast<double>(s.periods * static_cast<std::uint64_t>(substeps_) +
                                         static_cast<std::uint64_t>(i)) * arm_.dt;
    s.time = t;
    const bool enabled = s.state == PsmOperatingState::enabled;
    if ((s.motion == PsmMotion::move || s.motion == PsmMotion::home) && t >= s.move.t0 + s.move.duration) {
      if (s.motion == PsmMotion::home && enabled) s.homed = true;
      s.setpoint = s.move_to;
      s.setpoint_velocity.setZero();
      s.motion = PsmMotion::hold;
      s.last_command_time = t;
    }
    if (options_.teleop && enabled && s.homed && (s.motion == PsmMotion::hold || s.motion == PsmMotion::servo) &&
        t - s.last_command_time >= options_.teleop_idle_s)
      start_teleop(s);
    const ReferenceSample ref = get_reference(s, t, s.setpoint);
    if (s.motion == PsmMotion::move || s.motion == PsmMotion::home || s.motion == PsmMotion::teleop) {
      s.setpoint_velocity.head<3>() = ref.qd;
      if (s.motion != PsmMotion::teleop) {
        const double x = std::clamp((t - s.move.t0) / s.move.duration, 0.0, 1.0);
        s.setpoint_velocity.tail<3>() =
            (s.move_to.tail<3>() - s.move_from.tail<3>()) * (quintic_rate(x) / s.move.duration);
      }
    } else if (s.motion == PsmMotion::servo && t - s.servo_time >= options_.servo_velocity_hold_s) {
      s.setpoint_velocity.setZero();
    }
    update_incision(s, t);
    const TissueModel* tissue = s.tissue ? &*s.tissue : nullptr;
    bool powered = enabled || s.state == PsmOperatingState::paused;
    if (powered) {
      try {
        compute_bench_arm_step(arm_, s.arm, ref, tissue, s.step);
      } catch (const std::domain_error& e) {
        // The shaft too flat to the pad: the motion is outside what the
        // phantom simulates. The arm stops, as a dVRK faults on its safety checks.
        s.state = PsmOperatingState::fault;
        s.motion = PsmMotion::hold;
        s.last_fault = e.what();
        ++s.counters.faults;
        s.arm.plant.qd.setZero();
        s.arm.plant.qmd.setZero();
        s.arm.velocity_filtered.setZero();
        powered = false;
      }
    }
    if (i == 0) fill_sample(s);
    if (powered) advance_bench_arm_state(arm_, s.arm, s.step, tissue);
  }
  ++s.periods;
  s.time = static_cast<double>(s.periods * static_cast<std::uint64_t>(substeps_)) * arm_.dt;
}

PsmCommandVerdict SimulatedPsm::count(SimulatedPsmState& s, PsmCommandVerdict v, std::uint64_t& accepted) const {
  PsmCounters& c = s.counters;
  switch (v) {
    case PsmCommandVerdict::accepted: ++accepted; break;
    case PsmCommandVerdict::wrong_joint_count: ++c.wrong_joint_count; break;
    case PsmCommandVerdict::not_finite: ++c.not_finite; break;
    case PsmCommandVerdict::beyond_limits: ++c.beyond_limits; break;
    case PsmCommandVerdict::jump: ++c.jump; break;
    case PsmCommandVerdict::not_ready: ++c.not_ready; break;
    case PsmCommandVerdict::unknown_command: ++c.unknown_command; break;
    case PsmCommandVerdict::refused: ++c.refused; break;
  }
  return v;
}

PsmCommandVerdict SimulatedPsm::check_positions(SimulatedPsmState& s, const double* p, std::size_t n) const {
  if (n != static_cast<std::size_t>(kPsmJoints)) return PsmCommandVerdict::wrong_joint_count;
  for (std::size_t j = 0; j < n; ++j)
    if (!std::isfinite(p[j])) return PsmCommandVerdict::not_finite;
  for (int j = 0; j < kPsmJoints; ++j)
    if (p[j] < q_min_[j] || p[j] > q_max_[j]) return PsmCommandVerdict::beyond_limits;
  if (s.state != PsmOperatingState::enabled || !s.homed) return PsmCommandVerdict::not_ready;
  return PsmCommandVerdict::accepted;
}

PsmCommandVerdict SimulatedPsm::apply_servo_jp(SimulatedPsmState& s, const double* p, std::size_t n, const double* v,
                                               std::size_t nv) const {
  PsmCommandVerdict verdict = check_positions(s, p, n);
  if (verdict == PsmCommandVerdict::accepted && nv != 0 && nv != static_cast<std::size_t>(kPsmJoints))
    verdict = PsmCommandVerdict::wrong_joint_count;
  for (std::size_t j = 0; verdict == PsmCommandVerdict::accepted && j < nv; ++j)
    if (!std::isfinite(v[j])) verdict = PsmCommandVerdict::not_finite;
  if (verdict == PsmCommandVerdict::accepted)
    for (int j = 0; j < kPsmJoints; ++j)
      if (std::abs(p[j] - s.setpoint[j]) > options_.max_servo_step[j < 3 ? j : 0])
        verdict = PsmCommandVerdict::jump;
  if (verdict != PsmCommandVerdict::accepted) return count(s, verdict, s.counters.servo_accepted);
  for (int j = 0; j < kPsmJoints; ++j) {
    s.setpoint[j] = p[j];
    s.setpoint_velocity[j] = nv ? v[j] : 0.0;
  }
  if (s.motion == PsmMotion::servo && s.servo_gap > 0) {
    s.counters.servo_held_periods += s.servo_gap;
    s.counters.servo_longest_gap_periods = std::max(s.counters.servo_longest_gap_periods, s.servo_gap);
  }
  s.servo_gap = 0;
  ++s.servo_this_period;
  s.motion = PsmMotion::servo;
  s.servo_time = s.time;
  s.last_command_time = s.time;
  return count(s, verdict, s.counters.servo_accepted);
}

PsmCommandVerdict SimulatedPsm::apply_move_jp(SimulatedPsmState& s, const double* p, std::size_t n) const {
  const PsmCommandVerdict verdict = check_positions(s, p, n);
  if (verdict == PsmCommandVerdict::accepted) {
    PsmVector goal;
    for (int j = 0; j < kPsmJoints; ++j) goal[j] = p[j];
    start_move(s, goal, PsmMotion::move);
    s.last_command_time = s.time;
  }
  return count(s, verdict, s.counters.move_accepted);
}

PsmCommandVerdict SimulatedPsm::apply_state_command(SimulatedPsmState& s, const std::string& command) const {
  auto freeze = [&](PsmOperatingState to) {
    s.state = to;
    s.motion = PsmMotion::hold;
    s.setpoint_velocity.setZero();
    s.arm.plant.qd.setZero();
    s.arm.plant.qmd.setZero();
    s.arm.velocity_filtered.setZero();
  };
  auto enable = [&] {
    if (s.state == PsmOperatingState::enabled) return;
    s.state = PsmOperatingState::enabled;
    s.motion = PsmMotion::hold;
    s.setpoint.head<3>() = compute_measured_position(arm_.sensors, s.arm.plant.qm);
    s.setpoint_velocity.setZero();
    s.last_command_time = s.time;
  };
  PsmCommandVerdict v = PsmCommandVerdict::accepted;
  if (command == "enable") {
    enable();
  } else if (command == "disable") {
    freeze(PsmOperatingState::disabled);
  } else if (command == "home") {
    if (s.state == PsmOperatingState::fault || s.state == PsmOperatingState::paused) {
      v = PsmCommandVerdict::refused;
    } else {
      enable();  // as the dVRK's console: home powers the arm first
      start_move(s, home_, PsmMotion::home);
      s.last_command_time = s.time;
    }
  } else if (command == "pause") {
    if (s.state != PsmOperatingState::enabled) v = PsmCommandVerdict::refused;
    else {
      s.state = PsmOperatingState::paused;
      s.motion = PsmMotion::hold;
      s.setpoint_velocity.setZero();
    }
  } else if (command == "resume") {
    if (s.state != PsmOperatingState::paused) v = PsmCommandVerdict::refused;
    else {
      s.state = PsmOperatingState::enabled;
      s.last_command_time = s.time;
    }
  } else {
    v = PsmCommandVerdict::unknown_command;
  }
  return count(s, v, s.counters.state_accepted);
}

PsmCommandVerdict SimulatedPsm::apply_incision_command(SimulatedPsmState& s, const std::string& command) const {
  std::istringstream in(command);
  std::vector<std::string> words;
  for (std::string w; in >> w;) words.push_back(w);
  PsmCommandVerdict v = PsmCommandVerdict::unknown_command;
  if (words.size() == 1 && words[0] == "free_space") {
    s.tissue.reset();
    s.incision_motion.reset();
    s.arm.axial_z = 0.0;
    v = PsmCommandVerdict::accepted;
  } else if (words.size() == 4 && words[0] == "place") {
    Eigen::Vector3d m;
    bool ok = true;
    for (int i = 0; i < 3; ++i) ok = ok && parse_number(words[static_cast<std::size_t>(i) + 1], m[i]);
    if (!ok) v = PsmCommandVerdict::unknown_command;
    else if (!m.allFinite()) v = PsmCommandVerdict::not_finite;
    else if (m.cwiseAbs().maxCoeff() > 0.2) v = PsmCommandVerdict::refused;
    else {
      s.placed_m = m;
      s.incision_motion.reset();
      if (!s.tissue) s.arm.axial_z = 0.0;
      s.tissue.emplace(config_.tissue, config_.protocol.q0, m);
      update_incision(s, s.time);
      v = PsmCommandVerdict::accepted;
    }
  } else if (words.size() == 2 && words[0] == "motion") {
    const auto it = std::find_if(motions_.begin(), motions_.end(),
                                 [&](const IncisionMotion& m) { return m.name == words[1]; });
    if (it == motions_.end()) v = PsmCommandVerdict::unknown_command;
    else if (!s.tissue) v = PsmCommandVerdict::refused;  // no incision to move
    else {
      s.incision_motion = *it;
      s.motion_start = s.time;
      v = PsmCommandVerdict::accepted;
    }
  }
  return count(s, v, s.counters.sim_accepted);
}

PsmCommandVerdict SimulatedPsm::apply_rcm_shift(SimulatedPsmState& s, const Eigen::Vector3d& shift_base) const {
  PsmCommandVerdict v = PsmCommandVerdict::accepted;
  if (!options_.software_rcm) v = PsmCommandVerdict::refused;
  else if (!shift_base.allFinite()) v = PsmCommandVerdict::not_finite;
  else if (shift_base.norm() > options_.max_shift_m) v = PsmCommandVerdict::refused;
  else s.shift_target_base = shift_base;
  return count(s, v, s.counters.shift_accepted);
}

}  // namespace rcm::sim
