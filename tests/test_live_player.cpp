// The trajectory player (include/rcm/live/trajectory_player.hpp) against the
// simulated PSM, in one process and without middleware: the messages go
// straight from the arm's sample to the player and its commands straight back.
// Its refusals, its pacing on the arm's clock, its recording, and each of its
// safety stops.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "rcm/live/trajectory_player.hpp"
#include "rcm/sim/simulated_psm.hpp"

namespace {

using rcm::PlayerPhase;
using rcm::TrajectoryPlayer;
using rcm::sim::PsmCommandVerdict;
using rcm::sim::SimulatedPsm;
using rcm::sim::SimulatedPsmState;

constexpr std::int64_t kStampOrigin = 1700000000LL * 1000000000LL;

// The arm and the player, wired as a program wires them; the wall clock runs
// with the arm's clock unless a test stops the messages.
struct Bench {
  SimulatedPsm psm;
  SimulatedPsmState s;
  std::vector<std::string> names;
  std::vector<double> position, velocity, effort, setpoint, none;
  std::int64_t wall_ns = 0;
  bool deliver = true;  // false: the arm's messages stop (its node hangs)
  // A stall of the player's side: for this many periods the arm's messages
  // wait, then come together, each with its age (when it came less when the
  // arm wrote it). tell_age false: a middleware that does not say.
  int stall_periods = 0;
  bool tell_age = true;
  struct Message {
    rcm::sim::PsmSample sample;
    std::int64_t stamp, written;
  };
  std::vector<Message> waiting;

