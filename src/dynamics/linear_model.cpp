#include "rcm/dynamics/linear_model.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <deque>
#include <iostream>
#include <limits>
#include <memory>
#include <stdexcept>

#include "acceleration.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "rcm/dynamics/travel_terms.hpp"
#include "model_io.hpp"
#include "gravity_terms.hpp"

namespace rcm::dynamics {


namespace {

using detail::AccelerationEstimator;
using detail::is_time_sorted;
using detail::kDefaultAccelerationFilter;
using detail::kDefaultAccelerationWindow;
using detail::G;

struct LinearWorkspace final : TorqueModelWorkspace {
  Eigen::VectorXd prev_q, z, z_slow, acceleration;  // prev_q: at the Dahl states' last step
  // M x H, a joint's elements contiguous: the travel terms' Dahl states.
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> z_travel;
  Eigen::VectorXd travel_row;     // one joint's travel regressor
  std::vector<AccelerationEstimator> qdd;
  DahlClock dahl_clock;
  bool has_previous = false;
  Eigen::Matrix<double, 3, G> Y;
  Eigen::Matrix<double, 3, kInertiaTerms> Y_inertia;
  // live_zero_phase: the last samples [time, q 1..N, qd 1..N], sample number c
  // at row c % capacity; `pushed` samples since the stream (re)started, the
  // first `done` of them run; the torque of the last one run.
  std::vector<double> ring;
  std::int64_t capacity = 0, pushed = 0, done = 0;
  int back = 1;  // the last pick's distance from the newest sample (find_delayed_sample's hint)
  std::vector<detail::ZeroPhaseSlope> zero_phase;  // per output joint
  Eigen::VectorXd delayed_tau;
  // The samples the last call ran: their times, and their torques (row-major).
  std::vector<double> run_time, run_tau;
  int run_count = 0;
};

// Rows of the ring: the delay and the half window after it at the model's rate
// or at 2 kHz, whichever is faster (as the causal estimator's ring), bounded.
constexpr double kMaxRingSamples = 16384.0;

}  // namespace

void LinearTorqueModel::compute_gravity_regressor(const double* q, Eigen::Matrix<double, 3, G>& Y) {
  const double s1 = std::sin(q[0]), c1 = std::cos(q[0]);
  const double s2 = std::sin(q[1]), c2 = std::cos(q[1]);
  const double a[3] = {1.0, s1, c1}, da[3] = {0.0, c1, -s1};
  const double b[3] = {1.0, s2, c2}, db[3] = {0.0, c2, -s2};
  const double c[2] = {1.0, q[2]}, dc[2] = {0.0, 1.0};
  int k = 0;
  for (int al = 0; al < 3; ++al)
    for (int be = 0; be < 3; ++be)
      for (int ga = 0; ga < 2; ++ga) {
        if (al == 0 && be == 0 && ga == 0) continue;  // a constant potential has no torque
        Y(0, k) = da[al] * b[be] * c[ga];
        Y(1, k) = a[al] * db[be] * c[ga];
        Y(2, k) = a[al] * b[be] * dc[ga];
        ++k;
      }
}

LinearTorqueModel::LinearTorqueModel(TorqueModelInfo info, LinearTorqueParameters p)
    : TorqueModel(std::move(info)), parameters_(std::move(p)) {
  const int M = num_outputs();
  if (num_joints() < 3) throw std::invalid_argument("linear model: needs at least 3 joints");
  auto& q = parameters_;
  if (q.acceleration_window_s.size() == 0) q.acceleration_window_s = Eigen::VectorXd::Constant(M, kDefaultAccelerationWindow);
  if (q.acceleration_filter_s.size() == 0) q.acceleration_filter_s = Eigen::VectorXd::Constant(M, kDefaultAccelerationFilter);
  if (q.batch_acceleration_window_s.size() == 0) q.batch_acceleration_window_s = Eigen::VectorXd::Zero(M);
  if (q.gravity.size() != G || q.armature.size() != M || q.viscous.size() != M || q.coulomb.size() != M ||
      q.offset.size() != M || q.dahl_displacement.size() != M || q.acceleration_window_s.size() != M ||
      q.acceleration_filter_s.size() != M || q.batch_acceleration_window_s.size() != M)
    throw std::invalid_argument("linear model: parameter sizes do not match num_outputs");
  if ((q.dahl_displacement.array() <= 0).any())
    throw std::invalid_argument("linear model: dahl_displacement must be positive");
  if (q.inertia.size() != 0 && (q.inertia.size() != kInertiaTerms || M < 3))
    throw std::invalid_argument("linear model: inertia needs 19 values and joints 1-3 predicted");
  if (q.gravity_direction.size() != 0 && q.gravity_direction.size() != 3)
    throw std::invalid_argument("linear model: gravity_direction needs 3 values");
  if (q.coulomb_slow.size() != q.sqrt_viscous.size() || (q.coulomb_slow.size() != 0 && q.coulomb_slow.size() != M))
    throw std::invalid_argument("linear model: coulomb_slow and sqrt_viscous need one value per output joint, or none");
  has_extra_friction_ = q.coulomb_slow.size() == M;
  if (has_extra_friction_ && q.dahl_displacement_slow.size() == 0) q.dahl_displacement_slow = kSlowDahlFactor * q.dahl_displacement;
  if (q.dahl_displacement_slow.size() != (has_extra_friction_ ? M : 0))
    throw std::invalid_argument("linear model: dahl_displacement_slow needs one value per output joint, with coulomb_slow");
  if (!(q.dahl_displacement_slow.array() > 0).all())
    throw std::invalid_argument("linear model: dahl_displacement_slow must be positive");
  if (q.friction_speed_limit.size() != 0 &&
      (q.friction_speed_limit.size() != M || !(q.friction_speed_limit.array() >= 0).all() ||
       !q.friction_speed_limit.allFinite()))
    throw std::invalid_argument("linear model: friction_speed_limit needs one finite value >= 0 per output joint, or none");
  if (q.stiffness.size() != 0 && (q.stiffness.size() != M || !q.stiffness.allFinite()))
    throw std::invalid_argument("linear model: stiffness needs one finite value per output joint, or none");
  if (q.coulomb_profile.size() != 0 || q.coulomb_profile_range.size() != 0) {
    if (q.coulomb_profile.rows() != M || q.coulomb_profile.cols() < 2 || q.coulomb_profile_range.rows() != M ||
        q.coulomb_profile_range.cols() != 2)
      throw std::invalid_argument(
          "linear model: coulomb_profile needs M x K values (K >= 2) and coulomb_profile_range M x 2, or neither");
    if (!q.coulomb_profile.allFinite() ||
        !(q.coulomb_profile_range.col(1).array() > q.coulomb_profile_range.col(0).array()).all())
      throw std::invalid_argument("linear model: coulomb_profile must be finite over ranges with lo < hi");
  }
  const bool travel = q.travel_range.size() || q.travel_torque.size() || q.travel_hysteresis_displacement.size() ||
                      q.travel_hysteresis.size();
  if (travel) {
    const Eigen::Index H = q.travel_hysteresis_displacement.cols();
    if (q.travel_range.rows() != M || q.travel_range.cols() != 2 || q.travel_torque.rows() != M ||
        q.travel_torque.cols() < 2 || q.travel_hysteresis_displacement.rows() != M || H < 1 ||
        q.travel_hysteresis.rows() != M || q.travel_hysteresis.cols() % H != 0 || q.travel_hysteresis.cols() / H < 2)
      throw std::invalid_argument(
          "linear model: the travel terms need travel_range M x 2, travel_torque M x Kt (Kt >= 2), "
          "travel_hysteresis_displacement M x H (H >= 1) and travel_hysteresis M x H Kh (Kh >= 2), or none");
    if (!(q.travel_range.col(1).array() > q.travel_range.col(0).array()).all() || !q.travel_torque.allFinite() ||
        !q.travel_hysteresis.allFinite() || !(q.travel_hysteresis_displacement.array() > 0).all() ||
        !q.travel_hysteresis_displacement.allFinite())
      throw std::invalid_argument(
          "linear model: the travel terms must be finite, over ranges with lo < hi, with positive displacements");
    travel_coefficients_.resize(M, q.travel_torque.cols() + q.travel_hysteresis.cols());
    travel_coefficients_ << q.travel_torque, q.travel_hysteresis;
    for (int j = 0; j < M; ++j) has_travel_.push_back((travel_coefficients_.row(j).array() != 0).any());
  }
  if (!(q.acceleration_window_s.array() >= 0).all() || !(q.acceleration_filter_s.array() >= 0).all() ||
      !(q.batch_acceleration_window_s.array() >= 0).all())
    throw std::invalid_argument("linear model: the acceleration windows and filters must be >= 0");
  if (q.batch_acceleration_degree != 2 && q.batch_acceleration_degree != 3)
    throw std::invalid_argument("linear model: batch_acceleration_degree must be 2 or 3");
  const double half_window = 0.5 * q.batch_acceleration_window_s.maxCoeff();
  if (q.live_zero_phase && !(half_window <= 0.5 * kMaxLiveZeroPhaseWindow))
    throw std::invalid_argument("linear model: live_zero_phase needs zero-phase windows of at most 4 s");
  const double period = TorqueModel::info().sample_period_s;
  if (q.live_zero_phase && half_window > 0 && period > 0)
    live_delay_samples_ =
        static_cast<int>(std::ceil((half_window + 0.5 * kSlowestStreamPeriod) / period * (1.0 - 1e-12)));
}

std::unique_ptr<TorqueModelWorkspace> LinearTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LinearWorkspace>();
  const int M = num_outputs();
  ws->prev_q = Eigen::VectorXd::Zero(M);
  ws->z = Eigen::VectorXd::Zero(M);
  ws->acceleration = Eigen::VectorXd::Zero(M);
  ws->z_slow = Eigen::VectorXd::Zero(M);
  ws->z_travel = Eigen::MatrixXd::Zero(M, parameters_.travel_hysteresis_displacement.cols());
  ws->travel_row = Eigen::VectorXd::Zero(travel_coefficients_.cols());
  ws->dahl_clock = DahlClock(info().sample_period_s);
  ws->qdd.reserve(M);
  for (int j = 0; j < M; ++j)
    ws->qdd.emplace_back(parameters_.acceleration_window_s[j], parameters_.acceleration_filter_s[j],
                         info().sample_period_s);
  ws->delayed_tau = Eigen::VectorXd::Zero(M);
  if (live_delay_samples_ > 0) {
    const double span = get_output_delay_s() + 0.5 * parameters_.batch_acceleration_window_s.maxCoeff();
    const double period = std::min(info().sample_period_s, detail::kFastestSamplePeriod);
    ws->capacity = static_cast<std::int64_t>(std::min(std::ceil(span / period) + 4.0, kMaxRingSamples));
    ws->ring.assign(static_cast<std::size_t>(ws->capacity * (1 + 2 * num_joints())), 0.0);
    // A call runs at most the ring's samples and the new one.
    ws->run_time.assign(static_cast<std::size_t>(ws->capacity + 1), 0.0);
    ws->run_tau.assign(static_cast<std::size_t>((ws->capacity + 1) * M), 0.0);
    for (int j = 0; j < M; ++j)
      ws->zero_phase.emplace_back(parameters_.batch_acceleration_window_s[j], parameters_.batch_acceleration_degree);
  }
  return ws;
}

void LinearTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LinearWorkspace&>(workspace);
  ws.z.setZero();
  ws.z_slow.setZero();
  ws.z_travel.setZero();
  for (auto& e : ws.qdd) e.reset();
  ws.dahl_clock.reset();
  ws.has_previous = false;
  ws.pushed = ws.done = 0;
  ws.back = 1;
  for (auto& z : ws.zero_phase) z.reset();
  ws.delayed_tau.setZero();
  ws.run_count = 0;
}

TorqueModel::StepRuns LinearTorqueModel::get_step_runs(const TorqueModelWorkspace& workspace) const {
  if (live_delay_samples_ == 0) return {};
  const auto& ws = static_cast<const LinearWorkspace&>(workspace);
  return {ws.run_count, ws.run_time.data(), ws.run_tau.data()};
}

void LinearTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                     double* tau) const {
  if (live_delay_samples_ > 0)
    compute_delayed_step(workspace, t, q, qd, tau);
  else
    compute_step_with_acceleration(workspace, t, q, qd, nullptr, tau);
}

void LinearTorqueModel::compute_step_with_acceleration(TorqueModelWorkspace& workspace, double t, const double* q,
                                                       const double* qd, const double* qdd_batch,
                                                       double* tau) const {
  auto& ws = static_cast<LinearWorkspace&>(workspace);
  for (int j = 0; j < num_outputs(); ++j) {
    ws.acceleration[j] = ws.qdd[j].update(t, qd[j]);
    if (qdd_batch && parameters_.batch_acceleration_window_s[j] > 0) ws.acceleration[j] = qdd_batch[j];
  }
  compute_torque(workspace, t, q, qd, tau);
}

