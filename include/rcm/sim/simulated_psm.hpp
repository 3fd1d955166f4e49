#pragma once
// A simulated dVRK Classic PSM behind the robot's own interfaces, without any
// middleware: what `rcm_sim_psm_dds` puts on CRTK topics. The bench's arm (its
// dynamics, friction, cables, controller and sensors: bench_arm.hpp) and its
// tissue (tissue.hpp, with the closed-loop bench's moving incision,
// closed_loop.hpp) behind the commands a dVRK takes:
//
//   - state commands (CRTK `state_command`): enable, disable, home, pause,
//     resume; the operating state DISABLED / ENABLED / PAUSED / FAULT, is_homed
//     and is_busy as `operating_state` reports them;
//   - `servo_jp`: a direct setpoint of every joint, no interpolation;
//   - `move_jp`: the arm's own trajectory to a goal (a quintic within
//     move_velocity_max and move_acceleration_max), busy while it moves;
//   - with teleop, the bench's surgeon motion about the RCM once no command
//     came for teleop_idle_s (from the docking pose q0 of the configuration);
//   - sim-only: where the incision is (free space, placed, or moving as an
//     IncisionMotion) and, with software_rcm, the RCM setpoint's shift.
//
// Motion is refused unless ENABLED and homed. A bad command (wrong joint
// count, a value that is not finite, a position beyond the joint limits, a
// servo_jp jump larger than max_servo_step) is rejected and counted: the arm
// never moves on it. The first three joints are the bench's arm; the wrist
// (joints 4-6) is kinematic: it reads what it is told, with effort noise only.
//
// Time is the arm's own: compute_step advances it by one publishing period
// (1 / rate_hz) in physics steps of the bench's rate or finer (a whole number
// of them per period). Disabled or in FAULT the motors are off and the arm
// stands still (a real PSM's unpowered joints may sag; this one does not).
//
// The model (SimulatedPsm) is immutable; everything that changes is in
// SimulatedPsmState. compute_step allocates nothing except when teleoperation
// starts (its path is drawn then).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <random>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/sim/bench_arm.hpp"
#include "rcm/sim/closed_loop.hpp"
#include "rcm/sim/sim_config.hpp"
#include "rcm/sim/tissue.hpp"
#include "rcm/sim/trajectory.hpp"

