#pragma once
// Free-space joint torque models tau_fs = f(q, qdot, history) (paper III-B).
//
// Every kind (lstm, mlp, linear, hybrid) is an immutable TorqueModel plus a
// workspace that holds its state and buffers (STYLE 1). compute_step() advances
// the state by one sample and never allocates, so a model can run inside a 1.5 kHz
// loop; predict_torque() runs it over a whole recording with the state carried,
// which is how friction memory (the holding torque set by the last direction of
// motion) reaches the estimate at rest.
//
// Nothing here includes LibTorch: loading and running a trained model needs only
// rcm::core. Training of the networks lives in rcm::torch (training.hpp).

#include <Eigen/Core>
#include <algorithm>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rcm/dynamics/regime.hpp"
#include "rcm/io/recording.hpp"

namespace rcm::dynamics {

enum class TorqueModelKind { lstm, mlp, linear, hybrid };

std::string to_string(TorqueModelKind kind);
// "lstm" | "mlp" | "linear" | "hybrid"; throws InputError naming `what` otherwise.
TorqueModelKind parse_torque_model_kind(const std::string& text, const std::string& what = "--model");
// The kinds' words, for options tables (rcm/common/options.hpp).
const OptionChoices<TorqueModelKind>& get_option_choices(OptionTag<TorqueModelKind>);

// What every model shares: which joints it reads and predicts and the sampling
// period it was trained at (the networks step at that period, whatever the
// rate of the samples they are given).
struct TorqueModelInfo {
  int num_joints = 0;        // joints read: q and qdot of joints 1..num_joints
  int num_outputs = 0;       // joints predicted: 1..num_outputs (<= num_joints)
  double sample_period_s = 0.0;
  nlohmann::json training = nlohmann::json::object();  // fit summary, informative only
  // What the fit saw (regime.hpp); empty for a model that does not say.
  TrainingRegime regime;
};

// State and buffers of one running model. Create with model.create_workspace().
class TorqueModelWorkspace {
 public:
  virtual ~TorqueModelWorkspace() = default;
};

class TorqueSequencePredictor;

class TorqueModel {
 public:
  explicit TorqueModel(TorqueModelInfo info) : info_(std::move(info)) {}
  virtual ~TorqueModel() = default;
  TorqueModel(const TorqueModel&) = delete;
  TorqueModel& operator=(const TorqueModel&) = delete;

  virtual TorqueModelKind kind() const = 0;
  const TorqueModelInfo& info() const { return info_; }
  int num_joints() const { return info_.num_joints; }
  int num_outputs() const { return info_.num_outputs; }

  // A workspace sized for this model, in the reset state.
  virtual std::unique_ptr<TorqueModelWorkspace> create_workspace() const = 0;
  // Forget the history (state as at the start of a recording).
  virtual void reset_state(TorqueModelWorkspace& workspace) const = 0;
  // Advance by one sample taken at time `t` (s) and write the predicted torque of
  // joints 1..num_outputs into `tau`: the torque of this sample, or, for a model
  // with output_delay() = d > 0, of the sample d calls earlier (the first d calls
  // write nothing meaningful). q and qd hold at least num_joints values.
  // No allocation. The workspace must come from this model's create_workspace().
  virtual void compute_step(TorqueModelWorkspace& workspace, double t, const double* q,
                            const double* qd, double* tau) const = 0;
  // Samples by which compute_step's torque trails its input: 0, or d for a
  // model that also sees the d samples after the one it predicts (the inertial
  // torque needs qddot, which a causal estimate gets late): a fixed-lag
  // network, or the linear model with its zero-phase qddot live. A live caller
  // pairs it with the effort and joint state of that sample (OnlinePipeline
  // does, by get_step_runs, or by find_delayed_sample for a model that gives
  // one torque per call); predict_torque and predict_torque_streaming align it.
  virtual int output_delay() const { return 0; }
  // The samples the last compute_step() ran through, for a model whose torque
  // trails and that may run several in one call (after a gap in the stream, or
  // when jittered stamps move the delay's target past two samples), so that a
  // caller can pair every one of them: `count` samples (0: none this call),
  // oldest first, each with its time and its num_outputs torques (row-major).
  // count -1 (the default): the model gives one torque per call, that of the
  // sample find_delayed_sample picks.
  struct StepRuns {
    int count = -1;
    const double* time = nullptr;
    const double* torque = nullptr;
  };
  virtual StepRuns get_step_runs(const TorqueModelWorkspace& /*workspace*/) const { return {}; }
  // The same in seconds, d samples of the training period: what a caller
  // streaming at another rate pairs by (the networks step on their own clock).
  double get_output_delay_s() const { return output_delay() * info_.sample_period_s; }