void LinearTorqueModel::compute_delayed_step(TorqueModelWorkspace& workspace, double t, const double* q,
                                             const double* qd, double* tau) const {
  auto& ws = static_cast<LinearWorkspace&>(workspace);
  const auto& p = parameters_;
  // Rows hold every joint read: the regressors read q and qd of joints 1-3.
  const int M = num_outputs(), N = num_joints();
  const std::int64_t stride = 1 + 2 * N, cap = ws.capacity;
  auto row = [&](std::int64_t c) { return ws.ring.data() + (c % cap) * stride; };
  // Runs the samples not yet run up to sample `last`, each with the samples
  // within its half windows (those the stream has: cut at its ends).
  auto run_up_to = [&](std::int64_t last) {
    const std::int64_t oldest = std::max<std::int64_t>(0, ws.pushed - cap);
    for (std::int64_t c = std::max(ws.done, oldest); c <= last; ++c) {
      const double* r = row(c);
      const double t_c = r[0];
      for (int j = 0; j < M; ++j) {
        const double h = 0.5 * p.batch_acceleration_window_s[j];
        if (!(h > 0)) {
          ws.acceleration[j] = ws.qdd[j].update(t_c, r[1 + N + j]);
          continue;
        }
        ws.acceleration[j] = ws.zero_phase[static_cast<std::size_t>(j)].compute(
            c, oldest, ws.pushed, [&](std::int64_t k) { return row(k)[0]; },
            [&](std::int64_t k) { return row(k)[1 + N + j]; });
      }
      compute_torque(workspace, t_c, r + 1, r + 1 + N, ws.delayed_tau.data());
      ws.done = c + 1;
      if (ws.run_count < static_cast<int>(ws.run_time.size())) {
        ws.run_time[static_cast<std::size_t>(ws.run_count)] = t_c;
        std::copy(ws.delayed_tau.data(), ws.delayed_tau.data() + M,
                  ws.run_tau.data() + static_cast<std::ptrdiff_t>(ws.run_count) * M);
        ++ws.run_count;
      }
    }
  };
  ws.run_count = 0;
  // As the causal estimate: a repeated stamp is the same sample; an earlier one
  // ends the stream (its last samples run with their windows cut, as at the end
  // of a recording) and starts another, the friction states carried on.
  if (ws.pushed > 0 && t < row(ws.pushed - 1)[0]) {
    run_up_to(ws.pushed - 1);
    ws.pushed = ws.done = 0;
    ws.back = 1;
    for (auto& e : ws.qdd) e.reset();
    for (auto& z : ws.zero_phase) z.reset();
  }
  if (ws.pushed == 0 || t > row(ws.pushed - 1)[0]) {
    double* r = row(ws.pushed);
    r[0] = t;
    std::copy(q, q + N, r + 1);
    std::copy(qd, qd + N, r + 1 + N);
    ++ws.pushed;
    ++ws.back;  // the last pick is one sample further back
  }
  const int back = find_delayed_sample(static_cast<int>(std::min(ws.pushed, cap)), t - get_output_delay_s(),
                                       [&](int b) { return row(ws.pushed - b)[0]; }, ws.back);
  if (back > 0) {
    ws.back = back;
    run_up_to(ws.pushed - back);
  }
  std::copy(ws.delayed_tau.data(), ws.delayed_tau.data() + M, tau);
}

