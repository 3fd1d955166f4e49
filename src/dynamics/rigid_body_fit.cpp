#include "rigid_body_fit.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "acceleration.hpp"
#include "rcm/dynamics/linear_model.hpp"

namespace rcm::dynamics::detail {

namespace {
constexpr int G = LinearTorqueModel::kGravityTerms;
constexpr double kDegree = M_PI / 180.0;

Eigen::Vector3d direction(double polar, double azimuth) {
  return {std::sin(polar) * std::cos(azimuth), std::sin(polar) * std::sin(azimuth), std::cos(polar)};
}
}  // namespace

ModelStats& ModelStats::operator+=(const ModelStats& o) {
  A += o.A;
  b += o.b;
  yy += o.yy;
  return *this;
}

double ModelStats::compute_loss(const Eigen::VectorXd& theta) const {
  return yy - 2.0 * theta.dot(b) + theta.dot(A * theta);
}

ModelStats accumulate_rigid_body_stats(const std::vector<Recording>& recordings,
                                       const std::vector<SampleSegment>& segments,
                                       const std::vector<JointEstimatorChoice>& choices,
                                       const std::vector<double>& weight, double sample_period_s) {
  const int M = static_cast<int>(choices.size());
  const int P = kRigidBodyShared + kRigidBodyBlock * M;
  ModelStats s{Eigen::MatrixXd::Zero(P, P), Eigen::VectorXd::Zero(P), 0.0};
  constexpr Eigen::Index kChunk = 4096;
  Eigen::MatrixXd F(kChunk, P);
  Eigen::VectorXd y(kChunk);
  Eigen::Matrix<double, 3, G> Yg;
  Eigen::Matrix<double, 3, kInertiaTerms> Yi;
  std::vector<AccelerationEstimator> estimators;
  for (const auto& c : choices) estimators.emplace_back(c.causal_window_s, c.causal_filter_s, sample_period_s);
  Eigen::VectorXd z(M), z_slow(M), qdd(M);
  // The zero-phase qddot of each joint whose choice regresses on it, per recording.
  std::vector<std::vector<Eigen::VectorXd>> batch(recordings.size(), std::vector<Eigen::VectorXd>(M));
  for (const auto& seg : segments)
    for (int j = 0; j < M; ++j)
      if (choices[j].batch_window_s > 0 && batch[seg.recording][j].size() == 0) {
        const auto& rec = recordings[seg.recording];
        batch[seg.recording][j] = compute_zero_phase_acceleration(rec.time, rec.velocity.col(j), choices[j].batch_window_s);
      }
  for (const auto& seg : segments) {
    const auto& rec = recordings[seg.recording];
    for (auto& e : estimators) e.reset();
    z.setZero();
    z_slow.setZero();
    Eigen::Index n = 0;
    auto flush = [&]() {
      s.A.noalias() += F.topRows(n).transpose() * F.topRows(n);
      s.b.noalias() += F.topRows(n).transpose() * y.head(n);
      s.yy += y.head(n).squaredNorm();
      n = 0;
    };
    for (Eigen::Index t = 0; t < seg.end; ++t) {
      for (int j = 0; j < M; ++j) {
        if (t > 0) {
          const double dq = rec.position(t, j) - rec.position(t - 1, j);
          z[j] = compute_dahl_state(z[j], dq, choices[j].dahl_displacement);
          z_slow[j] = compute_dahl_state(z_slow[j], dq, kSlowDahlFactor * choices[j].dahl_displacement);
        }
        estimators[j].update(rec.time(t), rec.velocity(t, j));
      }
      if (t < seg.begin) continue;
      for (int j = 0; j < M; ++j)
        qdd[j] = choices[j].batch_window_s > 0 ? batch[seg.recording][j](t) : estimators[j].value();
      const double q[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
      const double qd[3] = {rec.velocity(t, 0), rec.velocity(t, 1), rec.velocity(t, 2)};
      LinearTorqueModel::compute_gravity_regressor(q, Yg);
      compute_inertia_regressor(q, qd, qdd.data(), Yi);
      for (int j = 0; j < M; ++j) {
        const double w = weight[j];
        F.row(n).setZero();
        if (j < 3) {
          F.row(n).head(G) = Yg.row(j) * w;
          F.row(n).segment(G, kInertiaTerms) = Yi.row(j) * w;
        }
        F(n, rigid_body_block_index(j, 0)) = qdd[j] * w;
        F(n, rigid_body_block_index(j, 1)) = rec.velocity(t, j) * w;
        F(n, rigid_body_block_index(j, 2)) = z[j] * w;
        F(n, rigid_body_block_index(j, 3)) = w;
        F(n, rigid_body_block_index(j, 4)) = z_slow[j] * w;
        F(n, rigid_body_block_index(j, 5)) = compute_sqrt_velocity(rec.velocity(t, j)) * w;
        y(n) = rec.effort(t, j) * w;
        if (++n == kChunk) flush();
      }
    }
    if (n) flush();
  }
  return s;
}

Eigen::VectorXd solve_bounded_normal_equations(const Eigen::MatrixXd& A_in, const Eigen::VectorXd& b,
                                               const std::vector<int>& nonnegative) {
  const Eigen::Index P = A_in.rows();
  Eigen::MatrixXd A = A_in;
  const double floor = 1e-12 * std::max(1.0, A.diagonal().maxCoeff());
  for (Eigen::Index k = 0; k < P; ++k) A(k, k) += 1e-9 * A(k, k) + floor;
  std::vector<bool> fixed(static_cast<std::size_t>(P), false);
  Eigen::VectorXd theta;
  for (std::size_t iter = 0; iter <= nonnegative.size(); ++iter) {
    Eigen::MatrixXd Af = A;
    Eigen::VectorXd bf = b;
    for (Eigen::Index k = 0; k < P; ++k)
      if (fixed[static_cast<std::size_t>(k)]) {
        Af.row(k).setZero();
        Af.col(k).setZero();
        Af(k, k) = 1.0;
        bf(k) = 0.0;
      }
    theta = Af.ldlt().solve(bf);
    bool changed = false;
    for (int i : nonnegative)
      if (!fixed[static_cast<std::size_t>(i)] && theta(i) < 0) fixed[static_cast<std::size_t>(i)] = changed = true;
    if (!changed) break;
  }
  return theta;
}

RigidBodySolution solve_rigid_body(const ModelStats& stats, int M) {
  const int P = static_cast<int>(stats.A.rows());
  const int rest = P - G;  // inertia and the joint blocks
  const int R = kGravityMoments + rest;
  std::vector<int> nonnegative;  // viscous and Coulomb, in the reduced layout
  for (int j = 0; j < M; ++j)
    for (int k : {1, 2, 4, 5}) nonnegative.push_back(rigid_body_block_index(j, k) - G + kGravityMoments);
  Eigen::Matrix<double, 17, kGravityMoments> Pg;
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(P, R);
  T.bottomRightCorner(rest, rest).setIdentity();
  auto solve_at = [&](const Eigen::Vector3d& g) {
    compute_gravity_moment_map(g, Pg);
    T.topLeftCorner(G, kGravityMoments) = Pg;
    const Eigen::MatrixXd Ar = T.transpose() * stats.A * T;
    const Eigen::VectorXd br = T.transpose() * stats.b;
    RigidBodySolution s;
    s.theta = T * solve_bounded_normal_equations(Ar, br, nonnegative);
    s.gravity_direction = g;
    s.loss = stats.compute_loss(s.theta);
    return s;
  };
  // g and -g give the same span: the upper half sphere is enough.
  RigidBodySolution best;
  double best_polar = 0.0, best_azimuth = 0.0;
  bool first = true;
  for (int polar = 0; polar <= 90; polar += 5)
    for (int azimuth = 0; azimuth < 360; azimuth += (polar == 0 ? 360 : 15)) {
      RigidBodySolution s = solve_at(direction(polar * kDegree, azimuth * kDegree));
      if (first || s.loss < best.loss) {
        best = std::move(s);
        best_polar = polar;
        best_azimuth = azimuth;
        first = false;
      }
    }
  const double p0 = best_polar, a0 = best_azimuth;
  for (int dp = -5; dp <= 5; ++dp)
    for (int da = -8; da <= 8; ++da) {
      RigidBodySolution s = solve_at(direction((p0 + dp) * kDegree, (a0 + da) * kDegree));
      if (s.loss < best.loss) best = std::move(s);
    }
  return best;
}

}  // namespace rcm::dynamics::detail
