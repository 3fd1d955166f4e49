#include "rcm/sim/bench.hpp"

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
#include "rcm/io/json_file.hpp"
#include "rcm/io/session.hpp"
#include "rcm/sim/arm_dynamics.hpp"

namespace rcm::sim {

namespace {

constexpr double kPi = 3.141592653589793;

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

double quantize(double x, double quantum) {
  return quantum > 0.0 ? quantum * std::round(x / quantum) : x;
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
  const double dt = 1.0 / C.physics_rate_hz;
  const int decimation = static_cast<int>(std::lround(C.physics_rate_hz / S.log_rate_hz));
  const ArmDynamics arm(config.arm);
  const auto& friction_params = config.friction;

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
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);

  const long step_begin = -std::lround(C.settle_s * C.physics_rate_hz);
  const long step_end = static_cast<long>(k_last) * decimation;  // exclusive
  const double alpha = 1.0 - std::exp(-2.0 * kPi * C.velocity_filter_hz * dt);
  const Eigen::Vector3d q0 = config.protocol.q0;
  const ShaftFrame f0 = compute_shaft_frame(q0);

  Eigen::Vector3d q = reference.evaluate(step_begin * dt).q;
  Eigen::Vector3d qd = Eigen::Vector3d::Zero();
  Eigen::Vector3d z = Eigen::Vector3d::Zero();
  double axial_z = 0.0;
  auto measure_position = [&](const Eigen::Vector3d& x) {
    if (!S.noise) return x;
    Eigen::Vector3d m;
    for (int j = 0; j < 3; ++j) m[j] = quantize(x[j], S.position_quantum[j]);
    return m;
  };
  Eigen::Vector3d q_meas_prev = measure_position(q);
  // With a moving incision, the tissue's anchor is moved in a copy at every step.
  std::optional<TissueModel> moving;
  if (tissue && hooks && hooks->get_misalignment) moving.emplace(*tissue);
  const TissueModel* active_tissue = moving ? &*moving : tissue;
  Eigen::Vector3d velocity_filtered = Eigen::Vector3d::Zero();
  std::size_t buffer_index = 0;
  bool have_previous_row = false;

