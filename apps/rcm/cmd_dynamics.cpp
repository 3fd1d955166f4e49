// `rcm dynamics fit|eval|payload`: learn tau_fs from free-space recordings,
// score a model as in the paper's Table II, re-identify a payload change.

#include <fmt/format.h>

#include <cmath>
#include <iostream>
#include <iterator>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "study_cli.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/payload.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/recording_reader.hpp"
#if defined(RCM_HAVE_TORCH)
#include "training_loader.hpp"
#endif

namespace {
namespace cmd_dynamics {

struct DynamicsArgs {
  std::string model_kind;  // empty: the default of rcm run, rcm monitor and the node
  std::string out;
  std::vector<std::string> recordings;
  bool dedupe = false;
  bool json = false;
  bool streaming = false;
  bool generic_structure = false;
  bool free_inertia = false;
  bool constant_coulomb = false;
  bool no_insertion_stiffness = false;
  bool no_live_zero_phase = false;
  std::string model_path;
  rcm::cli::OptionFlags<rcm::dynamics::FitOptions> fit;  // the flags that are fields of FitOptions
  std::optional<std::string> direction_features;     // unset: the kind's default
  std::optional<std::string> acceleration_features;  // unset: the kind's default
  std::optional<std::string> dahl_features;          // unset: the kind's default
  std::optional<double> loss_balance;                // unset: the kind's default
  std::optional<double> output_delay;                 // s; unset: the kind's default
  std::string torchscript_out, torchscript_in, predictions;
};

// "none" or comma-separated positive numbers, for the network-input flags
// (--direction-features, --acceleration-features, --dahl-features), which only the recurrent
// kinds read.
std::vector<double> parse_feature_list(const std::string& text, const std::string& flag,
                                       rcm::dynamics::TorqueModelKind kind) {
  if (text == "none") return {};
  std::vector<double> values = rcm::cli::parse_number_list(text, flag);
  for (const double s : values)
    if (!(s > 0))
      throw rcm::InputError(rcm::cli::flag_location(flag),
                            "expected 'none' or positive numbers, got " + rcm::quote_token(text));
  if (kind != rcm::dynamics::TorqueModelKind::lstm && kind != rcm::dynamics::TorqueModelKind::hybrid)
    throw rcm::InputError(rcm::cli::flag_location(flag), "is for --model lstm or hybrid only");
  return values;
}

std::vector<rcm::Recording> load_all(const std::vector<std::string>& paths, bool dedupe) {
  rcm::RecordingReadOptions ro;
  ro.dedupe = dedupe;
  std::vector<rcm::Recording> recs;
  for (const auto& p : paths) recs.push_back(rcm::load_recording(p, ro));
  return recs;
}

void run_fit(const DynamicsArgs& a) {
  using namespace rcm::dynamics;
  const rcm::TorqueModelFitter fitter = rcm::cli::get_torque_model_fitter();
  const auto kind = a.model_kind.empty() ? rcm::dynamics::get_default_model_kind()
                                         : parse_torque_model_kind(a.model_kind, "--model");
  rcm::dynamics::FitOptions o;
  a.fit.apply(o);
  if (a.direction_features)
    o.velocity_tanh_scales = parse_feature_list(*a.direction_features, "--direction-features", kind);
  if (a.acceleration_features)
    o.acceleration_filters_s = parse_feature_list(*a.acceleration_features, "--acceleration-features", kind);
  if (a.dahl_features) o.dahl_fractions = parse_feature_list(*a.dahl_features, "--dahl-features", kind);
  if (a.loss_balance) {
    if (kind != TorqueModelKind::lstm && kind != TorqueModelKind::hybrid)
      throw rcm::InputError(rcm::cli::flag_location("--loss-balance"), "is for --model lstm or hybrid only");
    if (!(*a.loss_balance >= 0 && *a.loss_balance <= 1))
      throw rcm::InputError(rcm::cli::flag_location("--loss-balance"),
                            fmt::format("expected a value in [0, 1], got {}", *a.loss_balance));
    o.loss_balance = a.loss_balance;
  }
  if (a.output_delay) {
    if (kind != TorqueModelKind::lstm)
      throw rcm::InputError(rcm::cli::flag_location("--output-delay"), "is for --model lstm only");
    if (!(*a.output_delay >= 0 && std::isfinite(*a.output_delay)))
      throw rcm::InputError(rcm::cli::flag_location("--output-delay"),
                            fmt::format("expected a finite value >= 0 (s), got {}", *a.output_delay));
    o.output_delay_s = a.output_delay;
  }
  if (a.generic_structure && kind != TorqueModelKind::linear && kind != TorqueModelKind::hybrid)
    throw rcm::InputError(rcm::cli::flag_location("--generic-structure"), "is for --model linear or hybrid only");
  o.rigid_body = !a.generic_structure;
  if (a.free_inertia && kind != TorqueModelKind::linear && kind != TorqueModelKind::hybrid)
    throw rcm::InputError(rcm::cli::flag_location("--free-inertia"), "is for --model linear or hybrid only");
  o.remote_center = !a.free_inertia;
  if (a.constant_coulomb && kind != TorqueModelKind::linear && kind != TorqueModelKind::hybrid)
    throw rcm::InputError(rcm::cli::flag_location("--constant-coulomb"), "is for --model linear or hybrid only");
  o.coulomb_profile = !a.constant_coulomb;
  if (a.no_insertion_stiffness && kind != TorqueModelKind::linear && kind != TorqueModelKind::hybrid)
    throw rcm::InputError(rcm::cli::flag_location("--no-insertion-stiffness"), "is for --model linear or hybrid only");
  o.insertion_stiffness = !a.no_insertion_stiffness;
  if (a.no_live_zero_phase && kind != TorqueModelKind::linear)
    throw rcm::InputError(rcm::cli::flag_location("--no-live-zero-phase"), "is for --model linear only");
  o.live_zero_phase = !a.no_live_zero_phase;
  const auto recs = load_all(a.recordings, a.dedupe);
  if (a.output_delay && kind == TorqueModelKind::lstm && !recs.empty()) {
    // Checked here too, so that a delay longer than the burn-in names the flag.
    const double period = median_sample_period(recs);
    const double samples = std::round(*a.output_delay / period);
    if (period > 0 && samples > o.burn_in)
      throw rcm::InputError(rcm::cli::flag_location("--output-delay"),
                            fmt::format("{} s is {} samples at the recordings' {:.4g} s, more than the burn-in of {} "
                                        "samples that the shifted targets need",
                                        *a.output_delay, samples, period, o.burn_in));
  }
  FitResult fit;
  rcm::install_interrupt_handlers();
#if defined(RCM_HAVE_TORCH)
  if (!a.torchscript_out.empty() && kind != TorqueModelKind::lstm) {
    throw rcm::InputError(rcm::cli::flag_location("--torchscript"), "TorchScript export is for --model lstm only");
  }
#endif
  try {
    fit = fitter(kind, recs, o);
  } catch (const rcm::Interrupted& e) {
    throw rcm::Interrupted(std::string(e.what()) + "; nothing saved, " + a.out + " not written");
  }
#if defined(RCM_HAVE_TORCH)
  if (!a.torchscript_out.empty()) {
    rcm::cli::get_training_functions().export_torchscript(static_cast<const LstmTorqueModel&>(*fit.model),
                                                          a.torchscript_out);
  }
#endif
  save_torque_model(a.out, *fit.model);
  if (a.json) {
    auto j = fit.summary.to_json();
    j["model"] = a.out;
    rcm::cli::print_json(j);
  } else {
    // The fit printed its report on stderr as it ended (FitOptions::verbose).
    std::cout << (o.verbose ? std::string() : fit.summary.brief_report()) << "model written to " << a.out << "\n";
  }
  if (fit.summary.interrupted)
    throw rcm::Interrupted(fmt::format("interrupted after {} epochs: saved the model of epoch {} (the best validation "
                                       "loss so far) to {}; its training did not finish{}",
                                       fit.summary.epochs, fit.summary.best_epoch, a.out,
                                       a.torchscript_out.empty() ? "" : "; TorchScript written to " + a.torchscript_out));
}

void run_eval(const DynamicsArgs& a) {
  using namespace rcm::dynamics;
  std::unique_ptr<TorqueModel> model = load_torque_model(a.model_path);
  rcm::RecordingReadOptions ro;
  ro.dedupe = a.dedupe;
  const auto mode = a.streaming ? PredictionMode::streaming : PredictionMode::batch;
  const int M = model->num_outputs();
  // --predictions: recording index, time, predicted and measured torque of every output joint.
  std::optional<rcm::AtomicFileWriter> predictions;
  if (!a.predictions.empty()) {
    predictions.emplace(a.predictions);
    std::string header = "recording,time";
    for (int j = 1; j <= M; ++j) header += fmt::format(",tau_fs_{}", j);
    for (int j = 1; j <= M; ++j) header += fmt::format(",effort_{}", j);
    predictions->append(header + "\n");
  }
  // Each recording streams through the model a chunk at a time: memory does not grow with the recordings.
  std::vector<std::string> warnings, sources;
  std::vector<RegimeSummary> regimes;
  const RegimeMonitor regime(model->info().regime);
  TorqueErrorAccumulator accumulator(M);
  std::string csv;
  for (std::size_t r = 0; r < a.recordings.size(); ++r) {
    const auto reader = rcm::open_recording(a.recordings[r], ro);
    if (reader->num_joints() < model->num_joints()) {
      rcm::InputLocation where;
      where.file = reader->source();
      throw rcm::InputError(where, fmt::format("the model reads {} joints, the recording has {}",
                                               model->num_joints(), reader->num_joints()));
    }
    sources.push_back(reader->source());
    // Where the recordings leave what the model was fitted on, its error there is an
    // extrapolation: say how much of each recording that is.
    RegimeSummary summary;
    auto regime_ws = regime.create_workspace();
    RecordingTorqueStream stream(*model, mode);
    auto take_ready = [&] {
      const rcm::Recording& rec = stream.get_samples();
      const Eigen::MatrixXd& p = stream.get_torque();
      if (rec.num_samples() == 0) return;
      accumulator.add(rec.effort.leftCols(M), p);
      if (!predictions) return;
      csv.clear();
      for (Eigen::Index t = 0; t < p.rows(); ++t) {
        fmt::format_to(std::back_inserter(csv), "{},{}", r + 1, rec.time(t));
        for (int j = 0; j < M; ++j) fmt::format_to(std::back_inserter(csv), ",{}", p(t, j));
        for (int j = 0; j < M; ++j) fmt::format_to(std::back_inserter(csv), ",{}", rec.effort(t, j));
        csv += "\n";
      }
      predictions->append(csv);
    };
    rcm::Recording chunk;
    for (bool first = true; reader->read_chunk(chunk); first = false) {
      // The sampling-period check reads the first chunk (its median interval).
      const std::string w = first ? check_sample_period(*model, chunk) : std::string();
      if (!w.empty()) {
        std::cerr << "warning: " << w << "\n";
        warnings.push_back(w);
      }
      add_regime_samples(regime, regime_ws, chunk, summary);
      stream.add(chunk);
      take_ready();
    }
    stream.finish();
    take_ready();
    regimes.push_back(summary);
  }
  const auto errors = accumulator.get_errors();
  if (predictions) predictions->commit();
  if (a.json) {
    auto j = to_json(errors);
    j["model"] = {{"kind", to_string(model->kind())}, {"path", a.model_path}};
    j["mode"] = a.streaming ? "streaming" : "batch";
    j["warnings"] = warnings;
    nlohmann::json regime_json = nlohmann::json::array();
    for (std::size_t r = 0; r < sources.size(); ++r) {
      auto rj = regimes[r].to_json();
      rj["recording"] = sources[r];
      regime_json.push_back(rj);
    }
    j["regime"] = regime_json;
    rcm::cli::print_json(j);
    return;
  }
  std::vector<std::vector<std::string>> rows;
  // Joint 3 is the insertion (N); every other joint is revolute (N m).
  for (const auto& e : errors) {
    const char* unit = e.index == 3 ? "N" : "N m";
    rows.push_back({std::to_string(e.index), fmt::format("{:.4g} {}", e.rmse, unit), fmt::format("{:.2f}", e.nrmse_percent),
                    fmt::format("{:.4g} {}", e.range, unit)});
  }
  std::cout << "model: " << to_string(model->kind()) << " (" << a.model_path << "), "
            << (a.streaming ? "streaming (as live)" : "batch (offline)") << "\n"
            << rcm::cli::format_table({"joint", "RMSE", "NRMSE %", "range"}, rows);
  for (std::size_t r = 0; r < sources.size(); ++r)
    std::cout << "regime: " << (sources.size() > 1 ? sources[r] + ": " : std::string()) << regimes[r].to_text() << "\n";
}

void run_payload(const DynamicsArgs& a) {
  using namespace rcm::dynamics;
  std::unique_ptr<TorqueModel> model = load_torque_model(a.model_path);
  const auto* linear = dynamic_cast<const LinearTorqueModel*>(model.get());
  if (!linear)
    throw rcm::InputError(rcm::InputLocation::plain(a.model_path, "kind"),
                          fmt::format("expected a linear model (the payload is re-identified on its rigid-body terms), got {}",
                                      to_string(model->kind())));
  const auto recs = load_all(a.recordings, a.dedupe);
  for (const auto& r : recs)
    if (auto w = check_sample_period(*model, r); !w.empty()) std::cerr << "warning: " << w << "\n";
  PayloadRefit refit;
  try {
    refit = refit_payload(*linear, recs);
  } catch (const rcm::InputError& e) {
    // The library names the recording or the model's part; the file is the CLI's.
    rcm::InputLocation where = e.where();
    if (where.file.empty()) where.file = a.model_path;
    throw rcm::InputError(where, e.reason());
  }
  save_torque_model(a.out, *refit.model);
  if (a.json) {
    nlohmann::json j = refit.to_json();
    j["model"] = a.model_path;
    j["out"] = a.out;
    rcm::cli::print_json(j);
    return;
  }
  std::vector<std::vector<std::string>> rows;
  for (int j = 0; j < 3; ++j) {
    const char* unit = j == 2 ? "N" : "N m";
    rows.push_back({std::to_string(j + 1), fmt::format("{:.4g} {}", refit.rms_before[j], unit),
                    fmt::format("{:.4g} {}", refit.rms_after[j], unit)});
  }
  std::cout << fmt::format("payload re-identified on {} samples (reciprocal condition {:.2g}): first moment "
                           "[{:.4g}, {:.4g}, {:.4g}] N m, weight along the instrument {:.4g} N, inertia about yaw "
                           "{:.4g} kg m^2 and pitch {:.4g} kg m^2; gravity direction [{:.4f}, {:.4f}, {:.4f}]\n",
                           refit.samples, refit.reciprocal_condition, refit.payload[0], refit.payload[1],
                           refit.payload[2], refit.payload[3], refit.inertia[0], refit.inertia[1],
                           refit.gravity_direction[0], refit.gravity_direction[1], refit.gravity_direction[2])
            << rcm::cli::format_table({"joint", "RMS residual before", "after"}, rows) << "wrote " << a.out << "\n";
}

#if defined(RCM_HAVE_TORCH)
void run_import(const DynamicsArgs& a) {
  auto model = rcm::cli::get_training_functions().import_torchscript(a.torchscript_in);
  rcm::dynamics::save_torque_model(a.out, *model);
  std::cerr << "imported " << a.torchscript_in << " -> " << a.out << "\n";
}
#endif

const bool registered = rcm::cli::register_command({"dynamics", 30, [](CLI::App& app) {
  auto args = std::make_shared<DynamicsArgs>();
  auto* dyn = app.add_subcommand("dynamics", "Free-space torque models tau_fs = f(q, qdot, history)");
  dyn->require_subcommand(1);

  auto* fit = dyn->add_subcommand("fit", "Learn tau_fs from free-space recordings (70/20/10 split in time order)");
  fit->add_option("--model", args->model_kind,
                  fmt::format("lstm | mlp | linear | hybrid (default {}: the model rcm run and rcm monitor fit)",
                              rcm::dynamics::to_string(rcm::dynamics::get_default_model_kind())));
  fit->add_option("--out", args->out, "model file to write (rcm-torque-model/1 JSON)")->required();
  fit->add_option("recordings", args->recordings, "free-space recordings (CSV, bag, rosbag2 directory, .db3 or .mcap)")->required();
  args->fit.add(fit, "--seed", {"seed"});
  args->fit.add(fit, "--max-minutes", {"max_minutes"});
  args->fit.add(fit, "--hidden", {"hidden_size"});
  args->fit.add(fit, "--layers", {"num_layers"});
  args->fit.add(fit, "--window", {"window"});
  args->fit.add(fit, "--streams", {"streams"});
  args->fit.add(fit, "--learning-rate", {"learning_rate"});
  fit->add_option("--direction-features", args->direction_features,
                  "lstm, hybrid: extra inputs tanh(qdot / (s x velocity sd)) for each s of this comma-separated "
                  "list, or 'none' (default: 0.01,0.03,0.1 for lstm, none for hybrid)");
  fit->add_option("--acceleration-features", args->acceleration_features,
                  "lstm, hybrid: extra inputs, the difference of consecutive qdot low-passed with each time "
                  "constant (s) of this comma-separated list, or 'none' (default: 0.03 for lstm, none for hybrid)");
  fit->add_option("--dahl-features", args->dahl_features,
                  "lstm, hybrid: Dahl friction inputs of displacement f x the joint's range, per f of this "
                  "list, or 'none' (default: 3e-5,3e-4,3e-3 for lstm, none for hybrid)");
  fit->add_option("--loss-balance", args->loss_balance,
                  "lstm, hybrid: p in [0, 1]; each joint's loss divided by its running mean to the power p "
                  "(default: 0.5 for lstm, 0 for hybrid)");
  fit->add_option("--output-delay", args->output_delay,
                  "lstm: how far the torque trails the input, so that the network sees what follows (s; 0: "
                  "causal; default 0.04)");
  args->fit.add(fit, "--threads", {"threads"});
  args->fit.add(fit, "--max-epochs", {"max_epochs"});
#if defined(RCM_HAVE_TORCH)
  fit->add_option("--torchscript", args->torchscript_out, "also export the LSTM as TorchScript to this file");
#endif
  fit->add_flag("--generic-structure", args->generic_structure,
                "linear, hybrid: a free 17-term potential and constant armatures instead of the rigid-body structure");
  fit->add_flag("--free-inertia", args->free_inertia,
                "linear, hybrid: the 19 inertia coefficients free, not tied by the bodies of a remote-centre arm");
  fit->add_flag("--constant-coulomb", args->constant_coulomb,
                "linear, hybrid: one Coulomb level per joint instead of a level that varies along the joint's travel "
                "(kept when it predicts better)");
  fit->add_flag("--no-insertion-stiffness", args->no_insertion_stiffness,
                "linear, hybrid: no stiffness along the insertion (an elastic element no rigid link's weight gives)");
  fit->add_flag("--no-live-zero-phase", args->no_live_zero_phase,
                "linear: live torque from a causal qddot, without delay, instead of the fit's zero-phase qddot with "
                "the torque trailing by about half its window");
  fit->add_flag("--dedupe", args->dedupe, "drop rows that repeat the previous row's joint data");
  fit->add_flag("--json", args->json, "print the fit summary as one JSON object");
  fit->callback([args] { run_fit(*args); });

  auto* ev = dyn->add_subcommand(
      "eval", "Per-joint RMSE and NRMSE (%) of a model on recordings (Table II); streams in constant memory");
  ev->add_option("model", args->model_path, "model file")->required();
  ev->add_option("recordings", args->recordings, "recordings (CSV, bag, rosbag2 directory, .db3 or .mcap)")->required();
  ev->add_option("--predictions", args->predictions, "also write the predicted torque of every sample to this CSV");
  ev->add_flag("--streaming", args->streaming,
               "one sample at a time, causally, as live (default: offline, qddot may use later samples)");
  ev->add_flag("--dedupe", args->dedupe, "drop rows that repeat the previous row's joint data");
  ev->add_flag("--json", args->json, "print {\"joints\": [{\"index\", \"rmse\", \"nrmse_percent\"}]}");
  ev->callback([args] { run_eval(*args); });

  auto* pl = dyn->add_subcommand(
      "payload", "Re-identify a payload change on the insertion stage from a short free-space recording with it");
  pl->add_option("model", args->model_path, "linear model fitted without the payload")->required();
  pl->add_option("recordings", args->recordings, "free-space recordings with the payload (a minute of motion)")
      ->required();
  pl->add_option("--out", args->out, "model file to write: the model with its potential refitted and the payload's inertia")->required();
  pl->add_flag("--dedupe", args->dedupe, "drop rows that repeat the previous row's joint data");
  pl->add_flag("--json", args->json, "print the payload and the residuals as one JSON object");
  pl->callback([args] { run_payload(*args); });

#if defined(RCM_HAVE_TORCH)
  auto* im = dyn->add_subcommand("import", "Convert a TorchScript LSTM trained in PyTorch (layout: docs/formats.md)");
  im->add_option("torchscript", args->torchscript_in, "TorchScript file")->required();
  im->add_option("--out", args->out, "model file to write")->required();
  im->callback([args] { run_import(*args); });
#endif
}});

}  // namespace cmd_dynamics
}  // namespace
