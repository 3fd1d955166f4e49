#include "rcm/sim/bench.hpp"

// The simulated bench's run (simulate_run: the arm under its controller, the
// tissue, the sensors) and the recordings of the protocol: free space, baseline,
// calibration and trials (docs/simulator.md). The session on disk is written by
// bench_session.cpp, the Fig. 3 sweep by force_angle.cpp.

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <fstream>
#include <mutex>
#include <optional>
#include <random>
#include <stdexcept>
#include <thread>

#include "rcm/common/interrupt.hpp"
#include "rcm/sim/arm_dynamics.hpp"
#include "rcm/sim/bench_arm.hpp"
#include "rcm/sim/plant.hpp"

namespace rcm::sim {

namespace {


std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

struct SegmentBuffer {
  std::size_t k_begin = 0, k_end = 0;  // global log sample indices [begin, end)
  SimulatedRecording rec;
};

void allocate(SimulatedRecording& r, std::size_t n) {
  const auto N = static_cast<Eigen::Index>(n);
  r.recording.time.resize(N);
  r.recording.position.resize(N, 3);
  r.recording.velocity.resize(N, 3);
  r.recording.effort.resize(N, 3);
  r.recording.force = Eigen::MatrixXd(N, 3);
  SimTruth& t = r.truth;
  t.q.resize(N, 3);
  t.qd.resize(N, 3);
  t.qdd.resize(N, 3);
  t.tau.resize(N, 3);
  t.tau_fs.resize(N, 3);
  t.friction.resize(N, 3);
  t.force.resize(N, 3);
  t.theta.resize(N);
  t.shaft_distance.resize(N);
}

}  // namespace

std::uint64_t derive_seed(std::uint64_t seed, const std::string& stream) {
  std::uint64_t h = 1469598103934665603ULL;  // FNV-1a of the stream name
  for (unsigned char c : stream) {
    h ^= c;
    h *= 1099511628211ULL;
  }
  return splitmix64(splitmix64(seed) ^ h);
}

std::vector<SimulatedRecording> simulate_run(const SimConfig& config,
                                             const ReferenceTrajectory& reference,
                                             const TissueModel* tissue,
                                             const std::vector<RunSegment>& segments,
                                             std::uint64_t noise_seed, const RunHooks* hooks) {
  const ControllerParams& C = config.controller;
  const SensorParams& S = config.sensors;
  const BenchArm bench_arm(config);
  const double dt = bench_arm.dt;
  const int decimation = static_cast<int>(std::lround(C.physics_rate_hz / S.log_rate_hz));

  std::vector<SegmentBuffer> buffers(segments.size());
  std::size_t k_last = 0;
  for (std::size_t i = 0; i < segments.size(); ++i) {
    auto& b = buffers[i];
    b.k_begin = static_cast<std::size_t>(std::ceil(segments[i].t_begin * S.log_rate_hz - 1e-9));
    b.k_end = static_cast<std::size_t>(std::ceil(segments[i].t_end * S.log_rate_hz - 1e-9));
    if (b.k_end <= b.k_begin) throw std::invalid_argument("simulate_run: empty segment " + segments[i].name);
    b.rec.name = segments[i].name;
    b.rec.recording.source = "simulated:" + segments[i].name;
    b.rec.tissue_engaged = tissue != nullptr;
    if (tissue) b.rec.misalignment_m = tissue->misalignment_m;
    allocate(b.rec, b.k_end - b.k_begin);
    k_last = std::max(k_last, b.k_end);
  }

  std::mt19937_64 rng(noise_seed);
  // Its own stream, so that the other sensors' noise does not depend on it.
  std::mt19937_64 velocity_rng(splitmix64(noise_seed ^ 0x76656c6f63697479ULL));
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);

  const long step_begin = -std::lround(C.settle_s * C.physics_rate_hz);
  const long step_end = static_cast<long>(k_last) * decimation;  // exclusive
  const Eigen::Vector3d q0 = config.protocol.q0;
  const ShaftFrame f0 = compute_shaft_frame(q0);

  BenchArmState state = make_bench_arm_state(bench_arm, reference.evaluate(step_begin * dt).q);
  const Eigen::Vector3d& q = state.plant.q;
  const Eigen::Vector3d& qd = state.plant.qd;
  BenchArmStep s;
  // With a moving incision, the tissue's anchor is moved in a copy at every step.
  std::optional<TissueModel> moving;
  if (tissue && hooks && hooks->get_misalignment) moving.emplace(*tissue);
  const TissueModel* active_tissue = moving ? &*moving : tissue;
  std::size_t buffer_index = 0;
  bool have_previous_row = false;

