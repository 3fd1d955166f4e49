#include "rcm/dynamics/networks.hpp"

// The network kinds of free-space model (lstm, mlp, hybrid): construction
// checks, workspaces and the per-sample step. The kernels are in
// network_kernels.cpp, the memory features in network_features.cpp, the model
// file in network_io.cpp.

#include <algorithm>
#include <deque>
#include <stdexcept>

#include "network_parts.hpp"
#include "rcm/dynamics/linear_model.hpp"

namespace rcm::dynamics {

using detail::check_normalization;
using detail::check_stack;
using detail::save_lstm;
using detail::save_normalization;
using detail::save_stack;

void detail::check_normalization(const Normalization& n, int joints, int outputs) {
  if (n.input_mean.size() != 2 * joints || n.input_scale.size() != 2 * joints)
    throw std::invalid_argument("normalization: expected 2 x num_joints input entries");
  if (n.output_mean.size() != outputs || n.output_scale.size() != outputs)
    throw std::invalid_argument("normalization: expected num_outputs output entries");
  if (n.velocity_tanh_scale.size() % joints != 0 || !(n.velocity_tanh_scale.array() > 0).all())
    throw std::invalid_argument("normalization: velocity_tanh_scale must hold features x num_joints positive values");
  if (!(n.acceleration_filter_s.array() > 0).all() || !(n.acceleration_scale.array() > 0).all() ||
      n.acceleration_scale.size() != n.acceleration_filter_s.size() * joints)
    throw std::invalid_argument(
        "normalization: acceleration_filter_s (K positive time constants) and acceleration_scale (K x num_joints "
        "positive values) do not match");
  if (n.dahl_displacement.size() % joints != 0 || !(n.dahl_displacement.array() > 0).all() ||
      !n.dahl_displacement.allFinite())
    throw std::invalid_argument(
        "normalization: dahl_displacement must hold features x num_joints positive finite values");
}

namespace {

struct LstmWorkspace final : TorqueModelWorkspace {
  LstmKernel::State state;
  AccelerationFilter acceleration;
  DahlFilter dahl;
  Eigen::VectorXf x, y;
  Eigen::VectorXd base;  // hybrid: model-based part
  std::unique_ptr<TorqueModelWorkspace> base_ws;
  // The network's clock (advance_network): step k at clock_origin + k period.
  bool clock_started = false;
  double clock_origin = 0.0, last_time = 0.0;
  long long next_step = 0;
  Eigen::VectorXd last_q, last_qd, step_q, step_qd;
};

// x: n.network_inputs(N) floats; acceleration, dahl: the filters' values (read
// only when n has those features).
void normalize_input(const Normalization& n, int N, const double* q, const double* qd, const double* acceleration,
                     const double* dahl, float* x) {
  for (int k = 0; k < N; ++k) {
    x[k] = static_cast<float>((q[k] - n.input_mean[k]) / n.input_scale[k]);
    x[N + k] = static_cast<float>((qd[k] - n.input_mean[N + k]) / n.input_scale[N + k]);
  }
  const auto F = n.velocity_tanh_scale.size();
  if (F > 0) {
    for (Eigen::Index f = 0; f < F; ++f) x[2 * N + f] = static_cast<float>(qd[f % N]) / n.velocity_tanh_scale[f];
    // Eigen's vectorized tanh, as for the training's inputs; a scalar std::tanh loop was slower.
    Eigen::Map<Eigen::ArrayXf> features(x + 2 * N, F);
    features = features.tanh();
  }
  float* xa = x + 2 * N + F;
  for (Eigen::Index f = 0; f < n.acceleration_scale.size(); ++f)
    xa[f] = static_cast<float>(acceleration[f]) / n.acceleration_scale[f];
  float* xd = xa + n.acceleration_scale.size();
  for (Eigen::Index f = 0; f < n.dahl_displacement.size(); ++f) xd[f] = static_cast<float>(dahl[f]);
}

void init_filters(const Normalization& n, int N, LstmWorkspace& ws) {
  ws.acceleration = AccelerationFilter(n.acceleration_filter_s, N);
  ws.dahl = DahlFilter(n.dahl_displacement, N);
  for (Eigen::VectorXd* v : {&ws.last_q, &ws.last_qd, &ws.step_q, &ws.step_qd}) *v = Eigen::VectorXd::Zero(N);
}

void reset_filters(LstmWorkspace& ws) {
  ws.acceleration.reset();
  ws.dahl.reset();
  ws.clock_started = false;
}

// Advances the feature filters by one sample and writes the network input to ws.x.
void compute_network_input(const Normalization& n, int N, LstmWorkspace& ws, double t, const double* q,
                           const double* qd) {
  if (n.has_acceleration()) ws.acceleration.update(t, qd);
  if (n.has_dahl()) ws.dahl.update(q);
  normalize_input(n, N, q, qd, ws.acceleration.values().data(), ws.dahl.values().data(), ws.x.data());
}

// A gap in the stream longer than this restarts the network's clock at the
// next sample instead of stepping through it: a straight line between two
// samples that far apart is no motion the arm made, and a live callback must
// not run thousands of steps after a silence.
constexpr double kMaxInterpolatedGap = 0.25;

// The network learned the dynamics of one step of its training period, so it
// steps on its own clock, every `period` seconds, whatever rate the samples come
// at (the dVRK streams at 100 Hz to 1.5 kHz): every tick up to the sample's
// time t, on inputs interpolated linearly between the previous sample and this
// one; ws.y is then the output of the latest tick (held until the next). A tick
// within 1 % of a period of t is this sample's, so that at the training rate
// each sample is one step on its own values, as the network was trained. The
// first sample, a time that goes back or a gap over kMaxInterpolatedGap
// restarts the clock at t with one step.
void advance_network(const LstmKernel& kernel, const Normalization& n, int N, double period, LstmWorkspace& ws,
                     double t, const double* q, const double* qd) {
  const double gap = t - ws.last_time;
  if (!ws.clock_started || !(gap >= 0) || gap > kMaxInterpolatedGap || !(period > 0)) {
    ws.clock_started = true;
    ws.clock_origin = t;
    ws.next_step = 1;
    compute_network_input(n, N, ws, t, q, qd);
    kernel.step(ws.state, ws.x.data(), ws.y.data());
  } else {
    const double own = 0.01 * period;
    for (;;) {
      const double tick = ws.clock_origin + static_cast<double>(ws.next_step) * period;
      if (tick > t + own) break;
      if (tick >= t - own) {
        compute_network_input(n, N, ws, t, q, qd);
      } else {
        const double a = (tick - ws.last_time) / gap;
        for (int k = 0; k < N; ++k) {
          ws.step_q[k] = ws.last_q[k] + a * (q[k] - ws.last_q[k]);
          ws.step_qd[k] = ws.last_qd[k] + a * (qd[k] - ws.last_qd[k]);
        }
        compute_network_input(n, N, ws, tick, ws.step_q.data(), ws.step_qd.data());
      }
      kernel.step(ws.state, ws.x.data(), ws.y.data());
      ++ws.next_step;
    }
  }
  ws.last_time = t;
  for (int k = 0; k < N; ++k) ws.last_q[k] = q[k], ws.last_qd[k] = qd[k];
}

}  // namespace

// ---------------------------------------------------------------------------- lstm

LstmTorqueModel::LstmTorqueModel(TorqueModelInfo info, LstmNetwork network, Normalization normalization,
                                 int output_delay)
    : TorqueModel(std::move(info)),
      kernel_(network),
      normalization_(std::move(normalization)),
      output_delay_(output_delay) {
  check_normalization(normalization_, num_joints(), num_outputs());
  if (output_delay_ < 0) throw std::invalid_argument("LSTM model: output_delay must be >= 0 samples");
  if (network.input_size() != normalization_.network_inputs(num_joints()) || network.output_size() != num_outputs())
    throw std::invalid_argument(
        "LSTM model: network sizes do not match the normalization's inputs (2 x num_joints + direction, "
        "acceleration and Dahl features) / num_outputs");
}

std::unique_ptr<TorqueModelWorkspace> LstmTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LstmWorkspace>();
  ws->state = kernel_.create_state();
  init_filters(normalization_, num_joints(), *ws);
  ws->x = Eigen::VectorXf::Zero(normalization_.network_inputs(num_joints()));
  ws->y = Eigen::VectorXf::Zero(num_outputs());
  return ws;
}

void LstmTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  LstmKernel::reset(ws.state);
  reset_filters(ws);
}

void LstmTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                   double* tau) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  advance_network(kernel_, normalization_, num_joints(), info().sample_period_s, ws, t, q, qd);
  for (int j = 0; j < num_outputs(); ++j)
    tau[j] = static_cast<double>(ws.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
}

nlohmann::json LstmTorqueModel::save_parameters() const {
  nlohmann::json j = {{"lstm", save_lstm(kernel_.network())}, {"normalization", save_normalization(normalization_)}};
  // Absent at 0, so that a causal model writes no such field.
  if (output_delay_ > 0) j["output_delay_samples"] = output_delay_;
  return j;
}

// ---------------------------------------------------------------------------- mlp

namespace {
struct MlpWorkspace final : TorqueModelWorkspace {
  Eigen::VectorXf x, a, b;
  float y = 0;
};
}  // namespace

MlpTorqueModel::MlpTorqueModel(TorqueModelInfo info, std::vector<DenseStack> per_joint, Normalization normalization)
    : TorqueModel(std::move(info)), per_joint_(std::move(per_joint)), normalization_(std::move(normalization)) {
  if (static_cast<int>(per_joint_.size()) != num_outputs())
    throw std::invalid_argument("MLP model: expected one network per output joint");
  for (const auto& s : per_joint_) {
    check_stack(s, "MLP");
  }
  check_normalization(normalization_, num_joints(), num_outputs());
  if (normalization_.has_acceleration() || normalization_.has_dahl())
    throw std::invalid_argument("MLP model: acceleration and Dahl features need a state, and the MLP is memoryless");
  for (const auto& s : per_joint_)
    if (s.input_size() != normalization_.network_inputs(num_joints()) || s.output_size() != 1)
      throw std::invalid_argument("MLP model: each network maps the normalization's inputs to 1 output");
}