void LinearTorqueModel::compute_torque(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                       double* tau) const {
  auto& ws = static_cast<LinearWorkspace&>(workspace);
  const auto& p = parameters_;
  compute_gravity_regressor(q, ws.Y);
  const bool dahl_step = ws.dahl_clock.tick(t);
  for (int j = 0; j < num_outputs(); ++j) {
    if (ws.has_previous && dahl_step) {
      ws.z[j] = compute_dahl_state(ws.z[j], q[j] - ws.prev_q[j], p.dahl_displacement[j]);
      if (has_extra_friction_)
        ws.z_slow[j] = compute_dahl_state(ws.z_slow[j], q[j] - ws.prev_q[j], p.dahl_displacement_slow[j]);
    }
    const double qdd = ws.acceleration[j];
    const double v = p.friction_speed_limit.size() && p.friction_speed_limit[j] > 0
                         ? std::clamp(qd[j], -p.friction_speed_limit[j], p.friction_speed_limit[j])
                         : qd[j];
    double value =
        p.armature[j] * qdd + p.viscous[j] * v + get_coulomb_level(j, q[j]) * ws.z[j] + p.offset[j];
    if (j < 3) value += ws.Y.row(j).dot(p.gravity);
    if (has_extra_friction_) value += p.coulomb_slow[j] * ws.z_slow[j] + p.sqrt_viscous[j] * compute_sqrt_velocity(v);
    if (p.stiffness.size()) value += p.stiffness[j] * q[j];
    if (!has_travel_.empty() && has_travel_[static_cast<std::size_t>(j)]) {
      const Eigen::Index H = p.travel_hysteresis_displacement.cols();
      for (Eigen::Index h = 0; h < H && ws.has_previous && dahl_step; ++h)
        ws.z_travel(j, h) =
            compute_dahl_state(ws.z_travel(j, h), q[j] - ws.prev_q[j], p.travel_hysteresis_displacement(j, h));
      compute_travel_regressor(q[j], p.travel_range(j, 0), p.travel_range(j, 1), ws.z_travel.row(j).data(),
                               static_cast<int>(H),
                               static_cast<int>(p.travel_torque.cols()),
                               static_cast<int>(p.travel_hysteresis.cols() / H), ws.travel_row.data());
      value += travel_coefficients_.row(j).dot(ws.travel_row.transpose());
    }
    tau[j] = value;
    if (dahl_step) ws.prev_q[j] = q[j];
  }
  if (p.inertia.size() == kInertiaTerms) {
    compute_inertia_regressor(q, qd, ws.acceleration.data(), ws.Y_inertia);
    for (int j = 0; j < 3; ++j) tau[j] += ws.Y_inertia.row(j).dot(p.inertia);
  }
  ws.has_previous = true;
}