  for (long step = step_begin; step < step_end; ++step) {
    if (step % 4096 == 0 && is_interrupt_requested())
      throw Interrupted("interrupted while simulating " + segments.front().name);
    const double t = static_cast<double>(step) / C.physics_rate_hz;
    const ReferenceSample ref = reference.evaluate(std::max(t, step_begin * dt));
    if (moving)
      set_tissue_misalignment(*moving, hooks->get_misalignment(t),
                              hooks->get_misalignment_rate ? hooks->get_misalignment_rate(t)
                                                           : moving->misalignment_rate_m_per_s);
    try {
      compute_bench_arm_step(bench_arm, state, ref, active_tissue, s);
    } catch (const std::domain_error& e) {
      throw std::runtime_error(fmt::format("simulation of '{}' at t = {:.3f} s: {}",
                                           segments.front().name, t, e.what()));
    }
    const Eigen::Vector3d& q_meas = s.q_meas;
    const Eigen::Vector3d& tau = s.tau;
    const TissueOutput& tis = s.tissue;
    const PlantAcceleration& acc = s.acceleration;

    if (step >= 0 && step % decimation == 0) {
      const auto k = static_cast<std::size_t>(step / decimation);
      // The published velocity: the dVRK's estimate from encoder timing is
      // noisier than the controller's filtered difference (docs/simulator.md).
      const Eigen::Vector3d v_published =
          compute_published_velocity(S, s.v_meas, state.plant.qmd, velocity_rng, normal);
      // The loop reads the same noisy effort that the recording logs.
      std::optional<Eigen::Vector3d> sensed_effort;
      if (hooks && hooks->on_sample) {
        sensed_effort = compute_sensed_effort(S, tau, rng, normal);
        hooks->on_sample(static_cast<double>(k) / S.log_rate_hz, q_meas, v_published, *sensed_effort,
                         tis.f_inc_base);
      }
      while (buffer_index < buffers.size() &&
             (k < buffers[buffer_index].k_begin || k >= buffers[buffer_index].k_end)) {
        // Segments are in time order; find the one holding k (if any).
        if (k >= buffers[buffer_index].k_end) ++buffer_index;
        else break;
      }
      if (buffer_index < buffers.size() && k >= buffers[buffer_index].k_begin &&
          k < buffers[buffer_index].k_end) {
        SegmentBuffer& b = buffers[buffer_index];
        const auto r = static_cast<Eigen::Index>(k - b.k_begin);
        Recording& rec = b.rec.recording;
        SimTruth& tr = b.rec.truth;
        rec.time[r] = static_cast<double>(k) / S.log_rate_hz;
        const bool repeat = S.repeat_row_probability > 0.0 && r > 0 && have_previous_row &&
                            unit(rng) < S.repeat_row_probability;
        if (repeat) {
          rec.position.row(r) = rec.position.row(r - 1);
          rec.velocity.row(r) = rec.velocity.row(r - 1);
          rec.effort.row(r) = rec.effort.row(r - 1);
          rec.force->row(r) = rec.force->row(r - 1);
        } else {
          rec.position.row(r) = q_meas.transpose();
          rec.velocity.row(r) = v_published.transpose();
          // Without hooks the effort's and the force's noise alternate per
          // joint: the draws of every session written so far.
          for (int j = 0; j < 3; ++j) {
            rec.effort(r, j) = sensed_effort ? (*sensed_effort)[j]
                                             : tau[j] + (S.noise ? S.effort_noise[j] * normal(rng) : 0.0);
            (*rec.force)(r, j) =
                tis.f_inc_base[j] + (S.noise ? S.force_noise_n * normal(rng) : 0.0);
          }
        }
        have_previous_row = true;
        tr.q.row(r) = q.transpose();
        tr.qd.row(r) = qd.transpose();
        tr.qdd.row(r) = acc.qdd.transpose();
        tr.tau.row(r) = tau.transpose();
        tr.friction.row(r) = (acc.friction_link + acc.friction_motor).transpose();
        tr.tau_fs.row(r) = acc.tau_fs.transpose();
        tr.force.row(r) = tis.f_inc_base.transpose();
        const Eigen::Vector3d z3 = compute_shaft_frame(q).z3;
        tr.theta[r] = std::atan2(f0.z3.cross(z3).norm(), f0.z3.dot(z3));
        tr.shaft_distance[r] = tis.shaft_distance;
      }
    }

    advance_bench_arm_state(bench_arm, state, s, active_tissue);
  }

  std::vector<SimulatedRecording> out;
  out.reserve(buffers.size());
  for (auto& b : buffers) out.push_back(std::move(b.rec));
  return out;
}

ReferenceTrajectory make_teleop_reference(const SimConfig& config, const std::string& stream,
                                          double duration_s) {
  ReferenceTrajectory ref;
  ref.add_path(0.0, std::make_shared<const TeleopPath>(config.trajectory, config.protocol.q0,
                                                      derive_seed(config.seed, "path:" + stream), duration_s));
  return ref;
}

