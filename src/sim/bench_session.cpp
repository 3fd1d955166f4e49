// A simulated session on disk (rcm-session/1): every recording of the protocol
// simulated in parallel and written with its ground truth, and the manifest.

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <mutex>
#include <thread>

#include "parallel.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/session.hpp"
#include "rcm/sim/bench.hpp"

namespace rcm::sim {

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

// Runs jobs on up to `threads` threads; the first exception is rethrown.
void detail::run_parallel(std::vector<std::function<void()>>& jobs, int threads) {
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

using detail::run_parallel;

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

}  // namespace rcm::sim
