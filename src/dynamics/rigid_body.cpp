#include "rcm/dynamics/rigid_body.hpp"

#include <Eigen/Geometry>
#include <array>
#include <cmath>

namespace rcm::dynamics {

namespace {

// g_k(q2, q3) = f2(q2) f3(q3) times s_k = qd_a qd_b (1/2 qd_a^2 when a = b).
enum F2 { kOne2, kCos2, kSin2, kCos, kSin };
enum F3 { kOne3, kQ3, kQ3Squared };
struct EnergyTerm {
  F2 f2;
  F3 f3;
  int a, b;
};
constexpr std::array<EnergyTerm, kInertiaTerms> kTerms = {{
    {kOne2, kQ3, 0, 0}, {kOne2, kQ3Squared, 0, 0},                        // qd1^2
    {kCos2, kOne3, 0, 0}, {kCos2, kQ3, 0, 0}, {kCos2, kQ3Squared, 0, 0},  //
    {kSin2, kOne3, 0, 0}, {kSin2, kQ3, 0, 0}, {kSin2, kQ3Squared, 0, 0},  //
    {kCos, kOne3, 0, 1}, {kCos, kQ3, 0, 1}, {kCos, kQ3Squared, 0, 1},     // qd1 qd2
    {kSin, kOne3, 0, 1}, {kSin, kQ3, 0, 1}, {kSin, kQ3Squared, 0, 1},     //
    {kOne2, kQ3, 1, 1}, {kOne2, kQ3Squared, 1, 1},                        // qd2^2
    {kCos, kOne3, 0, 2}, {kSin, kOne3, 0, 2},                             // qd1 qd3
    {kOne2, kOne3, 1, 2},                                                 // qd2 qd3
}};

struct Factors {
  std::array<double, 5> f2, df2;
  std::array<double, 3> f3, df3;
};

Factors compute_factors(const double* q) {
  const double c = std::cos(q[1]), s = std::sin(q[1]), c2 = c * c - s * s, s2 = 2.0 * s * c;
  Factors f;
  f.f2 = {1.0, c2, s2, c, s};
  f.df2 = {0.0, -2.0 * s2, 2.0 * c2, -s, c};
  f.f3 = {1.0, q[2], q[2] * q[2]};
  f.df3 = {0.0, 1.0, 2.0 * q[2]};
  return f;
}

}  // namespace

void compute_inertia_regressor(const double* q, const double* qd, const double* qdd,
                               Eigen::Matrix<double, 3, kInertiaTerms>& Y) {
  const Factors f = compute_factors(q);
  for (int k = 0; k < kInertiaTerms; ++k) {
    const EnergyTerm& e = kTerms[static_cast<std::size_t>(k)];
    const double g = f.f2[e.f2] * f.f3[e.f3];
    const double dg[3] = {0.0, f.df2[e.f2] * f.f3[e.f3], f.f2[e.f2] * f.df3[e.f3]};
    const double g_dot = dg[1] * qd[1] + dg[2] * qd[2];
    const double s = e.a == e.b ? 0.5 * qd[e.a] * qd[e.a] : qd[e.a] * qd[e.b];
    for (int i = 0; i < 3; ++i) {
      // dT/dqd_i = g ds/dqd_i, and its time derivative.
      double ds = 0.0, ds_dot = 0.0;
      if (e.a == e.b) {
        if (i == e.a) ds = qd[e.a], ds_dot = qdd[e.a];
      } else if (i == e.a) {
        ds = qd[e.b], ds_dot = qdd[e.b];
      } else if (i == e.b) {
        ds = qd[e.a], ds_dot = qdd[e.a];
      }
      Y(i, k) = g_dot * ds + g * ds_dot - dg[i] * s;
    }
  }
}

double compute_inertia_energy(const Eigen::Matrix<double, kInertiaTerms, 1>& theta, const double* q,
                              const double* qd) {
  const Factors f = compute_factors(q);
  double T = 0.0;
  for (int k = 0; k < kInertiaTerms; ++k) {
    const EnergyTerm& e = kTerms[static_cast<std::size_t>(k)];
    const double s = e.a == e.b ? 0.5 * qd[e.a] * qd[e.a] : qd[e.a] * qd[e.b];
    T += theta[k] * f.f2[e.f2] * f.f3[e.f3] * s;
  }
  return T;
}

void compute_remote_center_map(double beta, Eigen::Matrix<double, kInertiaTerms, kRemoteCenterTerms>& M) {
  // Term indices as in kTerms; parameters as in the header.
  enum { kMass, kHx, kHy, kHz, kIc2, kIs2, kIc, kIs };
  const double sb = std::sin(beta), cb = std::cos(beta);
  M.setZero();
  // 1/2 m q3^2 [qd2^2 + qd1^2 sin^2(q2 - beta)]: no qd1 qd2 q3^2 terms.
  M(1, kMass) = 0.5;
  M(4, kMass) = -0.5 * std::cos(2.0 * beta);
  M(7, kMass) = -0.5 * std::sin(2.0 * beta);
  M(15, kMass) = 1.0;
  // q3 [|w|^2 (e.h) - (w.e)(w.h)], w.e = qd1 cos(q2 - beta).
  M(0, kHy) = sb, M(0, kHz) = cb;
  M(3, kHy) = sb, M(3, kHz) = -cb;
  M(6, kHy) = -cb, M(6, kHz) = -sb;
  M(14, kHy) = 2.0 * sb, M(14, kHz) = 2.0 * cb;
  M(9, kHx) = -cb;
  M(12, kHx) = -sb;
  // qd3 w.(h x e).
  M(16, kHx) = sb;
  M(17, kHx) = -cb;
  M(18, kHy) = cb, M(18, kHz) = -sb;
  // 1/2 w.I.w beyond the armatures.
  M(2, kIc2) = 1.0;
  M(5, kIs2) = 1.0;
  M(8, kIc) = 1.0;
  M(11, kIs) = 1.0;
}

double compute_remote_center_energy(double beta, const Eigen::Matrix<double, kRemoteCenterTerms, 1>& x,
                                    const double* q, const double* qd) {
  const double s = std::sin(q[1]), c = std::cos(q[1]);
  const Eigen::Vector3d w(qd[1], qd[0] * s, qd[0] * c);
  const Eigen::Vector3d e(0.0, std::sin(beta), std::cos(beta));
  const Eigen::Vector3d h(x[1], x[2], x[3]);
  // I without its constant diagonal (the armatures): I_zz - I_yy = 2 x4 split
  // as +-x4, the trace part dropped.
  Eigen::Matrix3d I;
  I << 0.0, x[7], x[6], x[7], -x[4], x[5], x[6], x[5], x[4];
  const double m = x[0], q3 = q[2];
  return 0.5 * w.dot(I * w) + q3 * (w.squaredNorm() * e.dot(h) - w.dot(e) * w.dot(h)) +
         0.5 * m * q3 * q3 * (w.squaredNorm() - w.dot(e) * w.dot(e)) + qd[2] * w.dot(h.cross(e));
}

void compute_gravity_moment_map(const Eigen::Vector3d& g, Eigen::Matrix<double, 17, kGravityMoments>& P) {
  // Coefficient index of a(q1) b(q2) c(q3) in compute_gravity_regressor's
  // order: a in {1, sin q1, cos q1}, b in {1, sin q2, cos q2}, c in {1, q3},
  // the constant left out.
  auto index = [](int a, int b, int c) { return a * 6 + b * 2 + c - 1; };
  enum { kOne = 0, kS = 1, kC = 2 };
  const double gx = g[0], gy = g[1], gz = g[2];
  P.setZero();
  // g . Rz(q1) = [gx c1 + gy s1, gy c1 - gx s1, gz]; with Rx(q2) on the right,
  // [., (.) c2 + gz s2, -(.) s2 + gz c2] for the middle component.
  P(index(kC, kOne, 0), 0) = gy;  // v0y
  P(index(kS, kOne, 0), 0) = -gx;
  for (int c = 0; c < 2; ++c) {  // v1 (c = 0) and v2 (times q3, c = 1)
    const int x = 1 + 3 * c, y = 2 + 3 * c, z = 3 + 3 * c;
    P(index(kC, kOne, c), x) = gx;
    P(index(kS, kOne, c), x) = gy;
    P(index(kC, kC, c), y) = gy;
    P(index(kS, kC, c), y) = -gx;
    P(index(kOne, kS, c), y) = gz;
    P(index(kC, kS, c), z) = -gy;
    P(index(kS, kS, c), z) = gx;
    P(index(kOne, kC, c), z) = gz;
  }
}

double compute_rigid_body_potential(const Eigen::Vector3d& g, const Eigen::Matrix<double, kGravityMoments, 1>& v,
                                    const double* q) {
  const double c1 = std::cos(q[0]), s1 = std::sin(q[0]), c2 = std::cos(q[1]), s2 = std::sin(q[1]);
  const Eigen::Vector3d u(g[0] * c1 + g[1] * s1, g[1] * c1 - g[0] * s1, g[2]);  // (Rz(q1)^T g)
  const Eigen::Vector3d w = Eigen::Vector3d(v[1], v[2], v[3]) + q[2] * Eigen::Vector3d(v[4], v[5], v[6]);
  const Eigen::Vector3d Rw(w[0], c2 * w[1] - s2 * w[2], s2 * w[1] + c2 * w[2]);  // Rx(q2) w
  return u[1] * v[0] + u.dot(Rw);
}

}  // namespace rcm::dynamics