SimulatedRecording simulate_free_space(const SimConfig& config, int index) {
  const int files = std::max(1, config.protocol.free_space_files);
  const double duration = config.protocol.free_space_s / files;
  const std::string name =
      files == 1 ? std::string("free_space") : fmt::format("free_space_{}", index + 1);
  ReferenceTrajectory ref;
  if (config.trajectory.free_space_path == "excitation")
    ref.add_path(0.0, std::make_shared<const ExcitationPath>(config.trajectory, config.protocol.q0,
                                                             derive_seed(config.seed, "path:" + name)));
  else if (config.trajectory.free_space_path == "file")
    ref.add_path(0.0, load_sampled_path(config.trajectory.free_space_file, load_robot_model(config.robot)));
  else
    ref = make_teleop_reference(config, name, duration);
  auto recs = simulate_run(config, ref, nullptr, {{name, 0.0, duration}},
                           derive_seed(config.seed, "noise:" + name));
  return std::move(recs.front());
}

SimulatedRecording simulate_baseline(const SimConfig& config) {
  const ProtocolParams& P = config.protocol;
  ReferenceTrajectory ref;
  ref.add_hold(0.0, P.q0 + P.baseline_start_offset);
  ref.add_move(0.0, P.baseline_approach_s, P.q0);
  ref.add_hold(P.baseline_approach_s, P.q0);
  const TissueModel tissue(config.tissue, P.q0, Eigen::Vector3d::Zero());
  auto recs = simulate_run(config, ref, &tissue,
                           {{"baseline", 0.0, P.baseline_approach_s + P.baseline_hold_s}},
                           derive_seed(config.seed, "noise:baseline"));
  return std::move(recs.front());
}

SimulatedRecording simulate_calibration(const SimConfig& config) {
  const ProtocolParams& P = config.protocol;
  const double duration = std::max(P.calibration_s, P.trial_s);
  const ReferenceTrajectory ref = make_teleop_reference(config, "teleop", duration);
  const TissueModel tissue(config.tissue, P.q0, Eigen::Vector3d(0.0, 0.0, P.calibration_offset_m));
  auto recs = simulate_run(config, ref, &tissue, {{"calibration", 0.0, P.calibration_s}},
                           derive_seed(config.seed, "noise:calibration"));
  return std::move(recs.front());
}

std::string get_trial_name(const Eigen::Vector3d& m) {
  auto mm = [](double v) { return static_cast<long>(std::lround(v * 1000.0)); };
  return fmt::format("D{}_r{}_{}", mm(m.z()), mm(m.x()), mm(m.y()));
}

SimulatedTrial simulate_trial(const SimConfig& config, const Eigen::Vector3d& misalignment_m) {
  const ProtocolParams& P = config.protocol;
  SimulatedTrial trial;
  trial.name = get_trial_name(misalignment_m);
  trial.misalignment_m = misalignment_m;
  ReferenceTrajectory ref = make_teleop_reference(config, P.trial_paths == "own" ? "teleop:" + trial.name : "teleop",
                                                  std::max(P.calibration_s, P.trial_s));
  // The static file: return to q0 and hold; with several approaches the arm then
  // moves out to the other side of q0 on every joint and comes back, so that
  // each joint's holds alternate the direction of the motion that ended there.
  const Eigen::Vector3d end = ref.evaluate(P.trial_s).q;
  Eigen::Vector3d side = (end - P.q0).unaryExpr([](double d) { return d < 0.0 ? -1.0 : 1.0; });
  const double hold_s = P.static_hold_s / P.static_approaches;
  double t = P.trial_s;
  // The return leaves the trial's path with its velocity, which may swing a
  // joint past q0 before it comes back: it ends through q0 + side x offset, so
  // that every joint's first hold ends a motion from that side, as the later
  // approaches do.
  ref.add_move(t, 2.0 * P.static_return_s / 3.0, P.q0 + side.cwiseProduct(P.static_approach_offset));
  ref.add_move(t + 2.0 * P.static_return_s / 3.0, P.static_return_s / 3.0, P.q0);
  t += P.static_return_s;
  for (int a = 0; a < P.static_approaches; ++a) {
    ref.add_hold(t, P.q0);
    t += hold_s;
    if (a + 1 == P.static_approaches) break;
    side = -side;
    ref.add_move(t, 0.5 * P.static_return_s, P.q0 + side.cwiseProduct(P.static_approach_offset));
    ref.add_move(t + 0.5 * P.static_return_s, 0.5 * P.static_return_s, P.q0);
    t += P.static_return_s;
  }
  const TissueModel tissue(config.tissue, P.q0, misalignment_m);
  auto recs = simulate_run(config, ref, &tissue,
                           {{trial.name, 0.0, P.trial_s}, {trial.name + "_static", P.trial_s, t}},
                           derive_seed(config.seed, "noise:" + trial.name));
  trial.recording = std::move(recs[0]);
  trial.static_recording = std::move(recs[1]);
  return trial;
}

}  // namespace rcm::sim