double LinearTorqueModel::get_coulomb_level(int j, double q) const {
  const auto& p = parameters_;
  if (!p.coulomb_profile.size()) return p.coulomb[j];
  int k;
  double w;
  compute_knot_weights(q, p.coulomb_profile_range(j, 0), p.coulomb_profile_range(j, 1),
                       static_cast<int>(p.coulomb_profile.cols()), k, w);
  return p.coulomb[j] + ((1.0 - w) * p.coulomb_profile(j, k) + w * p.coulomb_profile(j, k + 1));
}

// The whole-recording prediction with the zero-phase qddot, a sample as soon
// as its window is complete: the samples from the oldest any window still
// reaches to the newest are kept, with the windows' running sums
// (detail::ZeroPhaseSlope) exactly as over the whole recording.
class LinearSequencePredictor final : public TorqueSequencePredictor {
 public:
  explicit LinearSequencePredictor(const LinearTorqueModel& model)
      : model_(model),
        ws_(model.create_workspace()),
        N_(model.num_joints()),
        M_(model.num_outputs()),
        half_(static_cast<std::size_t>(M_), 0.0),
        q_(N_),
        qd_(N_),
        qdd_(Eigen::VectorXd::Zero(M_)),
        tau_(M_) {
    const auto& p = model.parameters();
    for (int j = 0; j < M_; ++j) {
      slopes_.emplace_back(p.batch_acceleration_window_s[j], p.batch_acceleration_degree);
      half_[static_cast<std::size_t>(j)] = 0.5 * p.batch_acceleration_window_s[j];
    }
  }

  void add(const Eigen::VectorXd& time, const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity,
           Eigen::MatrixXd& out) override {
    for (Eigen::Index i = 0; i < time.size(); ++i) {
      times_.push_back(time(i));
      for (int j = 0; j < N_; ++j) samples_.push_back(position(i, j));
      for (int j = 0; j < N_; ++j) samples_.push_back(velocity(i, j));
    }
    count_ += static_cast<std::size_t>(time.size());
    compute_ready(false, out);
  }
  void finish(Eigen::MatrixXd& out) override { compute_ready(true, out); }

 private:
  double time_at(Eigen::Index k) const { return times_[static_cast<std::size_t>(k) - base_]; }
  double value_at(Eigen::Index k, int i) const {
    return samples_[(static_cast<std::size_t>(k) - base_) * static_cast<std::size_t>(2 * N_) +
                    static_cast<std::size_t>(i)];
  }

  void compute_ready(bool ended, Eigen::MatrixXd& out) {
    rows_.clear();
    const auto end = static_cast<Eigen::Index>(count_);
    while (next_ < count_) {
      const auto c = static_cast<Eigen::Index>(next_);
      const double t_c = time_at(c);
      // Every window of sample c complete: a sample beyond its upper edge, or the end.
      bool complete = true;
      for (int j = 0; j < M_ && !ended; ++j)
        if (half_[static_cast<std::size_t>(j)] > 0 &&
            !(time_at(end - 1) > t_c + half_[static_cast<std::size_t>(j)] * (1.0 + detail::kWindowSlack)))
          complete = false;
      if (!complete) break;
      const auto begin = static_cast<Eigen::Index>(base_);
      for (int j = 0; j < M_; ++j)
        if (half_[static_cast<std::size_t>(j)] > 0)
          qdd_[j] = slopes_[static_cast<std::size_t>(j)].compute(
              c, begin, end, [&](Eigen::Index k) { return time_at(k); },
              [&](Eigen::Index k) { return value_at(k, N_ + j); });
      for (int j = 0; j < N_; ++j) {
        q_[j] = value_at(c, j);
        qd_[j] = value_at(c, N_ + j);
      }
      model_.compute_step_with_acceleration(*ws_, t_c, q_.data(), qd_.data(), qdd_.data(), tau_.data());
      rows_.insert(rows_.end(), tau_.data(), tau_.data() + M_);
      ++next_;
      // The samples below the lowest window edge of sample c are not reached again.
      double lowest = t_c;
      for (int j = 0; j < M_; ++j) lowest = std::min(lowest, t_c - half_[static_cast<std::size_t>(j)] * (1.0 + detail::kWindowSlack));
      while (base_ < next_ - 1 && times_.front() < lowest) {
        times_.pop_front();
        samples_.erase(samples_.begin(), samples_.begin() + 2 * N_);
        ++base_;
      }
    }
    out.resize(static_cast<Eigen::Index>(rows_.size() / static_cast<std::size_t>(M_)), M_);
    for (Eigen::Index r = 0; r < out.rows(); ++r)
      for (int j = 0; j < M_; ++j) out(r, j) = rows_[static_cast<std::size_t>(r * M_ + j)];
  }

