// rcm_sim_psm_dds: a simulated dVRK Classic PSM on ROS 2 (Cyclone DDS, no ROS 2
// needed), speaking CRTK as the dVRK's ROS 2 node does, under /<arm>/:
// measured_js and setpoint_js at --rate, operating_state; servo_jp, move_jp and
// state_command taken; the bench's truth on /<arm>/sim/... What the arm does is
// rcm::sim::SimulatedPsm (include/rcm/sim/simulated_psm.hpp); this file puts it
// on the wire and keeps its clock. Topics, flags: docs/howto-procedure.md.
//
//   rcm_sim_psm_dds [--arm PSM1] [--rate 1000] [--time-scale 1] [--teleop] [--software-rcm] [--seed 1]

#include <CLI/CLI.hpp>
#include <dds/dds.h>
#include <fmt/format.h>
#include <time.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <cstdio>
#include <string>
#include <vector>

#include "support/program_main.hpp"
#include "support/dds_io.hpp"
#include "rcm/common/command_line.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/sim/simulated_psm.hpp"
#include "ros2_msgs.h"

namespace {

using namespace rcm::dds_node;
using rcm::sim::PsmCommandVerdict;

void log(const char* level, const std::string& text) {
  std::fprintf(std::string(level) == "INFO" ? stdout : stderr, "[%s] [%.6f] [rcm_sim_psm_dds]: %s\n", level,
               static_cast<double>(get_wall_ns()) * 1e-9, text.c_str());
}

Eigen::Vector3d parse_vector(const std::string& text, const std::string& flag) {
  Eigen::Vector3d v;
  char c1 = 0, c2 = 0;
  std::size_t used = 0;
  if (std::sscanf(text.c_str(), "%lf%c%lf%c%lf%zn", &v[0], &c1, &v[1], &c2, &v[2], &used) < 5 || c1 != ',' ||
      c2 != ',' || used != text.size() || !v.allFinite())
    throw rcm::InputError(rcm::InputLocation::plain("command line", flag),
                          "expected three numbers separated by commas, got '" + text + "'");
  return v;
}

// Delays in the arm's time (s), in bins of 0.1 ms up to 1 s (and one beyond):
// what a summary line needs, without keeping every one.
class LoopDelayHistogram {
 public:
  void add(double delay_s) {
    const double bin = std::floor(delay_s / kBin);
    const auto i = static_cast<std::size_t>(std::clamp(bin, 0.0, static_cast<double>(kBins - 1)));
    ++bins_[i];
    ++count_;
    max_s_ = std::max(max_s_, delay_s);
  }
  std::uint64_t count() const { return count_; }
  double max_s() const { return max_s_; }
  // The upper edge of the bin holding the q-quantile.
  double get_quantile_s(double q) const {
    const auto target = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_)));
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kBins; ++i)
      if ((seen += bins_[i]) >= std::max<std::uint64_t>(target, 1)) return static_cast<double>(i + 1) * kBin;
    return max_s_;
  }

 private:
  static constexpr double kBin = 1e-4;
  static constexpr std::size_t kBins = 10001;
  std::vector<std::uint64_t> bins_ = std::vector<std::uint64_t>(kBins, 0);
  std::uint64_t count_ = 0;
  double max_s_ = 0.0;
};

struct Options {
  std::string arm = "PSM1";
  rcm::sim::SimulatedPsmOptions psm;
  double time_scale = 1.0;
  std::uint64_t seed = 1;
  std::string config_file, tissue, friction, arm_preset;
  double payload_kg = 0.0;
  std::string incision_offset, incision_motion;
  int domain = -1;
};