  for (long step = step_begin; step < step_end; ++step) {
    if (step % 4096 == 0 && is_interrupt_requested())
      throw Interrupted("interrupted while simulating " + segments.front().name);
    const double t = static_cast<double>(step) / C.physics_rate_hz;
    // Sensors as the controller sees them.
    const Eigen::Vector3d q_meas = measure_position(q);
    Eigen::Vector3d v_meas;
    if (S.noise) {
      velocity_filtered += alpha * ((q_meas - q_meas_prev) / dt - velocity_filtered);
      v_meas = velocity_filtered;
    } else {
      v_meas = qd;
    }
    q_meas_prev = q_meas;

    // Controller.
    const ReferenceSample ref = reference.evaluate(std::max(t, step_begin * dt));
    Eigen::Vector3d tau = C.kp.cwiseProduct(ref.q - q_meas) + C.kd.cwiseProduct(ref.qd - v_meas);
    if (C.feedforward) tau += compute_inverse_dynamics(arm, ref.q, ref.qd, ref.qdd, true);

    // Plant.
    const FrictionOutput fr = compute_friction(friction_params, z, qd);
    TissueOutput tis;
    if (moving) {
      moving->misalignment_m = hooks->get_misalignment(t);
      moving->p_anchor_base = moving->R_base_inc * moving->misalignment_m;
    }
    if (active_tissue) {
      try {
        tis = compute_tissue_force(*active_tissue, q, qd, axial_z);
      } catch (const std::domain_error& e) {
        throw std::runtime_error(fmt::format("simulation of '{}' at t = {:.3f} s: {}",
                                             segments.front().name, t, e.what()));
      }
    }
    const Eigen::Vector3d h = compute_inverse_dynamics(arm, q, qd, Eigen::Vector3d::Zero(), true);
    const Eigen::Matrix3d M = compute_mass_matrix(arm, q);
    const Eigen::Vector3d qdd = M.llt().solve(tau - h - fr.tau - tis.tau);

    if (step >= 0 && step % decimation == 0) {
      const auto k = static_cast<std::size_t>(step / decimation);
      // The loop reads the same noisy effort that the recording logs.
      std::optional<Eigen::Vector3d> sensed_effort;
      if (hooks && hooks->on_sample) {
        sensed_effort.emplace();
        for (int j = 0; j < 3; ++j) (*sensed_effort)[j] = tau[j] + (S.noise ? S.effort_noise[j] * normal(rng) : 0.0);
        hooks->on_sample(static_cast<double>(k) / S.log_rate_hz, q_meas, v_meas, *sensed_effort, tis.f_inc_base);
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
          rec.velocity.row(r) = v_meas.transpose();
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
        tr.qdd.row(r) = qdd.transpose();
        tr.tau.row(r) = tau.transpose();
        tr.friction.row(r) = fr.tau.transpose();
        tr.tau_fs.row(r) = (M * qdd + h + fr.tau).transpose();
        tr.force.row(r) = tis.f_inc_base.transpose();
        const Eigen::Vector3d z3 = compute_shaft_frame(q).z3;
        tr.theta[r] = std::atan2(f0.z3.cross(z3).norm(), f0.z3.dot(z3));
        tr.shaft_distance[r] = tis.shaft_distance;
      }
    }

    // Semi-implicit Euler; friction states by their exact exponential update.
    qd += dt * qdd;
    q += dt * qd;
    z = advance_friction_state(friction_params, z, qd, dt);
    if (active_tissue) axial_z = advance_tissue_state(*active_tissue, axial_z, tis.axial_velocity, dt);
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
  // The same path as the calibration, so that trials differ only by the misalignment.
  ReferenceTrajectory ref = make_teleop_reference(config, "teleop", std::max(P.calibration_s, P.trial_s));
  // The static file: return to q0 and hold; with several approaches the arm then
  // moves out to the other side of q0 on every joint and comes back, so that
  // each joint's holds alternate the direction of the motion that ended there.
  Eigen::Vector3d side = (ref.evaluate(P.trial_s).q - P.q0).unaryExpr([](double d) { return d < 0.0 ? -1.0 : 1.0; });
  const double hold_s = P.static_hold_s / P.static_approaches;
  double t = P.trial_s;
  ref.add_move(t, P.static_return_s, P.q0);
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

void save_truth_csv(const std::filesystem::path& path, const SimulatedRecording& rec) {
  // A valid recording in its own right (noise-free position, velocity, effort and
  // force), so that `rcm inspect` and every reader accept it; the extra columns
  // carry what no sensor measures.
  const SimTruth& t = rec.truth;
  fmt::memory_buffer buf;
  auto out = std::back_inserter(buf);
  fmt::format_to(out, "time");
  for (const char* name : {"position", "velocity", "effort"})
    for (int j = 1; j <= 3; ++j) fmt::format_to(out, ",{}_{}", name, j);
  fmt::format_to(out, ",force_x,force_y,force_z");
  for (const char* name : {"qdd", "tau_fs", "friction"})
    for (int j = 1; j <= 3; ++j) fmt::format_to(out, ",{}_{}", name, j);
  fmt::format_to(out, ",theta,shaft_distance\n");
  const Eigen::MatrixXd* blocks[] = {&t.q, &t.qd, &t.tau, &t.force, &t.qdd, &t.tau_fs, &t.friction};
  for (Eigen::Index r = 0; r < rec.recording.time.size(); ++r) {
    fmt::format_to(out, "{}", rec.recording.time[r]);
    for (const Eigen::MatrixXd* m : blocks)
      for (int j = 0; j < 3; ++j) fmt::format_to(out, ",{}", (*m)(r, j));
    fmt::format_to(out, ",{},{}\n", t.theta[r], t.shaft_distance[r]);
  }
  write_file_atomic(path, std::string(buf.data(), buf.size()));
}

RecordingFileInfo summarize_simulated_recording(const SimulatedRecording& rec) {
  RecordingFileInfo info;
  const Recording& r = rec.recording;
  info.name = rec.name;
  info.samples = r.num_samples();
  if (info.samples == 0) return info;
  info.duration_s = r.time[r.time.size() - 1] - r.time[0];
  info.effort_min = r.effort.colwise().minCoeff().transpose();
  info.effort_max = r.effort.colwise().maxCoeff().transpose();
  info.force_max_n = rec.truth.force.rowwise().norm().maxCoeff();
  info.theta_max_rad = rec.truth.theta.maxCoeff();
  // High-frequency effort content: the signal minus its centred 0.2 s moving
  // average (first zero of that filter at 5 Hz).
  const Eigen::Index n = r.effort.rows();
  const double rate = info.duration_s > 0 ? (n - 1) / info.duration_s : 200.0;
  const Eigen::Index half = std::max<Eigen::Index>(1, static_cast<Eigen::Index>(std::lround(0.1 * rate)));
  if (n > 2 * half + 1) {
    for (int j = 0; j < 3; ++j) {
      double sum = r.effort.col(j).segment(0, 2 * half + 1).sum();
      double sq = 0.0;
      Eigen::Index count = 0;
      for (Eigen::Index i = half; i + half < n; ++i) {
        if (i > half) sum += r.effort(i + half, j) - r.effort(i - half - 1, j);
        const double d = r.effort(i, j) - sum / static_cast<double>(2 * half + 1);
        sq += d * d;
        ++count;
      }
      info.effort_noise_hf[j] = std::sqrt(sq / static_cast<double>(count));
    }
  }
  return info;
}

namespace {

// Runs jobs on up to `threads` threads; the first exception is rethrown.
void run_parallel(std::vector<std::function<void()>>& jobs, int threads) {
  const int n = std::max(1, std::min<int>(threads, static_cast<int>(jobs.size())));
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&] {
    for (;;) {
      const std::size_t i = next.fetch_add(1);
      if (i >= jobs.size()) return;
      try {
        throw_if_interrupted("simulating");
        jobs[i]();
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = jobs.size();
      }
    }
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < n; ++i) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace

SessionWriteSummary simulate_session(const SimConfig& config, const std::filesystem::path& out_dir,
                                     const std::function<void(const std::string&)>& progress) {
  validate_config(config);
  const auto start = std::chrono::steady_clock::now();
  std::filesystem::create_directories(out_dir);
  const ProtocolParams& P = config.protocol;
  std::mutex mutex;
  auto report = [&](const std::string& msg) {
    if (!progress) return;
    std::lock_guard<std::mutex> lock(mutex);
    progress(msg);
  };

  std::vector<SimulatedRecording> free_space(static_cast<std::size_t>(std::max(1, P.free_space_files)));
  std::optional<SimulatedRecording> baseline, calibration;
  std::vector<Eigen::Vector3d> misalignments;
  for (double D : P.coaxial_offsets_m)
    for (const Eigen::Vector2d& r : P.radial_offsets_m) misalignments.emplace_back(r.x(), r.y(), D);
  std::vector<SimulatedTrial> trials(misalignments.size());
  std::vector<RecordingFileInfo> infos;

  auto write = [&](const SimulatedRecording& rec) {
    RecordingFileInfo info = summarize_simulated_recording(rec);
    info.file = out_dir / (rec.name + ".csv");
    save_recording(info.file, rec.recording);
    if (P.write_truth) {
      info.truth_file = out_dir / (rec.name + "_truth.csv");
      save_truth_csv(info.truth_file, rec);
    }
    report(fmt::format("wrote {} ({} samples, {:.1f} s)", info.file.filename().string(),
                       info.samples, info.duration_s));
    std::lock_guard<std::mutex> lock(mutex);
    infos.push_back(info);
  };

  // Longest first, so that two threads finish together.
  std::vector<std::function<void()>> jobs;
  for (std::size_t i = 0; i < free_space.size(); ++i)
    jobs.emplace_back([&, i] {
      free_space[i] = simulate_free_space(config, static_cast<int>(i));
      write(free_space[i]);
      free_space[i] = SimulatedRecording{};  // release the memory early
    });
  for (std::size_t i = 0; i < trials.size(); ++i)
    jobs.emplace_back([&, i] {
      SimulatedTrial t = simulate_trial(config, misalignments[i]);
      write(t.recording);
      write(t.static_recording);
      trials[i].name = t.name;
      trials[i].misalignment_m = t.misalignment_m;
    });
  jobs.emplace_back([&] { write(simulate_calibration(config)); });
  jobs.emplace_back([&] { write(simulate_baseline(config)); });
  // Written first: it says how the recordings were made, whatever stops the rest.
  save_config(out_dir / "sim_config.json", config);
  try {
    run_parallel(jobs, config.threads);
  } catch (const Interrupted& e) {
    // The recordings written are whole; without the manifest, nothing takes them for a session.
    std::string written;
    std::sort(infos.begin(), infos.end(),
              [](const RecordingFileInfo& a, const RecordingFileInfo& b) { return a.name < b.name; });
    for (const auto& info : infos) written += (written.empty() ? "" : ", ") + info.file.filename().string();
    const std::size_t planned = free_space.size() + 2 * trials.size() + 2;
    throw Interrupted(fmt::format("{}: {} of {} recordings written to {} ({}), and sim_config.json; session.json not "
                                  "written",
                                  e.what(), infos.size(), planned, out_dir.string(),
                                  written.empty() ? std::string("none") : written));
  }

  Session session;
  session.manifest = out_dir / "session.json";
  session.robot = config.robot;
  session.q0 = P.q0;
  for (std::size_t i = 0; i < free_space.size(); ++i)
    session.free_space.push_back(
        out_dir / (free_space.size() == 1 ? std::string("free_space.csv")
                                          : fmt::format("free_space_{}.csv", i + 1)));
  session.baseline = out_dir / "baseline.csv";
  session.calibration = CalibrationSpec{out_dir / "calibration.csv", P.calibration_offset_m};
  for (const SimulatedTrial& t : trials) {
    TrialSpec spec;
    spec.name = t.name;
    spec.recording = out_dir / (t.name + ".csv");
    spec.static_recording = out_dir / (t.name + "_static.csv");
    spec.truth_misalignment_m = t.misalignment_m;
    session.trials.push_back(spec);
  }
  nlohmann::json sim = {{"generator", "rcm simulate"},
                        {"seed", config.seed},
                        {"config", "sim_config.json"},
                        {"tissue", config.tissue.preset},
                        {"friction", config.friction_preset},
                        {"truth_files", P.write_truth}};
  session.extra["simulator"] = sim;
  save_session(session.manifest, session);

  SessionWriteSummary summary;
  summary.manifest = session.manifest;
  std::sort(infos.begin(), infos.end(),
            [](const RecordingFileInfo& a, const RecordingFileInfo& b) { return a.name < b.name; });
  summary.recordings = std::move(infos);
  summary.elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

ForceAngleResult run_force_angle_experiment(const SimConfig& config) {
  validate_config(config);
  const ForceAngleParams& F = config.force_angle;
  const Eigen::Vector3d q0 = config.protocol.q0;
  const double step_s = F.move_s + F.hold_s;
  const double total_s = step_s * static_cast<double>(F.angles_deg.size());
  std::vector<std::vector<ForceAnglePoint>> per_offset(F.offsets_m.size());
  std::vector<std::function<void()>> jobs;
  for (std::size_t d = 0; d < F.offsets_m.size(); ++d)
    jobs.emplace_back([&, d] {
      const double D = F.offsets_m[d];
      // Docked at q0, offset introduced, then pivoted through the angles in order.
      ReferenceTrajectory ref;
      ref.add_hold(0.0, q0);
      for (std::size_t i = 0; i < F.angles_deg.size(); ++i) {
        Eigen::Vector3d target = q0;
        target[F.pivot_joint - 1] += F.angles_deg[i] * kPi / 180.0;
        ref.add_move(step_s * static_cast<double>(i), F.move_s, target);
        ref.add_hold(step_s * static_cast<double>(i) + F.move_s, target);
      }
      const TissueModel tissue(config.tissue, q0, Eigen::Vector3d(0.0, 0.0, D));
      const std::string name = fmt::format("force_angle_D{}", std::lround(D * 1000));
      const SimulatedRecording rec =
          simulate_run(config, ref, &tissue, {{name, 0.0, total_s}},
                       derive_seed(config.seed, "noise:" + name))
              .front();
      const double rate = config.sensors.log_rate_hz;
      for (std::size_t i = 0; i < F.angles_deg.size(); ++i) {
        const double t_end = step_s * static_cast<double>(i + 1);
        const auto k1 = static_cast<Eigen::Index>(std::lround(t_end * rate));
        const auto k0 = static_cast<Eigen::Index>(std::lround((t_end - F.average_s) * rate));
        const Eigen::Index n = k1 - k0;
        const Eigen::VectorXd measured = rec.recording.force->middleRows(k0, n).rowwise().norm();
        const Eigen::VectorXd truth = rec.truth.force.middleRows(k0, n).rowwise().norm();
        ForceAnglePoint p;
        p.offset_m = D;
        p.theta_rad = F.angles_deg[i] * kPi / 180.0;
        p.theta_true_rad = rec.truth.theta.segment(k0, n).mean();
        p.force_n = measured.mean();
        p.force_std_n = std::sqrt((measured.array() - p.force_n).square().mean());
        p.force_true_n = truth.mean();
        p.force_law_n = compute_tissue_law(config.tissue, std::abs(D) * std::tan(p.theta_true_rad));
        per_offset[d].push_back(p);
      }
    });
  run_parallel(jobs, config.threads);
  ForceAngleResult result;
  for (auto& v : per_offset) result.points.insert(result.points.end(), v.begin(), v.end());
  return result;
}

void save_force_angle_csv(const std::filesystem::path& path, const ForceAngleResult& result) {
  fmt::memory_buffer buf;
  fmt::format_to(std::back_inserter(buf),
                 "offset_m,theta_rad,force_n,theta_deg,force_std_n,force_true_n,force_law_n,theta_true_rad\n");
  for (const auto& p : result.points)
    fmt::format_to(std::back_inserter(buf), "{},{},{},{},{},{},{},{}\n", p.offset_m, p.theta_rad,
                   p.force_n, p.theta_rad * 180.0 / kPi, p.force_std_n, p.force_true_n,
                   p.force_law_n, p.theta_true_rad);
  write_file_atomic(path, std::string(buf.data(), buf.size()));
}

PlotFiles save_force_angle_plot(const std::filesystem::path& stem, const ForceAngleResult& result) {
  PlotSpec spec;
  spec.title = "Static force at the incision vs pivot angle (simulated bench, paper Fig. 3)";
  spec.x_label = "pivot angle theta (deg)";
  spec.y_label = "|f| at the incision (N)";
  spec.legend = "top center";
  std::vector<double> offsets;
  for (const auto& p : result.points)
    if (std::find(offsets.begin(), offsets.end(), p.offset_m) == offsets.end())
      offsets.push_back(p.offset_m);
  for (double D : offsets) {
    PlotSeries s;
    s.label = fmt::format("D = {:g} mm", D * 1000.0);
    for (const auto& p : result.points)
      if (p.offset_m == D) {
        s.x.push_back(p.theta_rad * 180.0 / kPi);
        s.y.push_back(p.force_n);
      }
    spec.series.push_back(std::move(s));
  }
  return save_plot(spec, stem);
}

}  // namespace rcm::sim
