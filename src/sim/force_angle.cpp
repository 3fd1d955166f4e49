// The force-angle sweep of the paper's Fig. 3: the incision force at every
// coaxial offset and pivot angle of ForceAngleParams, as a table and a plot.

#include <fmt/format.h>

#include <cmath>

#include "parallel.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/sim/arm_dynamics.hpp"
#include "rcm/sim/bench.hpp"

namespace rcm::sim {

namespace {
}  // namespace

using detail::run_parallel;

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
        target[F.pivot_joint - 1] += F.angles_deg[i] * M_PI / 180.0;
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
        p.theta_rad = F.angles_deg[i] * M_PI / 180.0;
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
                   p.force_n, p.theta_rad * 180.0 / M_PI, p.force_std_n, p.force_true_n,
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
        s.x.push_back(p.theta_rad * 180.0 / M_PI);
        s.y.push_back(p.force_n);
      }
    spec.series.push_back(std::move(s));
  }
  return save_plot(spec, stem);
}

}  // namespace rcm::sim