  // Body of the model file (see docs/dynamics.md); `info` is written by the caller.
  virtual nlohmann::json save_parameters() const = 0;

  // Whole-recording prediction behind predict_torque(): T x num_outputs from the
  // reset state. By default predict_torque_streaming(); a model may
  // override it with estimates that also use later samples (the linear model's
  // zero-phase qddot), which only offline analysis can afford. Sizes are checked
  // by predict_torque().
  virtual Eigen::MatrixXd predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                           const Eigen::MatrixXd& velocity) const;
  // predict_sequence() over a recording given in chunks (TorqueSequencePredictor).
  // By default the live prediction's (predict_torque_streaming); a model that
  // overrides predict_sequence overrides this too, and predict_sequence is
  // this over one chunk.
  virtual std::unique_ptr<TorqueSequencePredictor> create_sequence_predictor() const;

 private:
  TorqueModelInfo info_;
};

// The period of the slowest stream the dVRK sends (100 Hz): a model whose
// torque trails keeps half of it in hand, so that the sample nearest the
// delay's target may be up to that much newer than the target.
constexpr double kSlowestStreamPeriod = 0.01;

// Which of the last `count` samples of a stream (time_at(1) the newest,
// time_at(count) the oldest) the output of a model whose torque trails by
// get_output_delay_s() is for, `target` being the newest sample's time less
// that delay: the newest sample no later than the target, or the next newer
// one if that is nearer and less than half of kSlowestStreamPeriod after it
// (after a gap in the stream the sample after it is far newer: the older one
// is taken); all within kDelayedSampleTolerance_s (which stamps at the
// model's own rate differ from the target by; a tie, as at 100 Hz behind a
// delay of an odd number of 5 ms, goes to the older sample whatever the
// rounding, so that consecutive calls pick consecutive samples). Returns its
// `back` (1 = newest), or 0 while the stream is shorter than the delay. The
// model and the caller that pairs its output pick by this one rule. The search
// starts at `hint` (the last call's answer plus the samples added since), so
// that a caller streaming at 1.5 kHz behind hundreds of samples of delay
// walks one or two of them per call, not all; on times that never decrease
// the answer does not depend on the hint (1: a walk from the newest).
constexpr double kDelayedSampleTolerance_s = 1e-6;
template <class TimeAt>
int find_delayed_sample(int count, double target, TimeAt time_at, int hint = 1) {
  if (count < 1) return 0;
  auto at_or_before = [&](int b) { return time_at(b) <= target + kDelayedSampleTolerance_s; };
  int back = std::clamp(hint, 1, count);
  if (at_or_before(back)) {
    while (back > 1 && at_or_before(back - 1)) --back;
  } else {
    while (back <= count && !at_or_before(back)) ++back;
    if (back > count) return 0;
  }
  if (back > 1 && time_at(back - 1) - target < target - time_at(back) - kDelayedSampleTolerance_s &&
      time_at(back - 1) - target < 0.5 * kSlowestStreamPeriod)
    return back - 1;
  return back;
}