std::unique_ptr<TorqueModelWorkspace> MlpTorqueModel::create_workspace() const {
  auto ws = std::make_unique<MlpWorkspace>();
  int w = 0;
  for (const auto& s : per_joint_) w = std::max(w, s.max_width());
  ws->x = Eigen::VectorXf::Zero(normalization_.network_inputs(num_joints()));
  ws->a = Eigen::VectorXf::Zero(w);
  ws->b = Eigen::VectorXf::Zero(w);
  return ws;
}

void MlpTorqueModel::reset_state(TorqueModelWorkspace&) const {}

void MlpTorqueModel::compute_step(TorqueModelWorkspace& workspace, double, const double* q, const double* qd,
                                  double* tau) const {
  auto& ws = static_cast<MlpWorkspace&>(workspace);
  normalize_input(normalization_, num_joints(), q, qd, nullptr, nullptr, ws.x.data());
  for (int j = 0; j < num_outputs(); ++j) {
    compute_dense_forward(per_joint_[j], ws.x.data(), &ws.y, ws.a.data(), ws.b.data());
    tau[j] = static_cast<double>(ws.y) * normalization_.output_scale[j] + normalization_.output_mean[j];
  }
}

nlohmann::json MlpTorqueModel::save_parameters() const {
  nlohmann::json nets = nlohmann::json::array();
  for (const auto& s : per_joint_) nets.push_back(save_stack(s));
  return {{"networks", nets}, {"normalization", save_normalization(normalization_)}};
}

// ---------------------------------------------------------------------------- hybrid

HybridTorqueModel::HybridTorqueModel(TorqueModelInfo info, std::shared_ptr<const LinearTorqueModel> base,
                                     LstmNetwork residual, Normalization residual_normalization)
    : TorqueModel(std::move(info)),
      base_(std::move(base)),
      kernel_(residual),
      normalization_(std::move(residual_normalization)) {
  if (!base_ || base_->num_joints() != num_joints() || base_->num_outputs() != num_outputs())
    throw std::invalid_argument("hybrid model: base model joints differ");
  if (base_->output_delay() != 0)
    throw std::invalid_argument(
        "hybrid model: the model-based part steps beside the network without delay (live_zero_phase off)");
  check_normalization(normalization_, num_joints(), num_outputs());
  if (residual.input_size() != normalization_.network_inputs(num_joints()) || residual.output_size() != num_outputs())
    throw std::invalid_argument("hybrid model: residual network sizes do not match");
}