namespace rcm::sim {

inline constexpr int kPsmJoints = 6;
using PsmVector = Eigen::Matrix<double, kPsmJoints, 1>;

// The dVRK's names of a PSM's joints, in the order of its measured_js.
const std::array<const char*, kPsmJoints>& get_psm_joint_names();

enum class PsmOperatingState { disabled, enabled, paused, fault };
// CRTK's words: "DISABLED", "ENABLED", "PAUSED", "FAULT".
const char* to_string(PsmOperatingState state);

enum class PsmCommandVerdict {
  accepted,
  wrong_joint_count,  // not one value per joint
  not_finite,         // NaN or infinite
  beyond_limits,      // a position beyond the joint limits
  jump,               // a servo_jp further than max_servo_step from the setpoint
  not_ready,          // motion while not ENABLED or not homed
  unknown_command,    // a state or sim command the arm does not know, or malformed
  refused,            // a command the present state does not allow (home in FAULT, a shift beyond the limit)
};
const char* to_string(PsmCommandVerdict verdict);

struct SimulatedPsmOptions {
  double rate_hz = 1000.0;  // measured_js per second of the arm's time (the dVRK: 100 Hz to 1.5 kHz)
  bool teleop = false;
  double teleop_idle_s = 0.5;  // without a command this long (arm time), teleoperation plays
  bool software_rcm = false;   // the RCM setpoint may shift (set_rcm_shift)
  double max_shift_rate_m_per_s = 0.05;  // the arm follows a commanded shift at most this fast
  double max_shift_m = 0.05;             // and no further than this from the docked RCM
  Eigen::Vector3d move_velocity_max = Eigen::Vector3d(1.0, 1.0, 0.1);      // move_jp, home: rad/s, rad/s, m/s
  Eigen::Vector3d move_acceleration_max = Eigen::Vector3d(4.0, 4.0, 0.4);  // rad/s^2, rad/s^2, m/s^2
  Eigen::Vector3d max_servo_step = Eigen::Vector3d(0.1, 0.1, 0.01);       // rad, rad, m (the wrist: the first)
  // A servo_jp's velocity feeds the controller forward until the next
  // servo_jp, or until this much of the arm's time passes without one (the
  // stream stopped: the setpoint comes to rest). Far longer than a period, so
  // that a setpoint a period late over the network moves the arm as it should.
  double servo_velocity_hold_s = 0.02;
  Eigen::Vector3d wrist_limit_rad = Eigen::Vector3d(4.5, 1.5, 1.5);        // |q| of joints 4-6
  // Throws InputError at `where(name)` for a value out of range.
  void check(const std::function<InputLocation(const std::string&)>& where) const;
};

// What the arm publishes once per period, stamped with `time`.
struct PsmSample {
  double time = 0.0;  // the arm's clock, s from its start
  PsmVector position = PsmVector::Zero(), velocity = PsmVector::Zero(), effort = PsmVector::Zero();  // measured_js
  PsmVector setpoint = PsmVector::Zero(), setpoint_velocity = PsmVector::Zero();                    // setpoint_js
  PsmOperatingState state = PsmOperatingState::disabled;
  bool homed = false, busy = false;
  // The bench's truth (never what a real arm publishes): the tissue's force
  // on the incision (base frame, N), the incision relative to the RCM as it now
  // is (incision frame of the docking pose, m), the software shift in effect
  // (base frame, m).
  bool tissue_engaged = false;
  Eigen::Vector3d f_inc_base = Eigen::Vector3d::Zero();
  Eigen::Vector3d misalignment_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d shift_base = Eigen::Vector3d::Zero();
};

struct PsmCounters {
  std::uint64_t servo_accepted = 0, move_accepted = 0, state_accepted = 0, sim_accepted = 0, shift_accepted = 0;
  std::uint64_t wrong_joint_count = 0, not_finite = 0, beyond_limits = 0, jump = 0, not_ready = 0,
                unknown_command = 0, refused = 0;
  std::uint64_t faults = 0;  // times the arm went to FAULT
  // How a servo_jp stream met the arm's periods (a setpoint is taken as it
  // comes): periods between two servo_jp that began without a new one (the
  // setpoint held), servo_jp replaced by a later one before any period used
  // them (rows skipped), and the most periods in a row without one.
  std::uint64_t servo_held_periods = 0, servo_superseded = 0, servo_longest_gap_periods = 0;
  std::uint64_t get_rejected() const {
    return wrong_joint_count + not_finite + beyond_limits + jump + not_ready + unknown_command + refused;
  }
};

enum class PsmMotion { hold, servo, move, home, teleop };

struct SimulatedPsmState {
  double time = 0.0;
  std::uint64_t periods = 0;
  BenchArmState arm;
  BenchArmStep step;
  PsmOperatingState state = PsmOperatingState::disabled;
  bool homed = false;
  PsmMotion motion = PsmMotion::hold;
  // The setpoint of every joint (setpoint_js); joints 1-3 are the controller's reference.
  PsmVector setpoint = PsmVector::Zero(), setpoint_velocity = PsmVector::Zero();
  double servo_time = 0.0;  // of the last servo_jp: its velocity holds for servo_velocity_hold_s
  int servo_this_period = 0;       // servo_jp taken since the last period began
  std::uint64_t servo_gap = 0;     // periods in a row without one, in servo motion
  // move_jp and home: joints 1-3 a quintic, the wrist along the same profile.
  QuinticMove move;
  PsmVector move_from = PsmVector::Zero(), move_to = PsmVector::Zero();
  ReferenceTrajectory teleop;
  double teleop_start = 0.0;
  int teleop_count = 0;
  double last_command_time = 0.0;
  // The incision: none in free space; placed at `placed_m`, plus `incision_motion`
  // from `motion_start` on.
  std::optional<TissueModel> tissue;
  Eigen::Vector3d placed_m = Eigen::Vector3d::Zero();
  std::optional<IncisionMotion> incision_motion;
  double motion_start = 0.0;
  Eigen::Vector3d shift_base = Eigen::Vector3d::Zero(), shift_target_base = Eigen::Vector3d::Zero();
  Eigen::Vector3d shift_rate_base = Eigen::Vector3d::Zero();
  std::mt19937_64 rng, velocity_rng;
  std::normal_distribution<double> normal{0.0, 1.0};
  PsmSample sample;
  PsmCounters counters;
  std::string last_fault;  // why the arm went to FAULT
  std::uint64_t seed = 0;
};

class SimulatedPsm {
 public:
  // Throws InputError for a configuration or options out of range.
  SimulatedPsm(const SimConfig& config, const SimulatedPsmOptions& options);