  explicit Bench(double rate_hz)
      : psm(rcm::sim::make_default_config(), [&] {
          rcm::sim::SimulatedPsmOptions o;
          o.rate_hz = rate_hz;
          return o;
        }()),
        s(psm.create_state(3)) {
    for (const char* n : rcm::sim::get_psm_joint_names()) names.emplace_back(n);
  }
  void make_ready() {
    psm.apply_state_command(s, "home");
    for (int k = 0; k < 100000 && !s.homed; ++k) psm.compute_step(s);
    for (int k = 0; k < 20; ++k) psm.compute_step(s);
  }
  std::int64_t stamp() const { return kStampOrigin + std::llround(s.sample.time * 1e9); }
  void apply(const rcm::PlayerCommand& c) {
    if (c.kind == rcm::PlayerCommand::Kind::servo_jp)
      psm.apply_servo_jp(s, c.position.data(), c.position.size(), c.velocity.data(), c.velocity.size());
    else if (c.kind == rcm::PlayerCommand::Kind::move_jp)
      psm.apply_move_jp(s, c.position.data(), c.position.size());
  }
  void deliver_message(TrajectoryPlayer& player, const rcm::sim::PsmSample& x, std::int64_t stamp_ns,
                       std::int64_t written_ns) {
    apply(player.compute_operating_state(to_string(x.state), x.homed, x.busy, wall_ns));
    setpoint.assign(x.setpoint.data(), x.setpoint.data() + 6);
    player.add_setpoint({names, setpoint, none, none}, stamp_ns);
    position.assign(x.position.data(), x.position.data() + 6);
    velocity.assign(x.velocity.data(), x.velocity.data() + 6);
    effort.assign(x.effort.data(), x.effort.data() + 6);
    // 50 us on the way: the age of a message that came at once.
    const std::int64_t age = tell_age ? wall_ns - written_ns + 50000 : -1;
    apply(player.compute_measured({names, position, velocity, effort}, stamp_ns, wall_ns, age));
  }
  // One period of the arm and what the player makes of it.
  void step(TrajectoryPlayer& player) {
    psm.compute_step(s);
    wall_ns += std::llround(psm.period_s() * 1e9);
    if (stall_periods > 0) {
      waiting.push_back({s.sample, stamp(), wall_ns});
      if (--stall_periods > 0) return;
      for (const Message& m : waiting) deliver_message(player, m.sample, m.stamp, m.written);
      waiting.clear();
    } else if (deliver) {
      deliver_message(player, s.sample, stamp(), wall_ns);
    }
    apply(player.compute_tick(wall_ns));
  }
  void play(TrajectoryPlayer& player, double max_s = 60.0) {
    for (long k = 0; !player.finished() && k * psm.period_s() < max_s; ++k) step(player);
  }
};

// A smooth 1 s excursion of the first three joints from the docking pose, at `rate_hz`.
rcm::JointTrajectory make_trajectory(double rate_hz, double seconds = 1.0) {
  const auto n = static_cast<Eigen::Index>(std::llround(seconds * rate_hz)) + 1;
  rcm::JointTrajectory t;
  t.time.resize(n);
  t.position.resize(n, 3);
  t.velocity.resize(n, 3);
  const double w = 2 * M_PI / seconds;
  for (Eigen::Index k = 0; k < n; ++k) {
    const double x = static_cast<double>(k) / rate_hz;
    t.time[k] = x;
    const double s = 0.5 * (1 - std::cos(w * x)), ds = 0.5 * w * std::sin(w * x);
    t.position.row(k) << 0.1 * s, -0.05 * s, 0.12 + 0.005 * s;
    t.velocity.row(k) << 0.1 * ds, -0.05 * ds, 0.005 * ds;
  }
  return t;
}

TEST(TrajectoryPlayer, RefusesAnArmThatIsNotEnabledOrNotHomed) {
  Bench disabled(1000.0);
  TrajectoryPlayer p1(make_trajectory(200.0), {});
  disabled.play(p1);
  EXPECT_EQ(p1.phase(), PlayerPhase::refused);
  EXPECT_NE(p1.summary().message.find("the arm is DISABLED"), std::string::npos) << p1.summary().message;
  EXPECT_EQ(disabled.s.counters.servo_accepted + disabled.s.counters.move_accepted, 0u);

  Bench not_homed(1000.0);
  not_homed.psm.apply_state_command(not_homed.s, "enable");
  TrajectoryPlayer p2(make_trajectory(200.0), {});
  not_homed.play(p2);
  EXPECT_EQ(p2.phase(), PlayerPhase::refused);
  EXPECT_NE(p2.summary().message.find("not homed"), std::string::npos) << p2.summary().message;

  Bench silent(1000.0);
  silent.deliver = false;
  TrajectoryPlayer p3(make_trajectory(200.0), {});
  silent.play(p3);
  EXPECT_EQ(p3.phase(), PlayerPhase::refused);
  EXPECT_NE(p3.summary().message.find("no operating_state and no measured_js"), std::string::npos);
}

// At 1.5 kHz: the move to the first row, then every row once, paced on the
// arm's clock, and every measured_js from the first row on recorded once.
TEST(TrajectoryPlayer, PlaysOnTheArmsClockAndRecordsEverySampleOnce) {
  Bench b(1500.0);
  b.make_ready();
  const rcm::JointTrajectory t = make_trajectory(200.0, 2.0);
  TrajectoryPlayer player(t, {});
  b.play(player);
  ASSERT_EQ(player.phase(), PlayerPhase::done) << player.summary().message;
  const rcm::PlayerSummary& s = player.summary();
  EXPECT_EQ(s.rows_sent, t.num_samples());
  EXPECT_EQ(s.rows_skipped, 0u);
  EXPECT_EQ(b.s.counters.servo_accepted, t.num_samples());
  EXPECT_EQ(b.s.counters.move_accepted, 1u);
  EXPECT_LT(std::abs(s.sent_span_s - s.file_duration_s), 1.0 / 1500 + 1e-9) << "within one period of the arm";
  const rcm::Recording r = player.get_recording("played.csv");
  ASSERT_EQ(r.num_joints(), 6);
  EXPECT_EQ(r.num_samples(), s.samples_recorded);
  EXPECT_EQ(static_cast<long>(r.num_samples()), std::lround(2.0 * 1500) + 1);
  for (Eigen::Index k = 1; k < r.time.size(); ++k) ASSERT_NEAR(r.time[k] - r.time[k - 1], 1.0 / 1500, 1e-6) << k;
  EXPECT_NO_THROW(rcm::validate_recording(r));
  // Where the arm went, against the file.
  EXPECT_NEAR(r.position.col(0).maxCoeff(), 0.1, 0.01);
  ASSERT_EQ(s.max_tracking_error.size(), 6u);
  EXPECT_GT(s.max_tracking_error[0], 0.0);
  EXPECT_LT(s.max_tracking_error[0], 0.01);
  const nlohmann::json j = rcm::to_json(s, player.joint_names());
  EXPECT_LT(std::abs(j["pacing_error"].get<double>()), 0.01);
  EXPECT_TRUE(j["max_tracking_error"].contains("outer_pitch"));
}

TEST(TrajectoryPlayer, HoldsJointsTheFileLacksWhereTheyWere) {
  Bench b(500.0);
  b.make_ready();
  rcm::sim::PsmVector pose = b.psm.home();
  pose[3] = 0.4;
  pose[5] = -0.3;
  ASSERT_EQ(b.psm.apply_move_jp(b.s, pose.data(), 6), PsmCommandVerdict::accepted);
  for (int k = 0; k < 2000; ++k) b.psm.compute_step(b.s);
  TrajectoryPlayer player(make_trajectory(100.0), {});
  b.play(player);
  ASSERT_EQ(player.phase(), PlayerPhase::done) << player.summary().message;
  const rcm::Recording r = player.get_recording("x");
  EXPECT_EQ(r.position.col(3).minCoeff(), 0.4);
  EXPECT_EQ(r.position.col(3).maxCoeff(), 0.4);
  EXPECT_EQ(r.position.col(5).maxCoeff(), -0.3);
}

TEST(TrajectoryPlayer, StopsWhenTheArmLeavesEnabled) {
  Bench b(1000.0);
  b.make_ready();
  TrajectoryPlayer player(make_trajectory(200.0, 2.0), {});
  for (int k = 0; k < 1000 && !player.finished(); ++k) b.step(player);
  ASSERT_EQ(player.phase(), PlayerPhase::streaming);
  b.psm.apply_state_command(b.s, "disable");
  b.step(player);
  EXPECT_EQ(player.phase(), PlayerPhase::stopped);
  EXPECT_NE(player.summary().message.find("the arm left ENABLED: it is now DISABLED"), std::string::npos)
      << player.summary().message;
  EXPECT_GT(player.summary().samples_recorded, 0u);
}

TEST(TrajectoryPlayer, StopsWhenMeasuredJsStops) {
  Bench b(1000.0);
  b.make_ready();
  rcm::PlayerOptions o;
  o.measured_timeout_s = 0.2;
  TrajectoryPlayer player(make_trajectory(200.0, 2.0), o);
  for (int k = 0; k < 1000 && !player.finished(); ++k) b.step(player);
  ASSERT_EQ(player.phase(), PlayerPhase::streaming);
  b.deliver = false;
  const std::size_t sent = player.summary().rows_sent;
  for (int k = 0; k < 150 && !player.finished(); ++k) b.step(player);
  EXPECT_NE(player.phase(), PlayerPhase::stopped) << "0.15 s of silence is within the timeout";
  for (int k = 0; k < 100 && !player.finished(); ++k) b.step(player);
  EXPECT_EQ(player.phase(), PlayerPhase::stopped);
  EXPECT_NE(player.summary().message.find("measured_js stopped"), std::string::npos) << player.summary().message;
  EXPECT_EQ(player.summary().rows_sent, sent) << "nothing sent without the arm's clock";
}

TEST(TrajectoryPlayer, StopsOnTrackingErrorAndHoldsTheArm) {
  Bench b(1000.0);
  b.make_ready();
  rcm::PlayerOptions o;
  o.max_tracking_error = {0.002, 0.05, 0.005, 0.2};
  // A trajectory faster than the arm follows within 2 mrad: 0.1 rad in 0.1 s.
  TrajectoryPlayer player(make_trajectory(200.0, 0.1), o);
  rcm::PlayerCommand last;
  for (long k = 0; k < 20000 && !player.finished(); ++k) {
    b.psm.compute_step(b.s);
    b.wall_ns += 1000000;
    const rcm::sim::PsmSample& x = b.s.sample;
    b.apply(player.compute_operating_state(to_string(x.state), x.homed, x.busy, b.wall_ns));
    b.setpoint.assign(x.setpoint.data(), x.setpoint.data() + 6);
    player.add_setpoint({b.names, b.setpoint, b.none, b.none}, b.stamp());
    b.position.assign(x.position.data(), x.position.data() + 6);
    b.velocity.assign(x.velocity.data(), x.velocity.data() + 6);
    b.effort.assign(x.effort.data(), x.effort.data() + 6);
    last = player.compute_measured({b.names, b.position, b.velocity, b.effort}, b.stamp(), b.wall_ns);
    b.apply(last);
  }
  ASSERT_EQ(player.phase(), PlayerPhase::stopped);
  EXPECT_GE(player.summary().rows_sent, 2u) << "it stopped once the arm fell behind, not before";
  EXPECT_GT(player.summary().max_tracking_error[0], 0.002);
  EXPECT_NE(player.summary().message.find("tracking error on outer_yaw (1)"), std::string::npos)
      << player.summary().message;
  ASSERT_EQ(last.kind, rcm::PlayerCommand::Kind::servo_jp) << "the last command holds the arm where it is";
  EXPECT_EQ(last.position, b.position);
}

// A 16 ms stall of the player's side at 1.5 kHz, where the file moves
// fastest: the arm holds the last row it got. Told the messages' ages, the
// player pauses the file over the late ones and the arm resumes from the row it
// holds; not told, the arm's setpoint jumps to where the file is by then.
TEST(TrajectoryPlayer, PausesTheFileOverAStallRatherThanJumpTheSetpoint) {
  const rcm::JointTrajectory t = make_trajectory(1500.0, 1.0);
  auto run = [&](bool tell_age, double& largest_step, rcm::PlayerSummary& summary) {
    Bench b(1500.0);
    b.make_ready();
    b.tell_age = tell_age;
    TrajectoryPlayer player(t, {});
    largest_step = 0.0;
    bool stalled = false;
    for (long k = 0; k < 100000 && !player.finished(); ++k) {
      // A quarter of the file in: the yaw's speed at its peak, 0.31 rad/s.
      if (!stalled && player.summary().rows_sent == 375) {
        b.stall_periods = 24;
        stalled = true;
      }
      const double before = b.s.setpoint[0];
      b.step(player);
      if (player.summary().rows_sent > 0) largest_step = std::max(largest_step, std::abs(b.s.setpoint[0] - before));
    }
    ASSERT_TRUE(stalled);
    ASSERT_EQ(player.phase(), PlayerPhase::done) << player.summary().message;
    summary = player.summary();
    const rcm::Recording r = player.get_recording("x");
    for (Eigen::Index k = 1; k < r.time.size(); ++k)
      ASSERT_NEAR(r.time[k] - r.time[k - 1], 1.0 / 1500, 1e-6) << "every sample recorded once, the late ones too";
  };
  double paused_step = 0.0, jumped_step = 0.0;
  rcm::PlayerSummary paused, jumped;
  run(true, paused_step, paused);
  run(false, jumped_step, jumped);
  const double row_step = 0.1 * M_PI / 1500;  // the file's largest step from one row to the next
  EXPECT_GT(jumped_step, 15 * row_step) << "without the ages: a jump over most of the stall";
  EXPECT_LT(paused_step, 9 * row_step) << "with them: at most stall_s (7.5 periods) of the file at once";
  EXPECT_EQ(jumped.stalls, 0u);
  EXPECT_EQ(paused.stalls, 1u);
  // Late beyond 5 ms: the first 16 of the 24 messages, each a period of the file's pause.
  EXPECT_NEAR(paused.paused_s, 16.0 / 1500, 2.0 / 1500);
  EXPECT_NEAR(paused.sent_span_s - jumped.sent_span_s, paused.paused_s, 1.0 / 1500) << "the pause is in the pacing";
  EXPECT_EQ(paused.rows_sent + paused.rows_skipped, t.num_samples());
  EXPECT_NE(paused.message.find("paused 0.01"), std::string::npos) << paused.message;
  const nlohmann::json j = rcm::to_json(paused, {"outer_yaw"});
  EXPECT_EQ(j["stalls"], 1);
}

// Short stalls all along the file, as a busy computer makes them (2 to 12
// periods every 97): once the pauses have added up, every row still goes out
// on its own message, none skipped, the setpoint never held a period.
TEST(TrajectoryPlayer, ManyShortStallsSkipNoRow) {
  const rcm::JointTrajectory t = make_trajectory(1500.0, 10.0);
  Bench b(1500.0);
  b.make_ready();
  TrajectoryPlayer player(t, {});
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> periods(2, 12);
  for (long k = 0; k < 60 * 1500 && !player.finished(); ++k) {
    if (b.stall_periods == 0 && k % 97 == 0) b.stall_periods = periods(rng);
    b.step(player);
  }
  ASSERT_EQ(player.phase(), PlayerPhase::done) << player.summary().message;
  const rcm::PlayerSummary& s = player.summary();
  EXPECT_GT(s.stalls, 20u) << "stalls longer than stall_s (7.5 periods) pause the file";
  EXPECT_EQ(s.rows_skipped, 0u) << s.message;
  EXPECT_EQ(s.rows_sent, t.num_samples());
}

TEST(TrajectoryPlayer, RejectsBadMeasuredJsAndRecordsOnly) {
  Bench b(500.0);
  b.make_ready();
  rcm::PlayerOptions o;
  o.max_tracking_error = {1e-9};  // beyond any arm's: a recorder reports it, never stops on it
  TrajectoryPlayer player(1.0, o);  // record 1 s of the arm's time
  for (int k = 0; k < 100; ++k) b.step(player);
  ASSERT_EQ(player.phase(), PlayerPhase::streaming);
  std::vector<double> nan_position = b.position;
  nan_position[1] = std::numeric_limits<double>::quiet_NaN();
  player.compute_measured({b.names, nan_position, b.velocity, b.effort}, b.stamp() + 1000, b.wall_ns);
  player.compute_measured({b.names, b.position, b.velocity, b.effort}, b.stamp(), b.wall_ns);  // the same stamp
  const std::vector<double> short_effort(b.effort.begin(), b.effort.begin() + 3);
  player.compute_measured({b.names, b.position, b.velocity, short_effort}, b.stamp() + 2000, b.wall_ns);
  EXPECT_EQ(player.summary().rejected, 3u);
  b.play(player);
  ASSERT_EQ(player.phase(), PlayerPhase::done) << player.summary().message;
  EXPECT_EQ(player.summary().rows_sent, 0u);
  EXPECT_GT(player.summary().max_tracking_error[0], 1e-9);
  EXPECT_EQ(b.s.counters.servo_accepted + b.s.counters.move_accepted, 0u) << "a recorder commands nothing";
  EXPECT_EQ(player.summary().rows_sent, 0u);
  EXPECT_GT(player.summary().max_tracking_error[0], 1e-9);
  EXPECT_EQ(static_cast<long>(player.summary().samples_recorded), 501);
  EXPECT_NEAR(player.summary().recorded_span_s, 1.0, 1e-6);
}

TEST(TrajectoryPlayer, HoldTrajectory) {
  const rcm::JointTrajectory t = rcm::make_hold_trajectory(Eigen::Vector3d(0.0, 0.0, 0.12), 10.0, 100.0);
  EXPECT_EQ(t.num_samples(), 1001u);
  EXPECT_DOUBLE_EQ(t.time[1000], 10.0);
  EXPECT_EQ(t.position.col(2).minCoeff(), 0.12);
  EXPECT_EQ(t.velocity.cwiseAbs().maxCoeff(), 0.0);
}

}  // namespace