// Runs the model over a whole recording from the reset state: T x num_outputs
// (model.predict_sequence: compute_step() per sample, or a model's non-causal
// batch estimate; see docs/dynamics.md). Throws InputError if the recording has
// fewer joints than the model reads.
Eigen::MatrixXd predict_torque(const TorqueModel& model, const Recording& recording);
Eigen::MatrixXd predict_torque(const TorqueModel& model, const Eigen::VectorXd& time,
                               const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity);

// What the live robot gets over a recording: compute_step() on every sample
// from the reset state, as a live caller would (predict_torque may instead use
// a model's offline estimate). Row t is the torque of sample t: for a model
// whose torque trails by get_output_delay_s(), the output of the call that
// find_delayed_sample pairs with sample t (a row no call is paired with, when
// jittered stamps straddle the delay, takes the next paired output), the last
// rows from more calls that repeat the last sample (a zero-order hold), time
// advancing. Same size checks.
Eigen::MatrixXd predict_torque_streaming(const TorqueModel& model, const Eigen::VectorXd& time,
                                         const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity);
Eigen::MatrixXd predict_torque_streaming(const TorqueModel& model, const Recording& recording);

// Which of the two above a caller wants: the offline estimate or the live one.
enum class PredictionMode { batch, streaming };
Eigen::MatrixXd predict_torque(const TorqueModel& model, const Recording& recording, PredictionMode mode);

// A whole-recording prediction over a recording given in chunks: add() the
// samples in order, finish() at the end; the rows come out in order as soon
// as they are final, equal bit for bit to predict_torque's (batch) or
// predict_torque_streaming's rows. Memory holds what the model looks ahead
// and behind: the samples of its output delay, or the linear model's
// zero-phase window (a few seconds), never the recording.
class TorqueSequencePredictor {
 public:
  virtual ~TorqueSequencePredictor() = default;
  // Appends the rows now final to `out` (resized: rows x num_outputs; none is
  // possible). Sizes as predict_torque checks them.
  virtual void add(const Eigen::VectorXd& time, const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity,
                   Eigen::MatrixXd& out) = 0;
  // No more samples: the remaining rows into `out`.
  virtual void finish(Eigen::MatrixXd& out) = 0;
};
std::unique_ptr<TorqueSequencePredictor> create_torque_predictor(const TorqueModel& model, PredictionMode mode);

// The samples of a recording given in chunks with their torque: add() a
// chunk, then get_samples() holds the samples whose torque is final (in
// order, the ones before them already handed out) and get_torque() their
// rows. What a command that streams a recording through a model uses.
class RecordingTorqueStream {
 public:
  RecordingTorqueStream(const TorqueModel& model, PredictionMode mode);
  // Throws InputError if the chunk has fewer joints than the model reads.
  void add(const Recording& chunk);
  void finish();
  const Recording& get_samples() const { return ready_; }
  const Eigen::MatrixXd& get_torque() const { return torque_; }

 private:
  void take_ready();
  const TorqueModel& model_;
  std::unique_ptr<TorqueSequencePredictor> predictor_;
  Recording waiting_, ready_;
  Eigen::MatrixXd rows_, torque_;
};

// Model files: one JSON document, "format": "rcm-torque-model/1"; weights as
// base64 little-endian arrays so that save -> load is bit-exact.
nlohmann::json torque_model_to_json(const TorqueModel& model);
std::unique_ptr<TorqueModel> torque_model_from_json(const nlohmann::json& document,
                                                    const std::string& source);
void save_torque_model(const std::filesystem::path& path, const TorqueModel& model);
std::unique_ptr<TorqueModel> load_torque_model(const std::filesystem::path& path);

// The recurrent kinds step their network on its own clock, at the period they
// were trained at, on inputs interpolated between samples, so any rate works;
// when the recording's median period is over 4 training periods (the network
// then sees straight lines between samples far apart), a sentence saying so;
// empty otherwise.
std::string check_sample_period(const TorqueModel& model, const Recording& recording);

}  // namespace rcm::dynamics