std::unique_ptr<TorqueModelWorkspace> HybridTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LstmWorkspace>();
  ws->state = kernel_.create_state();
  init_filters(normalization_, num_joints(), *ws);
  ws->x = Eigen::VectorXf::Zero(normalization_.network_inputs(num_joints()));
  ws->y = Eigen::VectorXf::Zero(num_outputs());
  ws->base_ws = base_->create_workspace();
  return ws;
}

void HybridTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  LstmKernel::reset(ws.state);
  reset_filters(ws);
  base_->reset_state(*ws.base_ws);
}

void HybridTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                     double* tau) const {
  auto& ws = static_cast<LstmWorkspace&>(workspace);
  base_->compute_step(*ws.base_ws, t, q, qd, tau);
  advance_network(kernel_, normalization_, num_joints(), info().sample_period_s, ws, t, q, qd);
  for (int j = 0; j < num_outputs(); ++j)
    tau[j] += static_cast<double>(ws.y[j]) * normalization_.output_scale[j] + normalization_.output_mean[j];
}

// The base's whole-recording prediction (its residual was trained against
// that one, see training), plus the residual network stepped with its state,
// a sample as soon as the base has its row.
class HybridSequencePredictor final : public TorqueSequencePredictor {
 public:
  explicit HybridSequencePredictor(const HybridTorqueModel& model)
      : model_(model),
        base_(model.base_->create_sequence_predictor()),
        ws_(model.create_workspace()),
        N_(model.num_joints()),
        M_(model.num_outputs()),
        sample_(1 + 2 * static_cast<std::size_t>(N_)) {}

  void add(const Eigen::VectorXd& time, const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity,
           Eigen::MatrixXd& out) override {
    for (Eigen::Index i = 0; i < time.size(); ++i) {
      waiting_.push_back(time(i));
      for (int j = 0; j < N_; ++j) waiting_.push_back(position(i, j));
      for (int j = 0; j < N_; ++j) waiting_.push_back(velocity(i, j));
    }
    base_->add(time, position, velocity, out);
    add_residual(out);
  }
  void finish(Eigen::MatrixXd& out) override {
    base_->finish(out);
    add_residual(out);
  }

 private:
  void add_residual(Eigen::MatrixXd& out) {
    auto& lw = static_cast<LstmWorkspace&>(*ws_);
    const std::size_t stride = 1 + 2 * static_cast<std::size_t>(N_);
    for (Eigen::Index r = 0; r < out.rows(); ++r) {
      for (std::size_t k = 0; k < stride; ++k) {
        sample_[k] = waiting_.front();
        waiting_.pop_front();
      }
      advance_network(model_.kernel_, model_.normalization_, N_, model_.info().sample_period_s, lw, sample_[0],
                      &sample_[1], &sample_[1 + static_cast<std::size_t>(N_)]);
      for (int j = 0; j < M_; ++j)
        out(r, j) += static_cast<double>(lw.y[j]) * model_.normalization_.output_scale[j] +
                     model_.normalization_.output_mean[j];
    }
  }

  const HybridTorqueModel& model_;
  std::unique_ptr<TorqueSequencePredictor> base_;
  std::unique_ptr<TorqueModelWorkspace> ws_;
  int N_, M_;
  std::deque<double> waiting_;  // per sample: time, q (N), qd (N)
  std::vector<double> sample_;
};

std::unique_ptr<TorqueSequencePredictor> HybridTorqueModel::create_sequence_predictor() const {
  return std::make_unique<HybridSequencePredictor>(*this);
}

Eigen::MatrixXd HybridTorqueModel::predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                                    const Eigen::MatrixXd& velocity) const {
  const auto predictor = create_sequence_predictor();
  Eigen::MatrixXd head, tail;
  predictor->add(time, position, velocity, head);
  predictor->finish(tail);
  Eigen::MatrixXd out(head.rows() + tail.rows(), num_outputs());
  out << head, tail;
  return out;
}

nlohmann::json HybridTorqueModel::save_parameters() const {
  return {{"base", base_->save_parameters()},
          {"residual", save_lstm(kernel_.network())},
          {"normalization", save_normalization(normalization_)}};
}

}  // namespace rcm::dynamics