  const LinearTorqueModel& model_;
  std::unique_ptr<TorqueModelWorkspace> ws_;
  int N_, M_;
  std::vector<detail::ZeroPhaseSlope> slopes_;
  std::vector<double> half_;
  Eigen::VectorXd q_, qd_, qdd_, tau_;
  std::deque<double> times_, samples_;  // samples base_, base_ + 1, ...: time; q and qd (N each)
  std::size_t base_ = 0, count_ = 0, next_ = 0;
  std::vector<double> rows_;
};

std::unique_ptr<TorqueSequencePredictor> LinearTorqueModel::create_sequence_predictor() const {
  if (!(parameters_.batch_acceleration_window_s.array() > 0).any()) return TorqueModel::create_sequence_predictor();
  return std::make_unique<LinearSequencePredictor>(*this);
}

Eigen::MatrixXd LinearTorqueModel::predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                                    const Eigen::MatrixXd& velocity) const {
  // Time that goes back (a caller's concatenation) has no zero-phase window: the causal estimate.
  if (!is_time_sorted(time)) return TorqueModel::predict_sequence(time, position, velocity);
  const auto predictor = create_sequence_predictor();
  Eigen::MatrixXd head, tail;
  predictor->add(time, position, velocity, head);
  predictor->finish(tail);
  Eigen::MatrixXd out(head.rows() + tail.rows(), num_outputs());
  out << head, tail;
  return out;
}

nlohmann::json LinearTorqueModel::save_parameters() const {
  const auto& p = parameters_;
  nlohmann::json j = {{"gravity", detail::encode_vector(p.gravity)},
          {"armature", detail::encode_vector(p.armature)},
          {"viscous", detail::encode_vector(p.viscous)},
          {"coulomb", detail::encode_vector(p.coulomb)},
          {"offset", detail::encode_vector(p.offset)},
          {"dahl_displacement", detail::encode_vector(p.dahl_displacement)},
          {"acceleration_window_s", detail::encode_vector(p.acceleration_window_s)},
          {"acceleration_filter_s", detail::encode_vector(p.acceleration_filter_s)},
          {"batch_acceleration_window_s", detail::encode_vector(p.batch_acceleration_window_s)},
          {"batch_acceleration_degree", p.batch_acceleration_degree}};
  if (p.inertia.size()) j["inertia"] = detail::encode_vector(p.inertia);
  if (p.gravity_direction.size()) j["gravity_direction"] = detail::encode_vector(p.gravity_direction);
  if (p.coulomb_slow.size()) j["coulomb_slow"] = detail::encode_vector(p.coulomb_slow);
  if (p.sqrt_viscous.size()) j["sqrt_viscous"] = detail::encode_vector(p.sqrt_viscous);
  if (p.dahl_displacement_slow.size()) j["dahl_displacement_slow"] = detail::encode_vector(p.dahl_displacement_slow);
  if (p.friction_speed_limit.size()) j["friction_speed_limit"] = detail::encode_vector(p.friction_speed_limit);
  if (p.coulomb_profile.size()) {
    j["coulomb_profile"] = detail::encode_array(p.coulomb_profile);
    j["coulomb_profile_range"] = detail::encode_array(p.coulomb_profile_range);
  }
  if (p.stiffness.size()) j["stiffness"] = detail::encode_vector(p.stiffness);
  if (p.travel_range.size()) {
    j["travel_range"] = detail::encode_array(p.travel_range);
    j["travel_torque"] = detail::encode_array(p.travel_torque);
    j["travel_hysteresis_displacement"] = detail::encode_array(p.travel_hysteresis_displacement);
    j["travel_hysteresis"] = detail::encode_array(p.travel_hysteresis);
  }
  if (p.live_zero_phase) j["live_zero_phase"] = true;
  return j;
}

