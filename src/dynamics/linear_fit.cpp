// Fit of the model-based free-space model (linear_model.hpp): the candidate
// search over each joint's qddot estimate and Dahl displacement, then the
// rigid-body stage.
#include "rcm/dynamics/linear_model.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <bitset>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <memory>
#include <stdexcept>

#include "acceleration.hpp"
#include "rigid_body_fit.hpp"
#include "gravity_terms.hpp"
#include "rcm/dynamics/travel_terms.hpp"

namespace rcm::dynamics {

namespace {

using detail::AccelerationEstimator;
using detail::compute_zero_phase_acceleration;
using detail::is_time_sorted;
using detail::kDefaultAccelerationFilter;
using detail::G;
constexpr int kBlock = 4;  // armature, viscous, coulomb, offset
// The rigid-body structure is kept while its validation loss is within this
// factor of the generic one's (FitOptions::rigid_body): a time slice of the same
// motion favours the free potential, which generalises worse across speeds.
constexpr double kRigidBodyTolerance = 1.25;
// A joint's Coulomb profile (5 more parameters) is kept when it lowers that
// score by more than this fraction: a smaller gain is within what any 5 columns
// take from the noise of one path.
constexpr double kProfileGain = 0.01;
// Joints 1-3 of the structure are yaw, pitch and insertion.
constexpr int kPitchJoint = 1, kInsertionJoint = 2;
// The joints a fit may give travel terms: pitch. On the real PSM what the
// rigid-body model leaves on pitch has the same shape at the same point of a
// path at full and half speed (the residuals of fits on each run correlate
// row by row, 0.48), and the terms fitted at one speed lower the error at the
// other; on yaw and the insertion the residual does not carry across speed
// (0.09 and 0.16-0.19), and the same terms, though they fit a later slice of
// the same run better, raise the error from full to half speed (docs/methods.md).
constexpr unsigned kTravelJoints = 1u << kPitchJoint;

// Gram matrix of one joint's regressor [gravity (17, joints 1-3), qdd, v, z, 1]
// and its products with the torque, for one x_c and one qddot candidate.
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

// A candidate qddot estimate: window and low-pass time constant, s.
struct AccelerationChoice {
  double window_s, filter_s;
};

// One pass over a joint's samples with every candidate at once: the Gram matrix
// of [gravity, v, 1, qdd per causal qddot candidate, qdd per zero-phase window,
// z per x_c candidate] and its products with the torque, from which the
// statistics of any combination are read without touching the samples again.
// Acceleration column a < acc.size() is causal candidate a, the others are the
// zero-phase estimates batch[recording][a - acc.size()] of the joint.
class JointCandidateStats {
 public:
  JointCandidateStats(const std::vector<Recording>& recs, const std::vector<SampleSegment>& segments, int j,
                      const std::vector<double>& x_c, const std::vector<AccelerationChoice>& acc,
                      const std::vector<std::vector<Eigen::VectorXd>>& batch, double weight, double sample_period_s)
      : A_(static_cast<int>(acc.size() + (batch.empty() ? 0 : batch.front().size()))),
        K_(static_cast<int>(x_c.size())) {
    const int causal = static_cast<int>(acc.size());
    const int P = G + 2 + A_ + K_;
    C_ = Eigen::MatrixXd::Zero(P, P);
    r_ = Eigen::VectorXd::Zero(P);
    Eigen::Matrix<double, 3, G> Y;
    constexpr Eigen::Index kChunk = 4096;
    Eigen::MatrixXd F(kChunk, P);
    Eigen::VectorXd y(kChunk);
    std::vector<AccelerationEstimator> estimators;
    for (const auto& a : acc) estimators.emplace_back(a.window_s, a.filter_s, sample_period_s);
    Eigen::VectorXd z(K_);
    for (const auto& seg : segments) {
      const auto& rec = recs[seg.recording];
      // The states need the history from the recording's start; the estimators
      // and the Dahl states' clock are compute_step's, so that fit and
      // prediction agree.
      for (auto& e : estimators) e.reset();
      z.setZero();
      DahlClock dahl_clock(sample_period_s);
      Eigen::Index dahl_last = 0;  // the sample of the states' last step
      Eigen::Index n = 0;
      auto flush = [&]() {
        C_.noalias() += F.topRows(n).transpose() * F.topRows(n);
        r_.noalias() += F.topRows(n).transpose() * y.head(n);
        yy_ += y.head(n).squaredNorm();
        n = 0;
      };
      for (Eigen::Index t = 0; t < seg.end; ++t) {
        if (dahl_clock.tick(rec.time(t))) {
          if (t > 0)
            for (int k = 0; k < K_; ++k)
              z[k] = compute_dahl_state(z[k], rec.position(t, j) - rec.position(dahl_last, j), x_c[k]);
          dahl_last = t;
        }
        for (int a = 0; a < causal; ++a) estimators[a].update(rec.time(t), rec.velocity(t, j));
        if (t < seg.begin) continue;
        if (j < 3) {
          double q3[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
          LinearTorqueModel::compute_gravity_regressor(q3, Y);
          F.row(n).head(G) = Y.row(j) * weight;
        } else {
          F.row(n).head(G).setZero();
        }
        F(n, G + 0) = rec.velocity(t, j) * weight;
        F(n, G + 1) = weight;
        for (int a = 0; a < causal; ++a) F(n, G + 2 + a) = estimators[a].value() * weight;
        for (int a = causal; a < A_; ++a) F(n, G + 2 + a) = batch[seg.recording][a - causal](t) * weight;
        for (int k = 0; k < K_; ++k) F(n, G + 2 + A_ + k) = z[k] * weight;
        y(n) = rec.effort(t, j) * weight;
        if (++n == kChunk) flush();
      }
      if (n) flush();
    }
  }

  JointStats get_stats(int dahl, int acceleration) const {
    // Columns of the combination in JointStats order [gravity, qdd, v, z, 1].
    std::array<int, G + kBlock> idx;
    for (int k = 0; k < G; ++k) idx[k] = k;
    idx[G + 0] = G + 2 + acceleration;
    idx[G + 1] = G;
    idx[G + 2] = G + 2 + A_ + dahl;
    idx[G + 3] = G + 1;
    JointStats s{Eigen::MatrixXd(G + kBlock, G + kBlock), Eigen::VectorXd(G + kBlock), yy_};
    for (int u = 0; u < G + kBlock; ++u) {
      s.r(u) = r_(idx[u]);
      for (int v = 0; v < G + kBlock; ++v) s.C(u, v) = C_(idx[u], idx[v]);
    }
    return s;
  }

 private:
  int A_, K_;
  Eigen::MatrixXd C_;
  Eigen::VectorXd r_;
  double yy_ = 0.0;
};

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
  // A singular; the ridge of solve_bounded_normal_equations picks the small-norm solution.
  std::vector<int> nonnegative;
  for (int j = 0; j < M; ++j)
    for (int k = 0; k < 3; ++k) nonnegative.push_back(block_index(j, k));  // armature, viscous, coulomb
  return detail::solve_bounded_normal_equations(A, b, nonnegative);
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
  resolve_output_delay_samples(TorqueModelKind::linear, options, median_sample_period(recordings));
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
  const double sample_period = median_sample_period(recordings);
  const std::vector<double> grid = {1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1};
  // Causal qddot candidates (compute_step): the low-pass of the backward
  // difference (the first is what model files without window fields use) and quadratic fits
  // over 40-120 ms, with or without a light low-pass after them.
  const std::vector<AccelerationChoice> accelerations = {
      {0.0, kDefaultAccelerationFilter}, {0.0, 0.01}, {0.0, 0.02}, {0.0, 0.05}, {0.04, 0.0}, {0.06, 0.0},
      {0.08, 0.0}, {0.10, 0.0}, {0.12, 0.0}, {0.16, 0.0}, {0.20, 0.0}, {0.06, 0.01}, {0.10, 0.01}};
  // Zero-phase windows (predict_torque); the fit regresses on the chosen one.
  // The cubic's slope is noisier than a straight line's over the same window,
  // so its windows run longer.
  // Recordings read from files have increasing time; one built in memory whose
  // time goes back gets the causal estimate only.
  bool sorted = true;
  for (const auto& r : recordings) sorted = sorted && is_time_sorted(r.time);
  const std::vector<double> batch_windows =
      sorted ? std::vector<double>{0.07, 0.10, 0.15, 0.20, 0.30, 0.40} : std::vector<double>{};
  const int K = static_cast<int>(grid.size());
  const int A = static_cast<int>(accelerations.size());
  const int B = static_cast<int>(batch_windows.size());
  // Statistics of every joint and candidate, one pass per joint and split.
  std::vector<JointCandidateStats> train, val;
  for (int j = 0; j < M; ++j) {
    std::vector<double> x_c(K);
    for (int k = 0; k < K; ++k) x_c[k] = grid[k] * range[j];
    std::vector<std::vector<Eigen::VectorXd>> batch(recordings.size());
    for (std::size_t r = 0; r < recordings.size(); ++r)
      for (double w : batch_windows)
        batch[r].push_back(compute_zero_phase_acceleration(recordings[r].time, recordings[r].velocity.col(j), w,
                                                           kZeroPhaseAccelerationDegree));
    train.emplace_back(recordings, split.train, j, x_c, accelerations, batch, weight[j], sample_period);
    val.emplace_back(recordings, split.validation, j, x_c, accelerations, batch, weight[j], sample_period);
  }
  struct Choice {
    int dahl, acceleration;  // acceleration: column, < A causal, >= A zero-phase
  };
  // Scoring reads a few hundred combinations; keep each one read.
  std::vector<std::vector<std::unique_ptr<JointStats>>> cache_train(M), cache_val(M);
  for (int j = 0; j < M; ++j) {
    cache_train[j].resize(K * (A + B));
    cache_val[j].resize(K * (A + B));
  }
  auto stats = [&](int j, const Choice& c, bool validation) -> const JointStats& {
    auto& slot = (validation ? cache_val : cache_train)[j][c.dahl * (A + B) + c.acceleration];
    if (!slot)
      slot = std::make_unique<JointStats>((validation ? val : train)[j].get_stats(c.dahl, c.acceleration));
    return *slot;
  };
  auto score = [&](const std::vector<Choice>& c) {
    std::vector<const JointStats*> tr(M), va(M);
    for (int j = 0; j < M; ++j) {
      tr[j] = &stats(j, c[j], false);
      va[j] = &stats(j, c[j], true);
    }
    return objective(va, solve_constrained(tr, M), M);
  };
  // Coordinate descent over each joint's x_c and qddot column in [first, end),
  // scored on the validation split.
  auto descend = [&](std::vector<Choice> choice, int first, int end, double& best) {
    best = score(choice);
    for (int sweep = 0; sweep < 2; ++sweep) {
      for (int j = 0; j < M; ++j)
        for (int k = 0; k < K; ++k) {
          auto trial = choice;
          trial[j].dahl = k;
          const double e = score(trial);
          if (e < best) best = e, choice = trial;
        }
      for (int j = 0; j < M; ++j)
        for (int a = first; a < end; ++a) {
          auto trial = choice;
          trial[j].acceleration = a;
          const double e = score(trial);
          if (e < best) best = e, choice = trial;
        }
    }
    return choice;
  };
  // The causal estimate of compute_step, then x_c and the zero-phase window with
  // which the coefficients are fitted.
  double best_causal = 0.0, best = 0.0;
  const std::vector<Choice> causal = descend(std::vector<Choice>(M, Choice{4, 0}), 0, A, best_causal);
  std::vector<Choice> choice = causal;
  best = best_causal;
  if (B > 0) {
    for (int j = 0; j < M; ++j) choice[j].acceleration = A + 1;
    choice = descend(choice, A, A + B, best);
  }
  // Final coefficients from train + validation.
  std::vector<JointStats> both(M);
  std::vector<const JointStats*> ptr(M);
  for (int j = 0; j < M; ++j) {
    both[j] = stats(j, choice[j], false);
    both[j] += stats(j, choice[j], true);
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
  p.acceleration_window_s.resize(M);
  p.acceleration_filter_s.resize(M);
  p.batch_acceleration_window_s.resize(M);
  for (int j = 0; j < M; ++j) {
    // Rows were scaled by weight[j] on both sides, so coefficients are in joint units.
    p.armature[j] = theta(block_index(j, 0));
    p.viscous[j] = theta(block_index(j, 1));
    p.coulomb[j] = theta(block_index(j, 2));
    p.offset[j] = theta(block_index(j, 3));
    p.dahl_displacement[j] = grid[choice[j].dahl] * range[j];
    p.acceleration_window_s[j] = accelerations[causal[j].acceleration].window_s;
    p.acceleration_filter_s[j] = accelerations[causal[j].acceleration].filter_s;
    p.batch_acceleration_window_s[j] = B > 0 ? batch_windows[choice[j].acceleration - A] : 0.0;
  }
  std::size_t params = G + kBlock * M;
  summary.structure = "generic";

  // Rigid-body stage: the same estimators, the structure of rigid_body.hpp, kept
  // unless the validation split says it does not describe this arm; then the
  // inertia tied by the bodies of a remote-centre arm, kept unless it fits
  // the validation split much worse than the free inertia coefficients.
  if (options.rigid_body && M >= 3) {
    // The Coulomb profile's knots span each joint's range over the samples fitted.
    std::vector<double> lo(M, std::numeric_limits<double>::infinity());
    std::vector<double> hi(M, -std::numeric_limits<double>::infinity());
    for (const auto* segments : {&split.train, &split.validation})
      for (const auto& seg : *segments)
        for (int j = 0; j < M; ++j) {
          const auto column = recordings[seg.recording].position.col(j).segment(seg.begin, seg.size());
          lo[j] = std::min(lo[j], column.minCoeff());
          hi[j] = std::max(hi[j], column.maxCoeff());
        }
    std::vector<detail::JointEstimatorChoice> estimators(M);
    for (int j = 0; j < M; ++j) {
      hi[j] = std::max(hi[j], lo[j] + 1e-6);
      const double slow = j == kPitchJoint || j == kInsertionJoint
                              ? std::max(kSlowDahlTravelFraction * (hi[j] - lo[j]), p.dahl_displacement[j])
                              : kSlowDahlFactor * p.dahl_displacement[j];
      estimators[j] = {p.dahl_displacement[j], slow, p.acceleration_window_s[j], p.acceleration_filter_s[j],
                       p.batch_acceleration_window_s[j], lo[j], hi[j]};
      estimators[j].travel = options.travel_terms && (kTravelJoints >> j & 1u);
    }
    // The time split's training and validation samples, and the same samples
    // cut by speed (split_by_speed: slow, fast), in one pass.
    enum { kTrain, kValidation, kSlow, kFast };
    std::vector<SampleSegment> fitted = split.train;
    fitted.insert(fitted.end(), split.validation.begin(), split.validation.end());
    std::vector<std::vector<SampleSegment>> groups = {split.train, split.validation};
    for (auto& g : detail::split_by_speed(recordings, fitted, M)) groups.push_back(std::move(g));
    const std::vector<detail::ModelStats> stats =
        detail::accumulate_rigid_body_stats(recordings, groups, estimators, weight, sample_period);
    const detail::ModelStats& train_stats = stats[kTrain];
    const detail::ModelStats& val_stats = stats[kValidation];
    // The insertion's stiffness (linear_model.hpp) comes with the structure.
    const unsigned stiffness = options.insertion_stiffness ? 1u << kInsertionJoint : 0u;
    const double rigid_validation = val_stats.compute_loss(
        detail::solve_rigid_body(train_stats, M, detail::InertiaStructure::free, 0.0, 0u, stiffness).theta);
    if (rigid_validation <= kRigidBodyTolerance * best) {
      const double beta = kInstrumentAxisAngle;
      // What the remaining choices are scored by: the mean squared residual on
      // the validation slice plus, fitted on the slow half and scored on the
      // fast one and the other way round, on the other speed.
      auto score = [&](detail::InertiaStructure structure, unsigned profile) {
        auto mean_loss = [&](int scored, int fitted_on) {
          const detail::RigidBodySolution fit =
              detail::solve_rigid_body(stats[fitted_on], M, structure, beta, profile, stiffness);
          return stats[scored].compute_loss(fit.theta) / static_cast<double>(std::max<std::size_t>(stats[scored].rows, 1));
        };
        return mean_loss(kValidation, kTrain) + 0.5 * (mean_loss(kFast, kSlow) + mean_loss(kSlow, kFast));
      };
      detail::InertiaStructure inertia = detail::InertiaStructure::free;
      if (options.remote_center) {
        const double free_score = score(detail::InertiaStructure::free, 0u);
        const double tied_score = score(detail::InertiaStructure::remote_center, 0u);
        if (tied_score <= kRigidBodyTolerance * free_score) {
          inertia = detail::InertiaStructure::remote_center;
        } else {
          summary.warnings.push_back(fmt::format(
              "the bodies of a remote-centre arm fit {:.0f} % worse than free inertia coefficients: kept the free "
              "ones",
              100.0 * (tied_score / free_score - 1.0)));
        }
      }
      // Each joint's Coulomb profile, kept when it predicts the validation slice
      // and the other speed better than a constant level.
      unsigned profile = 0u;
      if (options.coulomb_profile) {
        double best_score = score(inertia, profile);
        for (int j = 0; j < std::min(M, 32); ++j) {  // one bit per joint
          const double with = score(inertia, profile | 1u << j);
          if (with < (1.0 - kProfileGain) * best_score) best_score = with, profile |= 1u << j;
        }
      }
      // Pitch's travel terms (travel_terms.hpp), fitted on what the rest
      // leaves, so that they cannot trade places with the gravity direction
      // and the inertia; kept when they predict the validation slice more
      // than 1 % better. Only pitch (kTravelJoints): see there.
      unsigned travel = 0u;
      if (options.travel_terms) {
        const Eigen::VectorXd on_train =
            detail::solve_rigid_body(train_stats, M, inertia, beta, profile, stiffness).theta;
        const double without = val_stats.compute_loss(on_train);
        for (int j = 0; j < std::min(M, 32); ++j)
          if ((kTravelJoints >> j & 1u) &&
              detail::compute_loss_with_travel(val_stats, j, on_train,
                                               detail::solve_travel_terms(train_stats, j, on_train)) <
                  (1.0 - kProfileGain) * without)
            travel |= 1u << j;
      }
      detail::ModelStats all = train_stats;
      all += val_stats;
      const detail::RigidBodySolution rigid = detail::solve_rigid_body(all, M, inertia, beta, profile, stiffness);
      best = val_stats.compute_loss(
          detail::solve_rigid_body(train_stats, M, inertia, beta, profile, stiffness).theta);
      p.gravity = rigid.theta.head(G);
      p.inertia = rigid.theta.segment(G, kInertiaTerms);
      p.gravity_direction = rigid.gravity_direction;
      for (int j = 0; j < M; ++j) {
        p.armature[j] = rigid.theta(detail::rigid_body_block_index(j, 0));
        p.viscous[j] = rigid.theta(detail::rigid_body_block_index(j, 1));
        p.coulomb[j] = rigid.theta(detail::rigid_body_block_index(j, 2));
        p.offset[j] = rigid.theta(detail::rigid_body_block_index(j, 3));
      }
      if (stiffness) {
        p.stiffness = Eigen::VectorXd::Zero(M);
        for (int j = 0; j < M; ++j) {
          p.stiffness[j] = rigid.theta(detail::rigid_body_block_index(j, detail::kStiffnessEntry));
          p.offset[j] -= p.stiffness[j] * estimators[j].get_stiffness_origin();
        }
      }
      if (travel) {
        p.travel_range.resize(M, 2);
        p.travel_torque = Eigen::MatrixXd::Zero(M, kTravelTorqueKnots);
        p.travel_hysteresis_displacement.resize(M, kTravelHysteresisElements);
        p.travel_hysteresis = Eigen::MatrixXd::Zero(M, kTravelHysteresisElements * kTravelHysteresisKnots);
        for (int j = 0; j < M; ++j) {
          p.travel_range.row(j) << estimators[j].profile_lo, estimators[j].profile_hi;
          for (int h = 0; h < kTravelHysteresisElements; ++h)
            p.travel_hysteresis_displacement(j, h) = estimators[j].get_travel_displacement(h);
          if (!(travel >> j & 1u)) continue;
          const Eigen::VectorXd c = detail::solve_travel_terms(all, j, rigid.theta);
          p.travel_torque.row(j) = c.head(kTravelTorqueKnots).transpose();
          p.travel_hysteresis.row(j) = c.tail(kTravelHysteresisElements * kTravelHysteresisKnots).transpose();
        }
      }
      p.coulomb_slow.resize(M);
      p.sqrt_viscous.resize(M);
      p.dahl_displacement_slow.resize(M);
      for (int j = 0; j < M; ++j) {
        p.dahl_displacement_slow[j] = estimators[j].slow_dahl_displacement;
        p.coulomb_slow[j] = rigid.theta(detail::rigid_body_block_index(j, 4));
        p.sqrt_viscous[j] = rigid.theta(detail::rigid_body_block_index(j, 5));
      }
      if (profile) {
        p.coulomb_profile = Eigen::MatrixXd::Zero(M, kCoulombProfileKnots);
        p.coulomb_profile_range.resize(M, 2);
        for (int j = 0; j < M; ++j) {
          for (int k = 1; k < kCoulombProfileKnots && (profile >> j & 1u); ++k)
            p.coulomb_profile(j, k) =
                rigid.theta(detail::rigid_body_block_index(j, detail::kCoulombProfileFirst + k - 1));
          p.coulomb_profile_range.row(j) << estimators[j].profile_lo, estimators[j].profile_hi;
        }
      }
      const bool tied = inertia == detail::InertiaStructure::remote_center;
      params = kGravityMoments + 2 + (tied ? kRemoteCenterTerms : kInertiaTerms) +
               detail::kStiffnessEntry * M +
               (kCoulombProfileKnots - 1) * static_cast<int>(std::bitset<32>(profile).count()) +
               static_cast<int>(std::bitset<32>(stiffness).count()) +
               kTravelColumns * static_cast<int>(std::bitset<32>(travel).count());
      summary.structure = tied ? "remote-center" : "rigid-body";
    } else {
      summary.warnings.push_back(fmt::format(
          "the rigid-body structure fits the validation split {:.0f} % worse than the generic potential: kept the "
          "generic one (joints 1-3 may not pivot as yaw, pitch, insertion)",
          100.0 * (rigid_validation / best - 1.0)));
    }
  }
  summary.best_validation_loss = best / static_cast<double>(summary.validation_samples * M);

  // Too few data: fewer than 20 training rows per parameter, or a joint whose
  // velocity never changes sign (Coulomb and offset cannot be told apart).
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

  // Rate-dependent friction that bends over is not carried beyond the
  // fastest each joint moved in the samples fitted (linear_model.hpp).
  p.friction_speed_limit = Eigen::VectorXd::Zero(M);
  for (const auto* segments : {&split.train, &split.validation})
    for (const auto& seg : *segments)
      p.friction_speed_limit = p.friction_speed_limit.cwiseMax(
          recordings[seg.recording].velocity.block(seg.begin, 0, seg.size(), M).cwiseAbs().colwise().maxCoeff().transpose());
  for (int j = 0; j < M; ++j)
    if (!(p.viscous[j] < 0)) p.friction_speed_limit[j] = 0.0;

  TorqueModelInfo info;
  info.num_joints = N;
  info.num_outputs = M;
  info.sample_period_s = sample_period;
  // The regime of the joints the regressors read (1-3): a wrist that never
  // moved in free space is no reason to doubt the model when it turns.
  info.regime = compute_training_regime(recordings, 3);
  p.live_zero_phase = options.live_zero_phase;
  auto model_for_test = std::make_unique<LinearTorqueModel>(info, p);
  summary.output_delay_samples = model_for_test->output_delay();
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
