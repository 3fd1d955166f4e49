#include "rcm/dynamics/fit.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "rcm/common/options.hpp"
#include "rcm/dynamics/linear_model.hpp"

namespace rcm::dynamics {

namespace {
[[noreturn]] void bad_option(const std::string& field, const std::string& what) {
  InputLocation where;
  where.field = field;
  throw InputError(where, what);
}
}  // namespace

void FitOptions::check() const {
  if (!(train_fraction > 0 && validation_fraction > 0 && train_fraction + validation_fraction < 1))
    bad_option("train_fraction/validation_fraction", "expected two positive fractions summing to less than 1");
  if (threads < 1) bad_option("threads", "expected >= 1");
  if (num_outputs < 0) bad_option("num_outputs", "expected >= 0");
  if (hidden_size < 0 || num_layers < 0 || window < 0 || streams < 0 || burn_in < 0 || head_hidden < 1 ||
      mlp_hidden < 1)
    bad_option("network size", "expected non-negative sizes");
  if (max_epochs < 1) bad_option("max_epochs", "expected >= 1");
  if (!(learning_rate > 0) || !(weight_decay >= 0) || !(max_minutes > 0))
    bad_option("learning_rate/weight_decay/max_minutes", "expected positive values");
  if (velocity_tanh_scales)
    for (const double s : *velocity_tanh_scales)
      if (!(s > 0) || !std::isfinite(s)) bad_option("velocity_tanh_scales", "expected positive finite values");
  if (acceleration_filters_s)
    for (const double s : *acceleration_filters_s)
      if (!(s > 0) || !std::isfinite(s)) bad_option("acceleration_filters_s", "expected positive finite values");
  if (dahl_fractions)
    for (const double f : *dahl_fractions)
      if (!(f > 0) || !std::isfinite(f)) bad_option("dahl_fractions", "expected positive finite values");
  if (loss_balance && !(*loss_balance >= 0 && *loss_balance <= 1))
    bad_option("loss_balance", "expected a value in [0, 1]");
  if (output_delay_s && !(*output_delay_s >= 0 && std::isfinite(*output_delay_s)))
    bad_option("output_delay_s", "expected a finite value >= 0 (s)");
}

std::vector<double> get_default_velocity_tanh_scales(TorqueModelKind kind) {
  if (kind == TorqueModelKind::lstm) return {0.01, 0.03, 0.1};
  return {};
}

std::vector<double> get_default_acceleration_filters_s(TorqueModelKind kind) {
  if (kind == TorqueModelKind::lstm) return {0.03};
  return {};
}

std::vector<double> get_default_dahl_fractions(TorqueModelKind kind) {
  if (kind == TorqueModelKind::lstm) return {3e-5, 3e-4, 3e-3};
  return {};
}

double get_default_loss_balance(TorqueModelKind kind) { return kind == TorqueModelKind::lstm ? 0.5 : 0.0; }

double get_default_output_delay_s(TorqueModelKind kind) { return kind == TorqueModelKind::lstm ? 0.04 : 0.0; }

int resolve_output_delay_samples(TorqueModelKind kind, const FitOptions& options, double sample_period_s) {
  const double s = options.output_delay_s.value_or(get_default_output_delay_s(kind));
  if (s == 0.0) return 0;
  if (kind != TorqueModelKind::lstm)
    bad_option("output_delay_s", fmt::format("only the lstm has an output delay, not {}", to_string(kind)));
  if (!(sample_period_s > 0)) bad_option("output_delay_s", "the recordings have no sampling period");
  const double d = std::round(s / sample_period_s);
  // Targets before the first d samples of a recording do not exist; the burn-in
  // is never scored, so the delay must fit in it.
  if (d > options.burn_in)
    bad_option("output_delay_s", fmt::format("{} s is {} samples at {:.4g} s, more than the burn-in of {} samples", s,
                                             d, sample_period_s, options.burn_in));
  return static_cast<int>(d);
}

double compute_balanced_loss(const Eigen::Ref<const Eigen::ArrayXd>& per_joint_mse, double p) {
  if (per_joint_mse.size() == 0) throw std::invalid_argument("compute_balanced_loss: no joints");
  // A joint predicted exactly would make the geometric mean 0 whatever the others do.
  const Eigen::ArrayXd mse = per_joint_mse.max(1e-300);
  const double order = 1.0 - p;
  if (std::abs(order) < 1e-9) return std::exp(mse.log().mean());
  return std::pow(mse.pow(order).mean(), 1.0 / order);
}

TimeSplit split_in_time(const std::vector<Recording>& recordings, double train_fraction,
                        double validation_fraction) {
  Eigen::Index total = 0;
  for (const auto& r : recordings) total += static_cast<Eigen::Index>(r.num_samples());
  const auto train_end = static_cast<Eigen::Index>(std::llround(train_fraction * static_cast<double>(total)));
  const auto val_end =
      static_cast<Eigen::Index>(std::llround((train_fraction + validation_fraction) * static_cast<double>(total)));
  TimeSplit split;
  Eigen::Index offset = 0;
  for (std::size_t r = 0; r < recordings.size(); ++r) {
    const auto T = static_cast<Eigen::Index>(recordings[r].num_samples());
    auto add = [&](std::vector<SampleSegment>& to, Eigen::Index lo, Eigen::Index hi) {
      const Eigen::Index b = std::max(lo, offset), e = std::min(hi, offset + T);
      if (e > b) to.push_back({static_cast<int>(r), b - offset, e - offset});
    };
    add(split.train, 0, train_end);
    add(split.validation, train_end, val_end);
    add(split.test, val_end, total);
    offset += T;
  }
  return split;
}

void check_fit_recordings(const std::vector<Recording>& recordings, int min_samples) {
  if (recordings.empty()) bad_option("recordings", "at least one free-space recording is needed");
  std::size_t total = 0;
  for (const auto& r : recordings) {
    if (r.num_joints() < 3) {
      InputLocation where;
      where.file = r.source;
      throw InputError(where, fmt::format("expected at least 3 joints, got {}", r.num_joints()));
    }
    if (r.num_joints() != recordings.front().num_joints()) {
      InputLocation where;
      where.file = r.source;
      throw InputError(where, fmt::format("has {} joints but {} has {}; fit recordings of one arm", r.num_joints(),
                                          recordings.front().source, recordings.front().num_joints()));
    }
    total += r.num_samples();
  }
  if (total < static_cast<std::size_t>(min_samples)) {
    InputLocation where;
    where.file = recordings.front().source;
    throw InputError(where, fmt::format("only {} samples in all recordings; at least {} are needed to fit", total,
                                        min_samples));
  }
}

double median_sample_period(const std::vector<Recording>& recordings) {
  std::vector<double> dt;
  for (const auto& r : recordings)
    for (Eigen::Index i = 0; i + 1 < r.time.size(); ++i) dt.push_back(r.time(i + 1) - r.time(i));
  if (dt.empty()) return 0.0;
  std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
  return dt[dt.size() / 2];
}

int resolve_num_outputs(const std::vector<Recording>& recordings, const FitOptions& options) {
  const int n = recordings.front().num_joints();
  if (options.num_outputs == 0) return n;
  if (options.num_outputs > n) bad_option("num_outputs", fmt::format("expected <= {} (joints recorded)", n));
  return options.num_outputs;
}

nlohmann::json FitSummary::to_json() const {
  nlohmann::json j;
  j["kind"] = rcm::dynamics::to_string(kind);
  j["train_samples"] = train_samples;
  j["validation_samples"] = validation_samples;
  j["test_samples"] = test_samples;
  j["epochs"] = epochs;
  j["best_epoch"] = best_epoch;
  j["best_validation_loss"] = best_validation_loss;
  if (interrupted) j["interrupted"] = true;
  if (kind == TorqueModelKind::lstm || kind == TorqueModelKind::hybrid) j["loss_balance"] = loss_balance;
  if (kind == TorqueModelKind::lstm || output_delay_samples > 0) j["output_delay_samples"] = output_delay_samples;
  j["seconds"] = seconds;
  j["device"] = device;
  if (!structure.empty()) j["structure"] = structure;
  j["test"] = rcm::dynamics::to_json(test_errors)["joints"];
  j["warnings"] = warnings;
  return j;
}

std::string FitSummary::brief_report() const {
  std::string s = fmt::format("{} fit: {} train / {} validation / {} test samples, {:.1f} s on {}",
                              rcm::dynamics::to_string(kind), train_samples, validation_samples, test_samples,
                              seconds, device);
  if (!structure.empty()) s += fmt::format(", {} structure", structure);
  if (epochs > 0)
    s += fmt::format(", {} epochs (best {}, validation loss {:.4g})", epochs, best_epoch, best_validation_loss);
  s += "\n";
  for (const auto& e : test_errors)
    s += fmt::format("  test joint {}: RMSE {:.4g}, NRMSE {:.2f} %\n", e.index, e.rmse, e.nrmse_percent);
  for (const auto& w : warnings) s += "  warning: " + w + "\n";
  return s;
}

const OptionTable<FitOptions>& get_option_table(OptionTag<FitOptions>) {
  const auto positive = OptionLimits::above(0), non_negative = OptionLimits::at_least(0);
  static const auto table =
      OptionTable<FitOptions>("FitOptions")
          .add("seed", &FitOptions::seed, "random seed of the network initialization and batching")
          .add("threads", &FitOptions::threads, "LibTorch intra-op threads", "", OptionLimits::at_least(1))
          .add("verbose", &FitOptions::verbose, "progress to stderr")
          .add("train_fraction", &FitOptions::train_fraction, "first share of the samples, in time order, fitted on",
               "", OptionLimits::above_up_to(0, 1))
          .add("validation_fraction", &FitOptions::validation_fraction,
               "next share, for early stopping; the rest is the held-out test split", "",
               OptionLimits::above_up_to(0, 1))
          .add("num_outputs", &FitOptions::num_outputs, "joints to predict, 1..M (0: every recorded joint)", "",
               non_negative)
          .add("hidden_size", &FitOptions::hidden_size, "LSTM hidden size (0: 128, or 32 on < 5 min of data)", "",
               non_negative)
          .add("num_layers", &FitOptions::num_layers, "LSTM layers (0: 1)", "", non_negative)
          .add("head_hidden", &FitOptions::head_hidden, "width of the LSTM's tanh head", "", OptionLimits::at_least(1))
          .add("window", &FitOptions::window, "truncated-BPTT window (0: 100, or 50 on < 5 min of data)", "samples",
               non_negative)
          .add("streams", &FitOptions::streams, "contiguous streams per batch (0: 32)", "", non_negative)
          .add("burn_in", &FitOptions::burn_in, "samples run before a validation stream is scored", "samples",
               non_negative)
          .add("mlp_hidden", &FitOptions::mlp_hidden, "hidden width of each joint's MLP", "", OptionLimits::at_least(1))
          .add("max_epochs", &FitOptions::max_epochs, "epoch limit (early stopping usually ends sooner)", "",
               OptionLimits::at_least(1))
          .add("learning_rate", &FitOptions::learning_rate, "initial Adam learning rate", "", positive)
          .add("weight_decay", &FitOptions::weight_decay, "Adam weight decay (0: chosen from the amount of data)", "",
               non_negative)
          .add("patience", &FitOptions::patience, "epochs without validation improvement before stopping", "",
               OptionLimits::at_least(1))
          .add("plateau_patience", &FitOptions::plateau_patience, "epochs before the learning rate is halved", "",
               OptionLimits::at_least(1))
          .add("min_learning_rate", &FitOptions::min_learning_rate, "the learning rate is not halved below this", "",
               positive)
          .add("max_minutes", &FitOptions::max_minutes, "wall-clock budget of one fit", "min", positive)
          .add("velocity_tanh_scales", &FitOptions::velocity_tanh_scales,
               "lstm, hybrid: direction features tanh(qdot / (s x velocity sd)), one per s (null: the kind's "
               "default, get_default_velocity_tanh_scales)",
               "", positive)
          .add("acceleration_filters_s", &FitOptions::acceleration_filters_s,
               "lstm, hybrid: acceleration features, qdot's difference low-passed with each time constant (null: "
               "the kind's default)",
               "s", positive)
          .add("dahl_fractions", &FitOptions::dahl_fractions,
               "lstm, hybrid: Dahl features with characteristic displacement f x each joint's range of motion, one "
               "per f (null: the kind's default)",
               "", positive)
          .add("loss_balance", &FitOptions::loss_balance,
               "lstm, hybrid: each joint's loss divided by its running mean to this power (null: the kind's "
               "default)",
               "", OptionLimits::within(0, 1))
          .add("output_delay_s", &FitOptions::output_delay_s,
               "lstm: how far the network's torque trails its input (null: the kind's default; 0: causal)", "s",
               non_negative)
          .add("prefer_cuda", &FitOptions::prefer_cuda, "train on a CUDA device when there is one")
          .add("rigid_body", &FitOptions::rigid_body,
               "linear, hybrid: the rigid-body structure of joints 1-3 (false: a free potential and constant "
               "armature)")
          .add("remote_center", &FitOptions::remote_center,
               "linear, hybrid, with the rigid-body structure: its inertia tied by the bodies of a remote-centre "
               "arm (false: 19 free coefficients)")
          .add("coulomb_profile", &FitOptions::coulomb_profile,
               "linear, hybrid, with the rigid-body structure: a Coulomb level that varies along each joint's "
               "travel, when it predicts better (false: constant)")
          .add("insertion_stiffness", &FitOptions::insertion_stiffness,
               "linear, hybrid, with the rigid-body structure: a stiffness along the insertion, an elastic element "
               "that no rigid link's weight gives (false: none)")
          .add("travel_terms", &FitOptions::travel_terms,
               "linear, hybrid, with the rigid-body structure: a torque and a multi-scale hysteretic friction "
               "along each joint's travel, fitted on what the rest leaves, where they predict better (false: none)")
          .add("live_zero_phase", &FitOptions::live_zero_phase,
               "linear: live torque from the fit's zero-phase qddot, trailing by about half its window (false: "
               "causal qddot, no delay)")
          .add_check([](const FitOptions& o) { o.check(); });
  return table;
}

TorqueModelKind get_default_model_kind() { return TorqueModelKind::linear; }

FitResult fit_torque_model_without_networks(TorqueModelKind kind, const std::vector<Recording>& recordings,
                                            const FitOptions& options, const InputLocation& where) {
  if (kind != TorqueModelKind::linear)
    throw InputError(where, "fitting " + to_string(kind) +
                                " needs LibTorch (rcm::torch), which this program does not have; only the linear "
                                "model is fitted here. Fit it with `rcm dynamics fit --model " + to_string(kind) +
                                "` and use the model file");
  return fit_linear_torque_model(recordings, options);
}

}  // namespace rcm::dynamics

namespace rcm::dynamics {
std::vector<JointTorqueError> evaluate_on_segments(const TorqueModel& model,
                                                   const std::vector<Recording>& recordings,
                                                   const std::vector<SampleSegment>& segments) {
  Eigen::Index total = 0;
  for (const auto& s : segments) total += s.size();
  const int M = model.num_outputs();
  Eigen::MatrixXd measured(total, M), predicted(total, M);
  Eigen::Index row = 0;
  int cached = -1;
  Eigen::MatrixXd p;
  for (const auto& s : segments) {
    if (s.recording != cached) {
      p = predict_torque(model, recordings[s.recording]);
      cached = s.recording;
    }
    predicted.middleRows(row, s.size()) = p.middleRows(s.begin, s.size());
    measured.middleRows(row, s.size()) = recordings[s.recording].effort.leftCols(M).middleRows(s.begin, s.size());
    row += s.size();
  }
  return compute_torque_errors(measured, predicted);
}
}  // namespace rcm::dynamics
