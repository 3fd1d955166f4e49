#include "rigid_body_fit.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "acceleration.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "gravity_terms.hpp"

namespace rcm::dynamics::detail {

namespace {
using detail::G;
// Ridge of the travel terms' fit, relative to the mean of their normal
// matrix's diagonal.
constexpr double kTravelRidge = 1e-4;
}  // namespace

ModelStats& ModelStats::operator+=(const ModelStats& o) {
  A += o.A;
  b += o.b;
  yy += o.yy;
  rows += o.rows;
  if (travel.size() < o.travel.size()) travel.resize(o.travel.size());
  for (std::size_t j = 0; j < o.travel.size(); ++j) {
    auto& t = travel[j];
    const auto& u = o.travel[j];
    if (!u.ee.size()) continue;
    if (!t.ee.size()) {
      t = u;
    } else {
      t.ee += u.ee;
      t.ex += u.ex;
      t.ey += u.ey;
    }
  }
  return *this;
}

Eigen::VectorXd solve_travel_terms(const ModelStats& stats, int j, const Eigen::VectorXd& theta) {
  const auto& t = stats.travel.at(static_cast<std::size_t>(j));
  // The elements' states are nearly collinear (neighbouring displacements):
  // without a ridge the fit cancels large levels against each other, which
  // another slice of the path then does not cancel.
  Eigen::MatrixXd A = t.ee;
  A.diagonal().array() += kTravelRidge * t.ee.diagonal().mean();
  return solve_bounded_normal_equations(A, t.ey - t.ex * theta, {});
}

double compute_loss_with_travel(const ModelStats& stats, int j, const Eigen::VectorXd& theta,
                                const Eigen::VectorXd& c) {
  const auto& t = stats.travel.at(static_cast<std::size_t>(j));
  return stats.compute_loss(theta) - 2.0 * c.dot(t.ey - t.ex * theta) + c.dot(t.ee * c);
}

double ModelStats::compute_loss(const Eigen::VectorXd& theta) const {
  return yy - 2.0 * theta.dot(b) + theta.dot(A * theta);
}

std::vector<ModelStats> accumulate_rigid_body_stats(const std::vector<Recording>& recordings,
                                                    const std::vector<std::vector<SampleSegment>>& groups,
                                                    const std::vector<JointEstimatorChoice>& choices,
                                                    const std::vector<double>& weight, double sample_period_s) {
  const int M = static_cast<int>(choices.size());
  const int P = kRigidBodyShared + kRigidBodyBlock * M;
  const std::size_t num_groups = groups.size();
  std::vector<ModelStats> stats(num_groups, ModelStats{Eigen::MatrixXd::Zero(P, P), Eigen::VectorXd::Zero(P), 0.0, 0, {}});
  constexpr int E = kTravelColumns;
  for (auto& s : stats) {
    s.travel.resize(static_cast<std::size_t>(M));
    for (int j = 0; j < M; ++j)
      if (choices[j].travel)
        s.travel[static_cast<std::size_t>(j)] = {Eigen::MatrixXd::Zero(E, E), Eigen::MatrixXd::Zero(E, P),
                                                 Eigen::VectorXd::Zero(E)};
  }
  // Which groups each sample of each recording belongs to (bit g), and how far
  // each recording is needed.
  std::vector<std::vector<std::uint32_t>> member(recordings.size());
  std::vector<Eigen::Index> needed(recordings.size(), 0);
  for (std::size_t g = 0; g < num_groups; ++g)
    for (const auto& seg : groups[g]) {
      auto& m = member[static_cast<std::size_t>(seg.recording)];
      if (m.empty()) m.assign(static_cast<std::size_t>(recordings[seg.recording].time.size()), 0u);
      for (Eigen::Index t = seg.begin; t < seg.end; ++t) m[static_cast<std::size_t>(t)] |= 1u << g;
      needed[seg.recording] = std::max(needed[seg.recording], seg.end);
    }
  constexpr Eigen::Index kChunk = 2048;
  std::vector<Eigen::MatrixXd> F(num_groups, Eigen::MatrixXd(kChunk, P));
  std::vector<Eigen::VectorXd> y(num_groups, Eigen::VectorXd(kChunk));
  std::vector<Eigen::Index> n(num_groups, 0);
  // The travel rows of each group and joint, and the model rows and torques
  // they go with.
  constexpr Eigen::Index kTravelChunk = 512;
  std::vector<std::vector<Eigen::MatrixXd>> Fe(num_groups), Fx(num_groups);
  std::vector<std::vector<Eigen::VectorXd>> ye(num_groups);
  std::vector<std::vector<Eigen::Index>> ne(num_groups, std::vector<Eigen::Index>(static_cast<std::size_t>(M), 0));
  for (std::size_t g = 0; g < num_groups; ++g)
    for (int j = 0; j < M; ++j) {
      const bool on = choices[j].travel;
      Fe[g].push_back(on ? Eigen::MatrixXd(kTravelChunk, E) : Eigen::MatrixXd());
      Fx[g].push_back(on ? Eigen::MatrixXd(kTravelChunk, P) : Eigen::MatrixXd());
      ye[g].push_back(on ? Eigen::VectorXd(kTravelChunk) : Eigen::VectorXd());
    }
  auto flush_travel = [&](std::size_t g, int j) {
    const auto u = static_cast<std::size_t>(j);
    const Eigen::Index k = ne[g][u];
    auto& t = stats[g].travel[u];
    t.ee.noalias() += Fe[g][u].topRows(k).transpose() * Fe[g][u].topRows(k);
    t.ex.noalias() += Fe[g][u].topRows(k).transpose() * Fx[g][u].topRows(k);
    t.ey.noalias() += Fe[g][u].topRows(k).transpose() * ye[g][u].head(k);
    ne[g][u] = 0;
  };
  auto flush = [&](std::size_t g) {
    const Eigen::Index k = n[g];
    stats[g].A.noalias() += F[g].topRows(k).transpose() * F[g].topRows(k);
    stats[g].b.noalias() += F[g].topRows(k).transpose() * y[g].head(k);
    stats[g].yy += y[g].head(k).squaredNorm();
    n[g] = 0;
  };
  Eigen::RowVectorXd row(P);
  Eigen::Matrix<double, 3, G> Yg;
  Eigen::Matrix<double, 3, kInertiaTerms> Yi;
  std::vector<AccelerationEstimator> estimators;
  for (const auto& c : choices) estimators.emplace_back(c.causal_window_s, c.causal_filter_s, sample_period_s);
  std::vector<Eigen::VectorXd> batch(M);
  Eigen::VectorXd z(M), z_slow(M), qdd(M);
  Eigen::Matrix<double, Eigen::Dynamic, kTravelHysteresisElements, Eigen::RowMajor> z_travel(M,
                                                                                          kTravelHysteresisElements);
  Eigen::RowVectorXd travel_row(E);
  for (std::size_t r = 0; r < recordings.size(); ++r) {
    if (needed[r] == 0) continue;
    const auto& rec = recordings[r];
    // The zero-phase qddot of each joint whose choice regresses on it.
    for (int j = 0; j < M; ++j)
      batch[j] = choices[j].batch_window_s > 0
                     ? compute_zero_phase_acceleration(rec.time, rec.velocity.col(j), choices[j].batch_window_s,
                                                       kZeroPhaseAccelerationDegree)
                     : Eigen::VectorXd();
    for (auto& e : estimators) e.reset();
    z.setZero();
    z_slow.setZero();
    z_travel.setZero();
    DahlClock dahl_clock(sample_period_s);  // the model's (linear_model.hpp)
    Eigen::Index dahl_last = 0;
    for (Eigen::Index t = 0; t < needed[r]; ++t) {
      const bool dahl_step = dahl_clock.tick(rec.time(t));
      for (int j = 0; j < M; ++j) {
        if (t > 0 && dahl_step) {
          const double dq = rec.position(t, j) - rec.position(dahl_last, j);
          z[j] = compute_dahl_state(z[j], dq, choices[j].dahl_displacement);
          z_slow[j] = compute_dahl_state(z_slow[j], dq, choices[j].slow_dahl_displacement);
          if (choices[j].travel)
            for (int h = 0; h < kTravelHysteresisElements; ++h)
              z_travel(j, h) = compute_dahl_state(z_travel(j, h), dq, choices[j].get_travel_displacement(h));
        }
        estimators[j].update(rec.time(t), rec.velocity(t, j));
      }
      if (dahl_step) dahl_last = t;
      const std::uint32_t in = member[r][static_cast<std::size_t>(t)];
      if (!in) continue;
      for (int j = 0; j < M; ++j) qdd[j] = batch[j].size() ? batch[j](t) : estimators[j].value();
      const double q[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
      const double qd[3] = {rec.velocity(t, 0), rec.velocity(t, 1), rec.velocity(t, 2)};
      LinearTorqueModel::compute_gravity_regressor(q, Yg);
      compute_inertia_regressor(q, qd, qdd.data(), Yi);
      for (int j = 0; j < M; ++j) {
        const double w = weight[j];
        row.setZero();
        if (j < 3) {
          row.head(G) = Yg.row(j) * w;
          row.segment(G, kInertiaTerms) = Yi.row(j) * w;
        }
        row(rigid_body_block_index(j, 0)) = qdd[j] * w;
        row(rigid_body_block_index(j, 1)) = rec.velocity(t, j) * w;
        row(rigid_body_block_index(j, 2)) = z[j] * w;
        row(rigid_body_block_index(j, 3)) = w;
        row(rigid_body_block_index(j, 4)) = z_slow[j] * w;
        row(rigid_body_block_index(j, 5)) = compute_sqrt_velocity(rec.velocity(t, j)) * w;
        row(rigid_body_block_index(j, kStiffnessEntry)) = (rec.position(t, j) - choices[j].get_stiffness_origin()) * w;
        int k;
        double u;
        compute_knot_weights(rec.position(t, j), choices[j].profile_lo, choices[j].profile_hi, kCoulombProfileKnots, k,
                             u);
        // Knot 0's column is the constant Coulomb column's.
        if (k > 0) row(rigid_body_block_index(j, kCoulombProfileFirst + k - 1)) = (1.0 - u) * z[j] * w;
        row(rigid_body_block_index(j, kCoulombProfileFirst + k)) = u * z[j] * w;
        if (choices[j].travel)
          compute_travel_regressor(rec.position(t, j), choices[j].profile_lo, choices[j].profile_hi,
                                   z_travel.row(j).data(), kTravelHysteresisElements, kTravelTorqueKnots,
                                   kTravelHysteresisKnots, travel_row.data());
        const auto ju = static_cast<std::size_t>(j);
        for (std::size_t g = 0; g < num_groups; ++g)
          if (in & (1u << g)) {
            F[g].row(n[g]) = row;
            y[g](n[g]) = rec.effort(t, j) * w;
            ++stats[g].rows;
            if (++n[g] == kChunk) flush(g);
            if (choices[j].travel) {
              Fe[g][ju].row(ne[g][ju]) = travel_row * w;
              Fx[g][ju].row(ne[g][ju]) = row;
              ye[g][ju](ne[g][ju]) = rec.effort(t, j) * w;
              if (++ne[g][ju] == kTravelChunk) flush_travel(g, j);
            }
          }
      }
    }
  }
  for (std::size_t g = 0; g < num_groups; ++g) {
    if (n[g]) flush(g);
    for (int j = 0; j < M; ++j)
      if (ne[g][static_cast<std::size_t>(j)]) flush_travel(g, j);
  }
  return stats;
}

ModelStats accumulate_rigid_body_stats(const std::vector<Recording>& recordings,
                                       const std::vector<SampleSegment>& segments,
                                       const std::vector<JointEstimatorChoice>& choices,
                                       const std::vector<double>& weight, double sample_period_s) {
  return accumulate_rigid_body_stats(recordings, std::vector<std::vector<SampleSegment>>{segments}, choices, weight,
                                     sample_period_s)
      .front();
}

std::vector<std::vector<SampleSegment>> split_by_speed(const std::vector<Recording>& recordings,
                                                       const std::vector<SampleSegment>& segments, int M,
                                                       double chunk_s) {
  // Each joint's speed in units of its standard deviation over the segments.
  Eigen::VectorXd sum2 = Eigen::VectorXd::Zero(M);
  double count = 0;
  for (const auto& seg : segments) {
    sum2 += recordings[seg.recording].velocity.block(seg.begin, 0, seg.size(), M).colwise().squaredNorm().transpose();
    count += static_cast<double>(seg.size());
  }
  Eigen::VectorXd inv_sd(M);
  for (int j = 0; j < M; ++j) inv_sd[j] = sum2[j] > 0 ? std::sqrt(count / sum2[j]) : 0.0;
  struct Chunk {
    SampleSegment segment;
    double speed;
  };
  std::vector<Chunk> chunks;
  for (const auto& seg : segments) {
    const auto& rec = recordings[seg.recording];
    Eigen::Index begin = seg.begin;
    while (begin < seg.end) {
      Eigen::Index end = begin + 1;
      while (end < seg.end && rec.time(end) - rec.time(begin) < chunk_s) ++end;
      double speed = 0.0;
      for (Eigen::Index t = begin; t < end; ++t)
        speed += (rec.velocity.row(t).head(M).transpose().cwiseProduct(inv_sd)).norm();
      chunks.push_back({{seg.recording, begin, end}, speed / static_cast<double>(end - begin)});
      begin = end;
    }
  }
  std::vector<double> speeds;
  for (const auto& c : chunks) speeds.push_back(c.speed);
  std::vector<std::vector<SampleSegment>> out(2);
  if (speeds.empty()) return out;
  std::nth_element(speeds.begin(), speeds.begin() + static_cast<std::ptrdiff_t>(speeds.size() / 2), speeds.end());
  const double median = speeds[speeds.size() / 2];
  for (const auto& c : chunks) out[c.speed <= median ? 0 : 1].push_back(c.segment);
  return out;
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

namespace {

// The reduced problem of one structure: T maps [7 moments | inertia | joint
// blocks] to the full layout, its gravity block filled for each g.
class RigidBodyProblem {
 public:
  RigidBodyProblem(const ModelStats& stats, int M, InertiaStructure structure, double beta, unsigned profile_joints,
                   unsigned stiffness_joints)
      : stats_(stats) {
    const int P = static_cast<int>(stats.A.rows());
    const int blocks = P - kRigidBodyShared;
    const bool tied = structure == InertiaStructure::remote_center;
    const int first_block = kGravityMoments + (tied ? kRemoteCenterTerms : kInertiaTerms);
    T_ = Eigen::MatrixXd::Zero(P, first_block + blocks);
    T_.bottomRightCorner(blocks, blocks).setIdentity();
    // A joint without the profile: its columns map to nothing, the ridge holds them at 0.
    for (int j = 0; j < M; ++j)
      if (!(profile_joints >> j & 1u))
        for (int k = kCoulombProfileFirst; k < kRigidBodyBlock; ++k)
          T_(rigid_body_block_index(j, k), first_block + kRigidBodyBlock * j + k) = 0.0;
    for (int j = 0; j < M; ++j)
      if (!(stiffness_joints >> j & 1u))
        T_(rigid_body_block_index(j, kStiffnessEntry), first_block + kRigidBodyBlock * j + kStiffnessEntry) = 0.0;
    for (int j = 0; j < M; ++j) {
      // Friction >= 0; with the remote-centre bodies the armatures are
      // inertias (>= 0) and the viscous term may bend a sqrt-viscous one
      // over (friction that saturates with speed).
      for (int k : {1, 2, 4, 5})
        if (!(tied && k == 1)) nonnegative_.push_back(first_block + kRigidBodyBlock * j + k);
      if (tied) nonnegative_.push_back(first_block + kRigidBodyBlock * j);
    }
    if (tied) {
      Eigen::Matrix<double, kInertiaTerms, kRemoteCenterTerms> Mrc;
      compute_remote_center_map(beta, Mrc);
      T_.block(G, kGravityMoments, kInertiaTerms, kRemoteCenterTerms) = Mrc;
      T_(rigid_body_block_index(2, 0), kGravityMoments) = 1.0;  // the sliding mass is insertion inertia too
      nonnegative_.push_back(kGravityMoments);
    } else {
      T_.block(G, kGravityMoments, kInertiaTerms, kInertiaTerms).setIdentity();
    }
    // T's first kGravityMoments columns are its gravity block (rows 0..G-1,
    // zero below) and nothing else moves with g: the products with the other
    // columns are made once here, and each direction of the gravity search
    // costs O(G P) instead of two P x P products (most of a linear fit's time).
    const Eigen::Index rest = T_.cols() - kGravityMoments;
    const auto T_rest = T_.rightCols(rest);
    const Eigen::MatrixXd A_T_rest = stats.A * T_rest;
    Ar_rest_rest_ = T_rest.transpose() * A_T_rest;
    A_g_rest_ = A_T_rest.topRows(G);
    A_g_g_ = stats.A.topLeftCorner(G, G);
    br_rest_ = T_rest.transpose() * stats.b;
  }

  // T^T A T and T^T b, T's gravity block at g.
  RigidBodySolution solve_at(const Eigen::Vector3d& g) {
    compute_gravity_moment_map(g, Pg_);
    T_.topLeftCorner(G, kGravityMoments) = Pg_;
    const Eigen::Index n = T_.cols(), rest = n - kGravityMoments;
    Eigen::MatrixXd Ar(n, n);
    Ar.topLeftCorner(kGravityMoments, kGravityMoments).noalias() = Pg_.transpose() * A_g_g_ * Pg_;
    Ar.topRightCorner(kGravityMoments, rest).noalias() = Pg_.transpose() * A_g_rest_;
    Ar.bottomLeftCorner(rest, kGravityMoments) = Ar.topRightCorner(kGravityMoments, rest).transpose();
    Ar.bottomRightCorner(rest, rest) = Ar_rest_rest_;
    Eigen::VectorXd br(n);
    br.head(kGravityMoments).noalias() = Pg_.transpose() * stats_.b.head(G);
    br.tail(rest) = br_rest_;
    RigidBodySolution s;
    s.theta = T_ * solve_bounded_normal_equations(Ar, br, nonnegative_);
    s.gravity_direction = g;
    s.loss = stats_.compute_loss(s.theta);
    return s;
  }

 private:
  const ModelStats& stats_;
  Eigen::MatrixXd T_;
  std::vector<int> nonnegative_;
  Eigen::Matrix<double, 17, kGravityMoments> Pg_;
  Eigen::MatrixXd Ar_rest_rest_, A_g_rest_, A_g_g_;  // T's fixed columns' products
  Eigen::VectorXd br_rest_;
};

}  // namespace

RigidBodySolution solve_rigid_body_at(const ModelStats& stats, int M, InertiaStructure structure, double beta,
                                      const Eigen::Vector3d& g, unsigned profile_joints, unsigned stiffness_joints) {
  return RigidBodyProblem(stats, M, structure, beta, profile_joints, stiffness_joints).solve_at(g);
}

RigidBodySolution solve_rigid_body(const ModelStats& stats, int M, InertiaStructure structure, double beta,
                                   unsigned profile_joints, unsigned stiffness_joints) {
  RigidBodyProblem problem(stats, M, structure, beta, profile_joints, stiffness_joints);
  return search_gravity_direction([&](const Eigen::Vector3d& g) { return problem.solve_at(g); });
}

}  // namespace rcm::dynamics::detail
