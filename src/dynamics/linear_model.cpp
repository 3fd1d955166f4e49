#include "rcm/dynamics/linear_model.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <stdexcept>

#include "model_io.hpp"

namespace rcm::dynamics {

namespace {

constexpr int G = LinearTorqueModel::kGravityTerms;
constexpr int kBlock = 4;  // armature, viscous, coulomb, offset
// Time constant of the acceleration low-pass used for fitting. 30 ms minimized
// the error of the filtered qddot against the true one on the simulated bench
// (0.45 -> 0.15 rad/s^2 RMS for the yaw joint at 200 Hz).
constexpr double kAccelerationFilter = 0.03;

// Exact discretization of the rate-independent Dahl state over a displacement dq.
inline double advance_dahl(double z, double dq, double x_c) {
  if (dq == 0.0) return z;
  const double s = dq > 0 ? 1.0 : -1.0;
  return s + (z - s) * std::exp(-std::abs(dq) / x_c);
}

// qddot from differentiated velocity is mostly noise at 200 Hz (the velocity is
// itself a filtered difference of quantized encoders); a first-order causal
// low-pass with time constant tau trades that noise for a little lag.
inline double filter_acceleration(double filtered, double raw, double dt, double tau) {
  return filtered + dt / (tau + dt) * (raw - filtered);
}

struct LinearWorkspace final : TorqueModelWorkspace {
  Eigen::VectorXd prev_q, prev_qd, z, qdd;
  double prev_t = 0.0;
  bool has_previous = false;
  Eigen::Matrix<double, 3, G> Y;
};

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
  if (parameters_.gravity.size() != G || parameters_.armature.size() != M || parameters_.viscous.size() != M ||
      parameters_.coulomb.size() != M || parameters_.offset.size() != M || parameters_.dahl_displacement.size() != M)
    throw std::invalid_argument("linear model: parameter sizes do not match num_outputs");
  if ((parameters_.dahl_displacement.array() <= 0).any())
    throw std::invalid_argument("linear model: dahl_displacement must be positive");
}

std::unique_ptr<TorqueModelWorkspace> LinearTorqueModel::create_workspace() const {
  auto ws = std::make_unique<LinearWorkspace>();
  ws->prev_q = Eigen::VectorXd::Zero(num_outputs());
  ws->prev_qd = Eigen::VectorXd::Zero(num_outputs());
  ws->z = Eigen::VectorXd::Zero(num_outputs());
  ws->qdd = Eigen::VectorXd::Zero(num_outputs());
  return ws;
}

void LinearTorqueModel::reset_state(TorqueModelWorkspace& workspace) const {
  auto& ws = static_cast<LinearWorkspace&>(workspace);
  ws.z.setZero();
  ws.qdd.setZero();
  ws.has_previous = false;
}

void LinearTorqueModel::compute_step(TorqueModelWorkspace& workspace, double t, const double* q, const double* qd,
                                     double* tau) const {
  auto& ws = static_cast<LinearWorkspace&>(workspace);
  const auto& p = parameters_;
  compute_gravity_regressor(q, ws.Y);
  const double dt = ws.has_previous ? t - ws.prev_t : 0.0;
  for (int j = 0; j < num_outputs(); ++j) {
    if (ws.has_previous) {
      ws.z[j] = advance_dahl(ws.z[j], q[j] - ws.prev_q[j], p.dahl_displacement[j]);
      if (dt > 0) ws.qdd[j] = filter_acceleration(ws.qdd[j], (qd[j] - ws.prev_qd[j]) / dt, dt, p.acceleration_filter_s);
    }
    double value = p.armature[j] * ws.qdd[j] + p.viscous[j] * qd[j] + p.coulomb[j] * ws.z[j] + p.offset[j];
    if (j < 3) value += ws.Y.row(j).dot(p.gravity);
    tau[j] = value;
    ws.prev_q[j] = q[j];
    ws.prev_qd[j] = qd[j];
  }
  ws.prev_t = t;
  ws.has_previous = true;
}

nlohmann::json LinearTorqueModel::save_parameters() const {
  const auto& p = parameters_;
  return {{"gravity", detail::encode_vector(p.gravity)},
          {"armature", detail::encode_vector(p.armature)},
          {"viscous", detail::encode_vector(p.viscous)},
          {"coulomb", detail::encode_vector(p.coulomb)},
          {"offset", detail::encode_vector(p.offset)},
          {"dahl_displacement", detail::encode_vector(p.dahl_displacement)},
          {"acceleration_filter_s", p.acceleration_filter_s}};
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
  const auto& tau = require(j, "acceleration_filter_s", source, f);
  if (!tau.is_number() || !(tau.get<double>() >= 0)) fail(source, f + ".acceleration_filter_s", "expected a number >= 0");
  p.acceleration_filter_s = tau.get<double>();
  if (info.num_joints < 3) fail(source, "num_joints", "the linear model needs at least 3 joints");
  return std::make_unique<LinearTorqueModel>(std::move(info), std::move(p));
}

// ---------------------------------------------------------------------------- fitting

namespace {

// Per joint and per Dahl candidate: Gram matrix of the joint's regressor
// [gravity (17, joints 1-3), qdd, v, z, 1] and its products with the torque, so
// that every candidate combination is scored without touching the samples again.
struct JointStats {
  Eigen::MatrixXd C;  // (G + 4)^2
  Eigen::VectorXd r;
  double yy = 0.0;
  JointStats& operator+=(const JointStats& o) {
    C += o.C;
    r += o.r;
    yy += o.yy;
    return *this;
  }
};

JointStats compute_stats(const std::vector<Recording>& recs, const std::vector<SampleSegment>& segments, int j,
                         double x_c, double weight, double tau_a) {
  const int P = G + kBlock;
  JointStats s{Eigen::MatrixXd::Zero(P, P), Eigen::VectorXd::Zero(P), 0.0};
  Eigen::Matrix<double, 3, G> Y;
  constexpr Eigen::Index kChunk = 4096;
  Eigen::MatrixXd F(kChunk, P);
  Eigen::VectorXd y(kChunk);
  for (const auto& seg : segments) {
    const auto& rec = recs[seg.recording];
    // The state needs the history from the recording's start.
    double z = 0.0, qdd = 0.0;
    for (Eigen::Index t = 1; t < seg.begin; ++t) {
      z = advance_dahl(z, rec.position(t, j) - rec.position(t - 1, j), x_c);
      const double dt = rec.time(t) - rec.time(t - 1);
      qdd = filter_acceleration(qdd, (rec.velocity(t, j) - rec.velocity(t - 1, j)) / dt, dt, tau_a);
    }
    Eigen::Index n = 0;
    auto flush = [&]() {
      s.C.noalias() += F.topRows(n).transpose() * F.topRows(n);
      s.r.noalias() += F.topRows(n).transpose() * y.head(n);
      s.yy += y.head(n).squaredNorm();
      n = 0;
    };
    for (Eigen::Index t = seg.begin; t < seg.end; ++t) {
      if (t > 0) {
        z = advance_dahl(z, rec.position(t, j) - rec.position(t - 1, j), x_c);
        const double dt = rec.time(t) - rec.time(t - 1);
        qdd = filter_acceleration(qdd, (rec.velocity(t, j) - rec.velocity(t - 1, j)) / dt, dt, tau_a);
      }
      if (j < 3) {
        double q3[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
        LinearTorqueModel::compute_gravity_regressor(q3, Y);
        F.row(n).head(G) = Y.row(j) * weight;
      } else {
        F.row(n).head(G).setZero();
      }
      F(n, G + 0) = qdd * weight;
      F(n, G + 1) = rec.velocity(t, j) * weight;
      F(n, G + 2) = z * weight;
      F(n, G + 3) = weight;
      y(n) = rec.effort(t, j) * weight;
      if (++n == kChunk) flush();
    }
    if (n) flush();
  }
  return s;
}

// Index of joint j's block parameter b in the global vector.
inline int block_index(int j, int b) { return G + kBlock * j + b; }

// Solves the ridge-stabilized normal equations with armature, viscous and Coulomb
// kept >= 0 by an active set.
Eigen::VectorXd solve_constrained(const std::vector<const JointStats*>& stats, int M) {
  const int P = G + kBlock * M;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(P, P);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(P);
  for (int j = 0; j < M; ++j) {
    const auto& s = *stats[j];
    std::vector<int> idx;
    for (int k = 0; k < G; ++k) idx.push_back(k);
    for (int k = 0; k < kBlock; ++k) idx.push_back(block_index(j, k));
    for (int u = 0; u < G + kBlock; ++u) {
      b(idx[u]) += s.r(u);
      for (int v = 0; v < G + kBlock; ++v) A(idx[u], idx[v]) += s.C(u, v);
    }
  }
  // Collinear columns (e.g. the q3 potential term and the insertion offset) make
  // A singular; a ridge relative to each diagonal picks the small-norm solution.
  const double floor = 1e-12 * std::max(1.0, A.diagonal().maxCoeff());
  for (int k = 0; k < P; ++k) A(k, k) += 1e-9 * A(k, k) + floor;
  std::vector<bool> fixed(P, false);
  Eigen::VectorXd theta;
  for (int iter = 0; iter <= 3 * M; ++iter) {
    Eigen::MatrixXd Af = A;
    Eigen::VectorXd bf = b;
    for (int k = 0; k < P; ++k)
      if (fixed[k]) {
        Af.row(k).setZero();
        Af.col(k).setZero();
        Af(k, k) = 1.0;
        bf(k) = 0.0;
      }
    theta = Af.ldlt().solve(bf);
    bool changed = false;
    for (int j = 0; j < M; ++j)
      for (int k = 0; k < 3; ++k) {  // armature, viscous, coulomb
        const int i = block_index(j, k);
        if (!fixed[i] && theta(i) < 0) {
          fixed[i] = true;
          changed = true;
        }
      }
    if (!changed) break;
  }
  return theta;
}

double objective(const std::vector<const JointStats*>& stats, const Eigen::VectorXd& theta, int M) {
  double e = 0.0;
  for (int j = 0; j < M; ++j) {
    Eigen::VectorXd th(G + kBlock);
    th << theta.head(G), theta.segment(block_index(j, 0), kBlock);
    const auto& s = *stats[j];
    e += s.yy - 2.0 * th.dot(s.r) + th.dot(s.C * th);
  }
  return e;
}

}  // namespace

FitResult fit_linear_torque_model(const std::vector<Recording>& recordings, const FitOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  options.check();
  check_fit_recordings(recordings);
  const int N = recordings.front().num_joints();
  const int M = resolve_num_outputs(recordings, options);
  const TimeSplit split = split_in_time(recordings, options.train_fraction, options.validation_fraction);
  if (split.train.empty() || split.validation.empty())
    throw std::invalid_argument("fit_linear_torque_model: empty training or validation split");

  FitSummary summary;
  summary.kind = TorqueModelKind::linear;
  for (const auto& s : split.train) summary.train_samples += s.size();
  for (const auto& s : split.validation) summary.validation_samples += s.size();
  for (const auto& s : split.test) summary.test_samples += s.size();

  // Each joint's rows are weighted by 1 / (std of its torque) so that N m and N
  // joints count alike; the grid of x_c follows each joint's range of motion.
  std::vector<double> weight(M), range(M);
  for (int j = 0; j < M; ++j) {
    double sum = 0, sum2 = 0, lo = std::numeric_limits<double>::infinity(), hi = -lo;
    double n = 0;
    for (const auto& seg : split.train) {
      const auto& rec = recordings[seg.recording];
      for (Eigen::Index t = seg.begin; t < seg.end; ++t) {
        sum += rec.effort(t, j);
        sum2 += rec.effort(t, j) * rec.effort(t, j);
        lo = std::min(lo, rec.position(t, j));
        hi = std::max(hi, rec.position(t, j));
        n += 1;
      }
    }
    const double var = std::max(sum2 / n - (sum / n) * (sum / n), 0.0);
    weight[j] = var > 0 ? 1.0 / std::sqrt(var) : 1.0;
    range[j] = std::max(hi - lo, 1e-6);
  }
  const std::vector<double> grid = {1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1};
  const int K = static_cast<int>(grid.size());
  std::vector<std::vector<JointStats>> train(M), val(M);
  for (int j = 0; j < M; ++j)
    for (int k = 0; k < K; ++k) {
      train[j].push_back(compute_stats(recordings, split.train, j, grid[k] * range[j], weight[j], kAccelerationFilter));
      val[j].push_back(compute_stats(recordings, split.validation, j, grid[k] * range[j], weight[j], kAccelerationFilter));
    }
  // Coordinate descent over each joint's x_c, scored on the validation split.
  std::vector<int> choice(M, 4);
  auto score = [&](const std::vector<int>& c) {
    std::vector<const JointStats*> tr(M), va(M);
    for (int j = 0; j < M; ++j) {
      tr[j] = &train[j][c[j]];
      va[j] = &val[j][c[j]];
    }
    return objective(va, solve_constrained(tr, M), M);
  };
  double best = score(choice);
  for (int sweep = 0; sweep < 2; ++sweep)
    for (int j = 0; j < M; ++j)
      for (int k = 0; k < K; ++k) {
        auto trial = choice;
        trial[j] = k;
        const double e = score(trial);
        if (e < best) {
          best = e;
          choice = trial;
        }
      }
  // Final coefficients from train + validation.
  std::vector<JointStats> both(M);
  std::vector<const JointStats*> ptr(M);
  for (int j = 0; j < M; ++j) {
    both[j] = train[j][choice[j]];
    both[j] += val[j][choice[j]];
    ptr[j] = &both[j];
  }
  const Eigen::VectorXd theta = solve_constrained(ptr, M);

  LinearTorqueParameters p;
  p.gravity = theta.head(G);
  p.armature.resize(M);
  p.viscous.resize(M);
  p.coulomb.resize(M);
  p.offset.resize(M);
  p.dahl_displacement.resize(M);
  for (int j = 0; j < M; ++j) {
    // Rows were scaled by weight[j] on both sides, so coefficients are in joint units.
    p.armature[j] = theta(block_index(j, 0));
    p.viscous[j] = theta(block_index(j, 1));
    p.coulomb[j] = theta(block_index(j, 2));
    p.offset[j] = theta(block_index(j, 3));
    p.dahl_displacement[j] = grid[choice[j]] * range[j];
  }
  p.acceleration_filter_s = kAccelerationFilter;
  summary.best_validation_loss = best / static_cast<double>(summary.validation_samples * M);

  // Too few data: fewer than 20 training rows per parameter, or a joint whose
  // velocity never changes sign (Coulomb and offset cannot be told apart).
  const std::size_t params = G + kBlock * M;
  if (summary.train_samples * M < 20 * params)
    summary.warnings.push_back(fmt::format(
        "data too few to trust: {} training samples for {} parameters (need >= 20 rows per parameter)",
        summary.train_samples, params));
  for (int j = 0; j < M; ++j) {
    bool pos = false, neg = false;
    for (const auto& seg : split.train)
      for (Eigen::Index t = seg.begin; t < seg.end; ++t) {
        const double v = recordings[seg.recording].velocity(t, j);
        pos |= v > 0;
        neg |= v < 0;
      }
    if (!(pos && neg))
      summary.warnings.push_back(fmt::format(
          "joint {} moves in one direction only in the training data: Coulomb friction and offset are confounded",
          j + 1));
  }

  TorqueModelInfo info;
  info.num_joints = N;
  info.num_outputs = M;
  info.sample_period_s = median_sample_period(recordings);
  auto model_for_test = std::make_unique<LinearTorqueModel>(info, p);
  if (!split.test.empty()) summary.test_errors = evaluate_on_segments(*model_for_test, recordings, split.test);
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  info.training = summary.to_json();
  if (options.verbose) std::cerr << summary.brief_report();
  FitResult result;
  result.model = std::make_unique<LinearTorqueModel>(std::move(info), std::move(p));
  result.summary = std::move(summary);
  return result;
}

}  // namespace rcm::dynamics