std::unique_ptr<TorqueModel> detail::load_linear_parameters(TorqueModelInfo info, const nlohmann::json& j,
                                                            const std::string& source) {
  const int M = info.num_outputs;
  const std::string f = "parameters";
  LinearTorqueParameters p;
  p.gravity = decode_vector_d(require(j, "gravity", source, f), source, f + ".gravity", G);
  p.armature = decode_vector_d(require(j, "armature", source, f), source, f + ".armature", M);
  p.viscous = decode_vector_d(require(j, "viscous", source, f), source, f + ".viscous", M);
  p.coulomb = decode_vector_d(require(j, "coulomb", source, f), source, f + ".coulomb", M);
  p.offset = decode_vector_d(require(j, "offset", source, f), source, f + ".offset", M);
  p.dahl_displacement =
      decode_vector_d(require(j, "dahl_displacement", source, f), source, f + ".dahl_displacement", M);
  if ((p.dahl_displacement.array() <= 0).any()) fail(source, f + ".dahl_displacement", "expected positive values");
  // Files written before the qddot estimate was chosen per joint hold one number
  // for the low-pass and no windows (backward difference, causal batch).
  const auto& tau = require(j, "acceleration_filter_s", source, f);
  if (tau.is_number()) {
    if (!(tau.get<double>() >= 0)) fail(source, f + ".acceleration_filter_s", "expected a number >= 0");
    p.acceleration_filter_s = Eigen::VectorXd::Constant(M, tau.get<double>());
  } else {
    p.acceleration_filter_s = decode_vector_d(tau, source, f + ".acceleration_filter_s", M);
  }
  if (j.contains("acceleration_window_s"))
    p.acceleration_window_s = decode_vector_d(j["acceleration_window_s"], source, f + ".acceleration_window_s", M);
  else
    p.acceleration_window_s = Eigen::VectorXd::Constant(M, kDefaultAccelerationWindow);
  if (j.contains("batch_acceleration_window_s"))
    p.batch_acceleration_window_s =
        decode_vector_d(j["batch_acceleration_window_s"], source, f + ".batch_acceleration_window_s", M);
  else
    p.batch_acceleration_window_s = Eigen::VectorXd::Zero(M);
  if (!(p.batch_acceleration_window_s.array() >= 0).all())
    fail(source, f + ".batch_acceleration_window_s", "expected values >= 0");
  // Files without the degree were fitted on the quadratic's slope.
  p.batch_acceleration_degree = 2;
  if (j.contains("batch_acceleration_degree")) {
    const auto& d = j["batch_acceleration_degree"];
    if (!d.is_number_integer() || (d.get<std::int64_t>() != 2 && d.get<std::int64_t>() != 3))
      fail(source, f + ".batch_acceleration_degree", "expected 2 or 3");
    p.batch_acceleration_degree = static_cast<int>(d.get<std::int64_t>());
  }
  if (j.contains("inertia")) {
    if (M < 3) fail(source, f + ".inertia", "needs joints 1-3 predicted");
    p.inertia = decode_vector_d(j["inertia"], source, f + ".inertia", kInertiaTerms);
  }
  if (j.contains("gravity_direction"))
    p.gravity_direction = decode_vector_d(j["gravity_direction"], source, f + ".gravity_direction", 3);
  if (j.contains("coulomb_slow") != j.contains("sqrt_viscous"))
    fail(source, f + (j.contains("coulomb_slow") ? ".sqrt_viscous" : ".coulomb_slow"), "missing (the two come together)");
  if (j.contains("coulomb_slow")) {
    p.coulomb_slow = decode_vector_d(j["coulomb_slow"], source, f + ".coulomb_slow", M);
    p.sqrt_viscous = decode_vector_d(j["sqrt_viscous"], source, f + ".sqrt_viscous", M);
    if (j.contains("dahl_displacement_slow")) {
      p.dahl_displacement_slow = decode_vector_d(j["dahl_displacement_slow"], source, f + ".dahl_displacement_slow", M);
      if (!(p.dahl_displacement_slow.array() > 0).all())
        fail(source, f + ".dahl_displacement_slow", "must be positive");
    }
  } else if (j.contains("dahl_displacement_slow")) {
    fail(source, f + ".dahl_displacement_slow", "needs coulomb_slow and sqrt_viscous");
  }
  if (j.contains("friction_speed_limit")) {
    p.friction_speed_limit = decode_vector_d(j["friction_speed_limit"], source, f + ".friction_speed_limit", M);
    if (!(p.friction_speed_limit.array() >= 0).all() || !p.friction_speed_limit.allFinite())
      fail(source, f + ".friction_speed_limit", "must be finite and >= 0 (0: no limit)");
  }
  if (j.contains("coulomb_profile") != j.contains("coulomb_profile_range"))
    fail(source, f + (j.contains("coulomb_profile") ? ".coulomb_profile_range" : ".coulomb_profile"),
         "missing (the two come together)");
  if (j.contains("coulomb_profile")) {
    p.coulomb_profile = decode_array_d(j["coulomb_profile"], source, f + ".coulomb_profile");
    p.coulomb_profile_range = decode_array_d(j["coulomb_profile_range"], source, f + ".coulomb_profile_range");
    if (p.coulomb_profile.rows() != M || p.coulomb_profile.cols() < 2)
      fail(source, f + ".coulomb_profile", fmt::format("expected {} rows of at least 2 values", M));
    if (p.coulomb_profile_range.rows() != M || p.coulomb_profile_range.cols() != 2)
      fail(source, f + ".coulomb_profile_range", fmt::format("expected {} rows of 2 values", M));
    if (!(p.coulomb_profile_range.col(1).array() > p.coulomb_profile_range.col(0).array()).all())
      fail(source, f + ".coulomb_profile_range", "expected lo < hi on every row");
  }
  if (j.contains("stiffness")) p.stiffness = decode_vector_d(j["stiffness"], source, f + ".stiffness", M);
  {
    // The travel terms: the four fields together or none.
    const char* fields[] = {"travel_range", "travel_torque", "travel_hysteresis_displacement", "travel_hysteresis"};
    int present = 0;
    for (const char* name : fields) present += j.contains(name) ? 1 : 0;
    if (present != 0 && present != 4)
      for (const char* name : fields)
        if (!j.contains(name)) fail(source, f + "." + name, "missing (the four travel fields come together)");
    if (present == 4) {
      p.travel_range = decode_array_d(j["travel_range"], source, f + ".travel_range");
      p.travel_torque = decode_array_d(j["travel_torque"], source, f + ".travel_torque");
      p.travel_hysteresis_displacement =
          decode_array_d(j["travel_hysteresis_displacement"], source, f + ".travel_hysteresis_displacement");
      p.travel_hysteresis = decode_array_d(j["travel_hysteresis"], source, f + ".travel_hysteresis");
      const Eigen::Index H = p.travel_hysteresis_displacement.cols();
      if (p.travel_range.rows() != M || p.travel_range.cols() != 2)
        fail(source, f + ".travel_range", fmt::format("expected {} rows of 2 values", M));
      if (!(p.travel_range.col(1).array() > p.travel_range.col(0).array()).all())
        fail(source, f + ".travel_range", "expected lo < hi on every row");
      if (p.travel_torque.rows() != M || p.travel_torque.cols() < 2)
        fail(source, f + ".travel_torque", fmt::format("expected {} rows of at least 2 values", M));
      if (p.travel_hysteresis_displacement.rows() != M || H < 1)
        fail(source, f + ".travel_hysteresis_displacement", fmt::format("expected {} rows of at least 1 value", M));
      if (!(p.travel_hysteresis_displacement.array() > 0).all() || !p.travel_hysteresis_displacement.allFinite())
        fail(source, f + ".travel_hysteresis_displacement", "expected finite positive values");
      if (p.travel_hysteresis.rows() != M || p.travel_hysteresis.cols() % H != 0 || p.travel_hysteresis.cols() / H < 2)
        fail(source, f + ".travel_hysteresis",
             fmt::format("expected {} rows of H x Kh values, H = {} (travel_hysteresis_displacement), Kh >= 2", M, H));
      if (!p.travel_torque.allFinite()) fail(source, f + ".travel_torque", "expected finite values");
      if (!p.travel_hysteresis.allFinite()) fail(source, f + ".travel_hysteresis", "expected finite values");
    }
  }
  if (j.contains("live_zero_phase")) {
    if (!j["live_zero_phase"].is_boolean()) fail(source, f + ".live_zero_phase", "expected true or false");
    p.live_zero_phase = j["live_zero_phase"].get<bool>();
    if (p.live_zero_phase && !(p.batch_acceleration_window_s.maxCoeff() <= kMaxLiveZeroPhaseWindow))
      fail(source, f + ".live_zero_phase",
           fmt::format("the zero-phase windows run live must be at most {} s (batch_acceleration_window_s)",
                       kMaxLiveZeroPhaseWindow));
  }
  if (!(p.acceleration_filter_s.array() >= 0).all())
    fail(source, f + ".acceleration_filter_s", "expected values >= 0");
  if (!(p.acceleration_window_s.array() >= 0).all())
    fail(source, f + ".acceleration_window_s", "expected values >= 0");
  if (info.num_joints < 3) fail(source, "num_joints", "the linear model needs at least 3 joints");
  return std::make_unique<LinearTorqueModel>(std::move(info), std::move(p));
}

}  // namespace rcm::dynamics