  // DISABLED, not homed, at rest at the docking pose q0 (joints 4-6 at 0), in free space.
  SimulatedPsmState create_state(std::uint64_t seed) const;

  // One publishing period: the sample at the period's start is in
  // state.sample, then the arm's time advances by 1 / rate_hz.
  void compute_step(SimulatedPsmState& state) const;

  // Commands, applied at once (the next compute_step sees them). `velocity`
  // may be empty (servo_jp: no feedforward).
  PsmCommandVerdict apply_servo_jp(SimulatedPsmState& state, const double* position, std::size_t positions,
                                   const double* velocity, std::size_t velocities) const;
  PsmCommandVerdict apply_move_jp(SimulatedPsmState& state, const double* position, std::size_t positions) const;
  // enable, disable, home, pause, resume.
  PsmCommandVerdict apply_state_command(SimulatedPsmState& state, const std::string& command) const;
  // Sim only: "free_space"; "place DR_X DR_Y D" (m, incision frame of q0);
  // "motion NAME" (an IncisionMotion of make_default_incision_motions, from
  // now, added to the placement).
  PsmCommandVerdict apply_incision_command(SimulatedPsmState& state, const std::string& command) const;
  // With software_rcm: the shift of the RCM setpoint to reach (base frame, m,
  // from the docked RCM), followed at up to max_shift_rate_m_per_s.
  PsmCommandVerdict apply_rcm_shift(SimulatedPsmState& state, const Eigen::Vector3d& shift_base) const;

  const SimulatedPsmOptions& options() const { return options_; }
  const SimConfig& config() const { return config_; }
  double period_s() const { return 1.0 / options_.rate_hz; }
  int substeps() const { return substeps_; }
  const PsmVector& home() const { return home_; }
  const PsmVector& q_min() const { return q_min_; }
  const PsmVector& q_max() const { return q_max_; }

 private:
  ReferenceSample get_reference(const SimulatedPsmState& state, double t, PsmVector& setpoint) const;
  PsmCommandVerdict check_positions(SimulatedPsmState& state, const double* position, std::size_t n) const;
  void start_move(SimulatedPsmState& state, const PsmVector& goal, PsmMotion motion) const;
  void start_teleop(SimulatedPsmState& state) const;
  void update_incision(SimulatedPsmState& state, double t) const;
  void fill_sample(SimulatedPsmState& state) const;
  PsmCommandVerdict count(SimulatedPsmState& state, PsmCommandVerdict verdict, std::uint64_t& accepted) const;

  SimulatedPsmOptions options_;
  int substeps_;
  SimConfig config_;  // with the physics rate the period divides into substeps_ steps
  BenchArm arm_;
  PsmVector home_, q_min_, q_max_;
  std::vector<IncisionMotion> motions_;
};

}  // namespace rcm::sim