int run(int argc, char** argv) {
  Options o;
  CLI::App app{"rcm_sim_psm_dds: a simulated dVRK Classic PSM on ROS 2 (DDS), speaking CRTK under /<arm>/"};
  app.add_option("--arm", o.arm, "arm namespace: /<arm>/measured_js, /<arm>/servo_jp, ...")->capture_default_str();
  app.add_option("--rate", o.psm.rate_hz, "measured_js and setpoint_js per second of the arm's time (Hz, 100 to 1500)")
      ->capture_default_str();
  app.add_option("--time-scale", o.time_scale,
                 "the arm's clock runs this many times faster than the wall (stamps too; for tests and demos)")
      ->capture_default_str();
  app.add_option("--seed", o.seed, "seed of the sensors' noise and the teleoperation paths")->capture_default_str();
  app.add_flag("--teleop", o.psm.teleop, "play the bench's surgeon motion about the RCM when no command arrives");
  app.add_option("--teleop-idle-s", o.psm.teleop_idle_s, "arm time without a command before teleoperation plays (s)")
      ->capture_default_str();
  app.add_flag("--software-rcm", o.psm.software_rcm,
               "move the RCM setpoint to the shift the monitor commands on /<arm>/rcm/shift");
  app.add_option("--max-shift-rate-m-per-s", o.psm.max_shift_rate_m_per_s,
                 "software RCM: the arm follows the commanded shift at most this fast (m/s)")
      ->capture_default_str();
  app.add_option("--max-shift-m", o.psm.max_shift_m, "software RCM: a shift further than this is refused (m)")
      ->capture_default_str();
  app.add_option("--config", o.config_file, "simulator configuration (JSON of `rcm simulate --config`)");
  app.add_option("--tissue", o.tissue, "tissue preset: linear, stiffening, viscoelastic, sliding (default linear)");
  app.add_option("--friction", o.friction, "friction preset (default hysteretic; `rcm simulate --help` lists them)");
  app.add_option("--arm-model", o.arm_preset, "transmission preset: rigid or cable (default rigid)");
  app.add_option("--payload-kg", o.payload_kg, "mass added to the insertion stage (kg; a tool the model never saw)")
      ->capture_default_str();
  app.add_option("--incision-offset", o.incision_offset,
                 "engage the tissue from the start, the incision at dr_x,dr_y,D from the RCM (m; default free space)");
  app.add_option("--incision-motion", o.incision_motion,
                 "move the incision from the start: step, drift, breathing or large_step (the closed-loop bench's)");
  app.add_option("--domain", o.domain, "DDS domain (default: ROS_DOMAIN_ID, else 0)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return rcm::exit_on_parse_error(app, e);
  }
  const auto where = [](const std::string& name) {
    std::string flag = "--" + name;
    for (char& c : flag)
      if (c == '_') c = '-';
    return rcm::InputLocation::plain("command line", flag);
  };
  if (!(o.psm.rate_hz >= 100.0 && o.psm.rate_hz <= 1500.0))
    throw rcm::InputError(where("rate"), "must be in [100, 1500] Hz (the dVRK's rates)");
  if (!(o.time_scale > 0 && o.time_scale <= 100)) throw rcm::InputError(where("time_scale"), "must be in (0, 100]");
  if (!(o.payload_kg >= 0 && o.payload_kg <= 2)) throw rcm::InputError(where("payload_kg"), "must be in [0, 2] kg");
  o.psm.check(where);
  const int domain = get_domain(o.domain, "command line");

  rcm::sim::SimConfig config = rcm::sim::make_default_config();
  if (!o.tissue.empty()) rcm::sim::apply_tissue_preset(config.tissue, o.tissue);
  if (!o.arm_preset.empty()) rcm::sim::apply_arm_preset(config, o.arm_preset);
  if (!o.friction.empty()) rcm::sim::apply_friction_preset(config, o.friction);
  if (!o.config_file.empty())
    rcm::sim::apply_config_json(config, rcm::load_json_file(o.config_file), o.config_file);
  config.arm.insertion_stage.mass_kg += o.payload_kg;
  config.seed = o.seed;
  const rcm::sim::SimulatedPsm psm(config, o.psm);
  rcm::sim::SimulatedPsmState s = psm.create_state(o.seed);
  if (!o.incision_offset.empty()) {
    const Eigen::Vector3d m = parse_vector(o.incision_offset, "--incision-offset");
    if (psm.apply_incision_command(s, fmt::format("place {:.17g} {:.17g} {:.17g}", m[0], m[1], m[2])) !=
        PsmCommandVerdict::accepted)
      throw rcm::InputError(where("incision_offset"), "beyond 0.2 m");
  }
  if (!o.incision_motion.empty()) {
    if (o.incision_offset.empty()) psm.apply_incision_command(s, "place 0 0 0");
    if (psm.apply_incision_command(s, "motion " + o.incision_motion) != PsmCommandVerdict::accepted)
      throw rcm::InputError(where("incision_motion"), "unknown motion '" + o.incision_motion +
                                                          "'; known: step, drift, breathing, large_step");
  }

  const dds_entity_t participant =
      check(dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr), "create participant");
  const std::string ns = "/" + o.arm + "/";
  constexpr int kDepth = 100;  // the dVRK's
  const dds_entity_t measured_w = make_writer(participant, &sensor_msgs_msg_dds__JointState__desc, ns + "measured_js", kDepth);
  const dds_entity_t setpoint_w = make_writer(participant, &sensor_msgs_msg_dds__JointState__desc, ns + "setpoint_js", kDepth);
  const dds_entity_t state_w =
      make_writer(participant, &crtk_msgs_msg_dds__OperatingState__desc, ns + "operating_state", kDepth);
  const dds_entity_t force_w =
      make_writer(participant, &geometry_msgs_msg_dds__WrenchStamped__desc, ns + "sim/incision_force", kDepth);
  const dds_entity_t misalignment_w =
      make_writer(participant, &geometry_msgs_msg_dds__Vector3Stamped__desc, ns + "sim/misalignment", kDepth);
  const dds_entity_t shift_w =
      make_writer(participant, &geometry_msgs_msg_dds__Vector3Stamped__desc, ns + "sim/rcm_shift", kDepth);
  const dds_entity_t servo_r = make_reader(participant, &sensor_msgs_msg_dds__JointState__desc, ns + "servo_jp", 1000);
  const dds_entity_t move_r = make_reader(participant, &sensor_msgs_msg_dds__JointState__desc, ns + "move_jp", kDepth);
  const dds_entity_t command_r =
      make_reader(participant, &crtk_msgs_msg_dds__StringStamped__desc, ns + "state_command", kDepth);
  const dds_entity_t incision_r =
      make_reader(participant, &crtk_msgs_msg_dds__StringStamped__desc, ns + "sim/incision_command", kDepth);
  const dds_entity_t rcm_shift_r =
      o.psm.software_rcm
          ? make_reader(participant, &geometry_msgs_msg_dds__Vector3Stamped__desc, ns + "rcm/shift", 1000)
          : 0;

  std::vector<std::string> names(rcm::sim::get_psm_joint_names().begin(), rcm::sim::get_psm_joint_names().end());
  JointStateMessage measured_msg(names), setpoint_msg(names);
  const std::string base_frame = o.arm + "_base", incision_frame = o.arm + "_incision";

  log("INFO", fmt::format("rcm: simulated Classic PSM on {} (domain {}): measured_js and setpoint_js at {:g} Hz of the "
                          "arm's time ({} physics steps each), time scale {:g}; arm {}, friction {}, tissue {}{}; "
                          "takes servo_jp, move_jp, state_command{}{}",
                          ns, domain, o.psm.rate_hz, psm.substeps(), o.time_scale, config.arm.preset,
                          config.friction_preset, config.tissue.preset,
                          o.payload_kg > 0 ? fmt::format(", {:g} kg payload", o.payload_kg) : "",
                          o.psm.software_rcm ? ", rcm/shift (software RCM)" : "",
                          o.psm.teleop ? "; teleoperation when idle" : ""));
  log("INFO", fmt::format("rcm: {} at the docking pose, not homed; {}", to_string(s.state),
                          s.tissue ? "tissue engaged" : "free space"));

  // Rejections are counted and logged: every one of the first ten of each
  // kind, then one in a hundred.
  std::map<std::string, std::uint64_t> rejected;
  auto report = [&](const char* what, PsmCommandVerdict v, const std::string& detail) {
    if (v == PsmCommandVerdict::accepted) return;
    const std::string key = std::string(what) + ": " + to_string(v);
    const std::uint64_t n = ++rejected[key];
    if (n <= 10 || n % 100 == 0)
      log("WARN", fmt::format("rcm: {} rejected ({}){}; the arm did not move on it [{} so far]", what, to_string(v),
                              detail, n));
  };
  auto describe = [](const double* x, std::size_t n) {
    std::string t;
    for (std::size_t i = 0; i < n; ++i) t += fmt::format("{}{:.4g}", i ? ", " : "", x[i]);
    return " [" + t + "]";
  };
  // The stamps: the wall clock at the arm's time 0 plus the arm's time.
  const std::int64_t stamp0 = get_wall_ns();
  LoopDelayHistogram shift_delay;
  auto drain_commands = [&] {
    take_all(command_r, [&](const void* p) {
      const auto& m = *static_cast<const crtk_msgs_msg_dds__StringStamped_*>(p);
      const std::string c = m.string ? m.string : "";
      const PsmCommandVerdict v = psm.apply_state_command(s, c);
      if (v == PsmCommandVerdict::accepted) log("INFO", fmt::format("rcm: state_command {}: now {}", c, to_string(s.state)));
      report("state_command", v, " '" + c + "'");
    });
    take_all(incision_r, [&](const void* p) {
      const auto& m = *static_cast<const crtk_msgs_msg_dds__StringStamped_*>(p);
      const std::string c = m.string ? m.string : "";
      const PsmCommandVerdict v = psm.apply_incision_command(s, c);
      if (v == PsmCommandVerdict::accepted) log("INFO", fmt::format("rcm: t = {:.3f} s: incision: {}", s.time, c));
      report("sim/incision_command", v, " '" + c + "'");
    });
    take_all(move_r, [&](const void* p) {
      const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(p);
      report("move_jp", psm.apply_move_jp(s, m.position._buffer, m.position._length),
             describe(m.position._buffer, m.position._length));
    });
    take_all(servo_r, [&](const void* p) {
      const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(p);
      report("servo_jp",
             psm.apply_servo_jp(s, m.position._buffer, m.position._length, m.velocity._buffer, m.velocity._length),
             describe(m.position._buffer, m.position._length));
    });
    if (rcm_shift_r)
      take_all(rcm_shift_r, [&](const void* p) {
        const auto& m = *static_cast<const geometry_msgs_msg_dds__Vector3Stamped_*>(p);
        const Eigen::Vector3d v(m.vector.x, m.vector.y, m.vector.z);
        const PsmCommandVerdict verdict = psm.apply_rcm_shift(s, v);
        report("rcm/shift", verdict, describe(v.data(), 3));
        // The monitor stamps a shift with the sample it answers: the loop's
        // delay, in the arm's time, from that sample to the shift taken here.
        if (verdict == PsmCommandVerdict::accepted) shift_delay.add(s.time - (get_stamp_ns(m.header) - stamp0) * 1e-9);
      });
  };

  std::int64_t steady0 = get_steady_ns();
  const std::int64_t wall_start = steady0;
  std::int64_t last_state_wall = 0;
  rcm::sim::PsmOperatingState last_state = s.state;
  bool last_homed = false, last_busy = false;
  double slipped_s = 0.0;
  std::uint64_t slips = 0;
  const double period = psm.period_s();
  while (!rcm::dds_node::is_stop_requested()) {
    double due = static_cast<double>(get_steady_ns() - steady0) * 1e-9 * o.time_scale;
    // Behind the wall (a busy machine): the clock slips rather than catching
    // up in a burst of periods that no command could answer. The stamps stay
    // the arm's own, evenly spaced; only the wall's pace is lost.
    if (due - s.time > 2 * period) {
      const double slip = due - s.time - 2 * period;
      steady0 += std::llround(slip / o.time_scale * 1e9);
      due -= slip;
      slipped_s += slip;
      ++slips;
    }
    while (s.time <= due && !rcm::dds_node::is_stop_requested()) {
      drain_commands();
      psm.compute_step(s);
      const rcm::sim::PsmSample& x = s.sample;
      const std::int64_t stamp = stamp0 + std::llround(x.time * 1e9);
      // The setpoint first: a client holding measured_js against setpoint_js has both.
      dds_write(setpoint_w, setpoint_msg.fill(stamp, x.setpoint.data(), 6, x.setpoint_velocity.data(), 6, nullptr, 0));
      dds_write(measured_w, measured_msg.fill(stamp, x.position.data(), 6, x.velocity.data(), 6, x.effort.data(), 6));
      if (x.tissue_engaged) {
        geometry_msgs_msg_dds__WrenchStamped_ f{};
        f.header = make_header(stamp, base_frame.c_str());
        f.wrench.force = {x.f_inc_base[0], x.f_inc_base[1], x.f_inc_base[2]};
        dds_write(force_w, &f);
        geometry_msgs_msg_dds__Vector3Stamped_ v{};
        v.header = make_header(stamp, incision_frame.c_str());
        v.vector = {x.misalignment_m[0], x.misalignment_m[1], x.misalignment_m[2]};
        dds_write(misalignment_w, &v);
      }
      if (o.psm.software_rcm) {
        geometry_msgs_msg_dds__Vector3Stamped_ v{};
        v.header = make_header(stamp, base_frame.c_str());
        v.vector = {x.shift_base[0], x.shift_base[1], x.shift_base[2]};
        dds_write(shift_w, &v);
      }
      const bool changed = x.state != last_state || x.homed != last_homed || x.busy != last_busy;
      if (changed || get_steady_ns() - last_state_wall > 50000000) {
        crtk_msgs_msg_dds__OperatingState_ m{};
        m.header = make_header(stamp);
        m.state = const_cast<char*>(to_string(x.state));
        m.is_homed = x.homed;
        m.is_busy = x.busy;
        dds_write(state_w, &m);
        last_state_wall = get_steady_ns();
        if (changed && x.state == rcm::sim::PsmOperatingState::fault)
          log("ERROR", fmt::format("rcm: t = {:.3f} s: FAULT: {}", x.time, s.last_fault));
        else if (changed)
          log("INFO", fmt::format("rcm: t = {:.3f} s: {}{}{}", x.time, to_string(x.state), x.homed ? ", homed" : "",
                                  x.busy ? ", busy" : ""));
        last_state = x.state;
        last_homed = x.homed;
        last_busy = x.busy;
      }
    }
    const std::int64_t next = steady0 + std::llround(s.time / o.time_scale * 1e9);
    const timespec ts{static_cast<time_t>(next / 1000000000), static_cast<long>(next % 1000000000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
  }
  const rcm::sim::PsmCounters& c = s.counters;
  std::fprintf(stderr,
               "rcm: %.3f s of the arm's time, %llu periods; commands accepted: servo_jp %llu, move_jp %llu, "
               "state_command %llu, sim %llu, rcm/shift %llu; rejected %llu (wrong joint count %llu, not finite %llu, "
               "beyond the joint limits %llu, jump %llu, not ready %llu, unknown %llu, refused %llu); faults %llu\n",
               s.time, static_cast<unsigned long long>(s.periods), static_cast<unsigned long long>(c.servo_accepted),
               static_cast<unsigned long long>(c.move_accepted), static_cast<unsigned long long>(c.state_accepted),
               static_cast<unsigned long long>(c.sim_accepted), static_cast<unsigned long long>(c.shift_accepted),
               static_cast<unsigned long long>(c.get_rejected()), static_cast<unsigned long long>(c.wrong_joint_count),
               static_cast<unsigned long long>(c.not_finite), static_cast<unsigned long long>(c.beyond_limits),
               static_cast<unsigned long long>(c.jump), static_cast<unsigned long long>(c.not_ready),
               static_cast<unsigned long long>(c.unknown_command), static_cast<unsigned long long>(c.refused),
               static_cast<unsigned long long>(c.faults));
  std::fprintf(stderr,
               "rcm: servo_jp against the arm's periods: %llu periods held between two (no new setpoint; the longest "
               "run %llu), %llu replaced before a period used them\n",
               static_cast<unsigned long long>(c.servo_held_periods),
               static_cast<unsigned long long>(c.servo_longest_gap_periods),
               static_cast<unsigned long long>(c.servo_superseded));
  if (shift_delay.count() > 0)
    std::fprintf(stderr,
                 "rcm: rcm/shift: %llu taken; from the sample a shift answers to the shift taken here (the arm's "
                 "time): median %.1f ms, 95th percentile %.1f ms, max %.1f ms\n",
                 static_cast<unsigned long long>(shift_delay.count()), 1e3 * shift_delay.get_quantile_s(0.5),
                 1e3 * shift_delay.get_quantile_s(0.95), 1e3 * shift_delay.max_s());
  std::fprintf(stderr,
               "rcm: clock: %.3f s of the arm's time in %.3f s of wall time (%.3f times the wall; asked %g); behind "
               "the wall %llu times, %.3f s of the arm's time slipped\n",
               s.time, static_cast<double>(get_steady_ns() - wall_start) * 1e-9,
               s.time / std::max(1e-9, static_cast<double>(get_steady_ns() - wall_start) * 1e-9), o.time_scale,
               static_cast<unsigned long long>(slips), slipped_s);
  dds_delete(participant);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcm::dds_node::run_program("rcm_sim_psm_dds", argc, argv, run); }
