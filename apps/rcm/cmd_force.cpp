// rcm force: the incision force series of one recording (paper Eq. 6),
// f_inc_base = J_D^{-T} (tau - tau_fs), with its RMSE per axis against the
// recording's force columns when it has them.

#include <fmt/format.h>

#include <cmath>
#include <iostream>
#include <iterator>
#include <memory>
#include <optional>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace {
namespace cmd_force {

struct Options {
  std::string model_path, recording, out, q0, robot = "dvrk-psm-classic";
  double offset = 0.0;
  double max_condition = 0.0;
  bool dedupe = false;
  bool json = false;
};

void run(const Options& o) {
  const rcm::PsmModel robot = rcm::load_robot_model(o.robot, "--robot");
  if (!std::isfinite(o.offset)) throw rcm::InputError(rcm::cli::flag_location("--offset"), "must be finite");
  const auto model = rcm::dynamics::load_torque_model(o.model_path);
  rcm::RecordingReadOptions ro;
  ro.dedupe = o.dedupe;
  // The recording streams through the model and Eq. 6 a chunk at a time: memory does not grow with its length.
  const auto reader = rcm::open_recording(o.recording, ro);
  const std::string source = reader->source();
  if (reader->num_joints() < model->num_joints() || model->num_outputs() < 3) {
    rcm::InputLocation where;
    where.file = source;
    throw rcm::InputError(where, fmt::format("the model reads {} joints and predicts {}; the recording has {} joints "
                                             "and Eq. 6 needs the first three predicted",
                                             model->num_joints(), model->num_outputs(), reader->num_joints()));
  }
  rcm::Recording chunk;
  reader->read_chunk(chunk);
  // The sampling-period check reads the first chunk (its median interval).
  if (auto w = rcm::dynamics::check_sample_period(*model, chunk); !w.empty()) std::cerr << "warning: " << w << "\n";

  Eigen::Vector3d q0;
  if (o.q0.empty()) {
    // Trials start docked at q0, so the first sample is the natural default; say
    // so rather than guess silently.
    q0 = chunk.position.row(0).head<3>().transpose();
    std::cerr << fmt::format("note: --q0 not given; using the first sample of {} (line {}): {:.6f},{:.6f},{:.6f}\n",
                             source, chunk.line.empty() ? 0 : chunk.line.front(), q0[0], q0[1], q0[2]);
  } else {
    q0 = rcm::cli::parse_vector3(o.q0, "--q0");
  }
  robot.check_within_limits(q0, rcm::cli::flag_location("--q0"));

  rcm::JacobianCheckOptions check;
  if (o.max_condition < 0.0 || !std::isfinite(o.max_condition))
    throw rcm::InputError(rcm::cli::flag_location("--max-condition"), "must be a positive number");
  if (o.max_condition > 0.0) check.max_condition = o.max_condition;
  const rcm::IncisionFrame incision = rcm::make_incision_frame(q0);

  // RMSE per axis over the samples with a finite estimate; the singular ones
  // are counted in the output, never folded in as numbers.
  std::optional<rcm::AtomicFileWriter> csv_file;
  if (!o.out.empty()) {
    csv_file.emplace(o.out);
    csv_file->append("time,force_x,force_y,force_z,theta,condition,status\n");
  }
  std::string csv;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  std::size_t compared = 0, ill_conditioned = 0, singular = 0;
  Eigen::Index T = 0;
  rcm::dynamics::RecordingTorqueStream stream(*model, rcm::dynamics::PredictionMode::batch);
  auto take_ready = [&] {
    const rcm::Recording& rec = stream.get_samples();
    if (rec.num_samples() == 0) return;
    const rcm::IncisionForceSeries series =
        rcm::compute_incision_force_series(incision, rec, stream.get_torque(), o.offset, check);
    ill_conditioned += series.num_ill_conditioned;
    singular += series.num_singular;
    T += series.f_inc_base.rows();
    if (rec.has_force()) {
      for (Eigen::Index t = 0; t < series.f_inc_base.rows(); ++t) {
        if (!series.f_inc_base.row(t).allFinite()) continue;
        sum += (series.f_inc_base.row(t) - rec.force->row(t)).cwiseAbs2().transpose();
        ++compared;
      }
    }
    if (csv_file) {
      csv.clear();
      auto cell = [](double v) { return std::isfinite(v) ? fmt::format("{}", v) : std::string("nan"); };
      const auto& f = series.f_inc_base;
      for (Eigen::Index t = 0; t < f.rows(); ++t)
        fmt::format_to(std::back_inserter(csv), "{},{},{},{},{},{},{}\n", rec.time(t), cell(f(t, 0)), cell(f(t, 1)),
                       cell(f(t, 2)), series.theta(t), cell(series.condition(t)), rcm::to_string(series.status[t]));
      csv_file->append(csv);
    }
  };
  do {
    stream.add(chunk);
    take_ready();
  } while (reader->read_chunk(chunk));
  stream.finish();
  take_ready();
  if (csv_file) csv_file->commit();
  Eigen::Vector3d rmse = Eigen::Vector3d::Constant(NAN);
  if (compared > 0) rmse = (sum / static_cast<double>(compared)).cwiseSqrt();
  if (o.json) {
    nlohmann::json out;
    out["recording"] = source;
    out["model"] = {{"kind", rcm::dynamics::to_string(model->kind())}, {"path", o.model_path}};
    out["offset_m"] = o.offset;
    out["q0"] = rcm::cli::to_json(q0);
    out["samples"] = T;
    out["ill_conditioned"] = ill_conditioned;
    out["singular"] = singular;
    if (compared > 0)
      out["rmse"] = {{"x", rmse[0]}, {"y", rmse[1]}, {"z", rmse[2]}, {"samples", compared}};
    else
      out["rmse"] = nullptr;
    out["out"] = o.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(o.out);
    rcm::cli::print_json(out);
    return;
  }
  std::cout << fmt::format("recording  {} ({} samples)\n", source, T);
  std::cout << fmt::format("model      {} ({})\n", rcm::dynamics::to_string(model->kind()), o.model_path);
  std::cout << fmt::format("D          {:.4f} m, q0 [{:.6f}, {:.6f}, {:.6f}]\n", o.offset, q0[0], q0[1], q0[2]);
  std::cout << fmt::format("J_D        {} ill-conditioned, {} singular samples (force NaN)\n",
                           ill_conditioned, singular);
  if (compared > 0)
    std::cout << rcm::cli::format_table({"axis", "RMSE (N)"}, {{"x", fmt::format("{:.3f}", rmse[0])},
                                                               {"y", fmt::format("{:.3f}", rmse[1])},
                                                               {"z", fmt::format("{:.3f}", rmse[2])}})
              << fmt::format("(over {} samples with a finite estimate)\n", compared);
  else
    std::cout << "no force columns in the recording: no RMSE\n";
  if (!o.out.empty()) std::cout << "series written to " << o.out << "\n";
}

const bool registered = rcm::cli::register_command({"force", 35, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "force", "Incision force series of a recording (paper Eq. 6, f = J_D^-T (tau - tau_fs)); RMSE per axis against the "
               "recording's force columns when present; streams in constant memory");
  cmd->add_option("--model", o->model_path, "free-space torque model (from `rcm dynamics fit`)")->required();
  cmd->add_option("--offset", o->offset, "coaxial offset D in m")->required();
  cmd->add_option("--q0", o->q0, "docking configuration q0 (rad, rad, m; default: the recording's first sample)");
  cmd->add_option("RECORDING", o->recording, "recording (CSV, bag, rosbag2 directory, .db3 or .mcap)")->required();
  cmd->add_option("--out", o->out, "write the series as CSV: time,force_x,force_y,force_z,theta,condition,status");
  cmd->add_option("--max-condition", o->max_condition,
                  "condition number of J_D above which a sample is flagged ill-conditioned (default: the library's)");
  cmd->add_option("--robot", o->robot, "built-in robot name or rcm-robot/1 JSON file");
  cmd->add_flag("--dedupe", o->dedupe, "drop repeated rows");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_force
}  // namespace
