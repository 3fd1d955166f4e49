#pragma once
// Small synthetic free-space recordings for the torque-model tests: a yaw /
// pitch / insertion arm with gravity, configuration-dependent inertia and LuGre
// friction (so the holding torque at rest depends on the approach direction),
// moving along band-limited trajectories with pauses.

#include <Eigen/Core>
#include <cmath>
#include <random>

#include "rcm/io/recording.hpp"

namespace rcm::test {

struct SyntheticArmOptions {
  double duration_s = 60.0;
  double rate_hz = 200.0;
  unsigned seed = 7;
  double effort_noise = 0.002;  // relative to each joint's friction level
  bool pauses = true;
};

// The arm itself: gravity of a tilted yaw/pitch/insertion arm, configuration-
// dependent inertia, and LuGre friction whose bristle state z is the memory.
struct SyntheticArm {
  static constexpr int N = 3;
  // LuGre: sigma0 (bristle stiffness), Coulomb, static, Stribeck velocity, viscous.
  double Fc[N] = {0.05, 0.06, 0.4}, Fs[N] = {0.07, 0.08, 0.55}, vs[N] = {0.02, 0.02, 0.005};
  double s0[N] = {0.05 / 2e-3, 0.06 / 2e-3, 0.4 / 2e-4}, s2[N] = {0.03, 0.04, 0.8};
  double z[N] = {0, 0, 0};
  double F[N] = {0, 0, 0};  // friction after the last advance_friction

  // LuGre bristle state over dt at velocity qd, exact exponential update at constant velocity.
  void advance_friction(const double* qd, double dt) {
    for (int j = 0; j < N; ++j) {
      const double v = qd[j];
      const double g = Fc[j] + (Fs[j] - Fc[j]) * std::exp(-(v / vs[j]) * (v / vs[j]));
      const double zss = v == 0 ? z[j] : g / s0[j] * (v > 0 ? 1 : -1);
      z[j] = zss + (z[j] - zss) * std::exp(-s0[j] * std::abs(v) * dt / g);
      F[j] = s0[j] * z[j] + s2[j] * v;
    }
  }
  // Noise-free joint torque at (q, qdd) with the current friction.
  void compute_effort(const double* q, const double* qdd, double* tau) const {
    const double s1 = std::sin(q[0]), c1 = std::cos(q[0]), sn2 = std::sin(q[1]), c2 = std::cos(q[1]);
    const double m3 = 0.3, g0 = 9.81;
    // Potential: U = m3 g (q3 - 0.1) c1 c2 + 0.4 s2 c1 + 0.1 s1 (a tilted base).
    const double tau_g[N] = {-m3 * g0 * (q[2] - 0.1) * s1 * c2 - 0.4 * sn2 * s1 + 0.1 * c1,
                             -m3 * g0 * (q[2] - 0.1) * c1 * sn2 + 0.4 * c2 * c1, m3 * g0 * c1 * c2};
    const double inertia[N] = {0.02 + m3 * q[2] * q[2], 0.02 + m3 * q[2] * q[2], m3};
    for (int j = 0; j < N; ++j) tau[j] = inertia[j] * qdd[j] + tau_g[j] + F[j];
  }
};

inline Recording make_synthetic_free_space(const SyntheticArmOptions& o = {}) {
  std::mt19937 rng(o.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  constexpr int N = 3, K = 4;
  const double center[N] = {0.0, 0.0, 0.13}, amp[N] = {0.5, 0.4, 0.04};
  double w[N][K], ph[N][K], a[N][K];
  for (int j = 0; j < N; ++j)
    for (int k = 0; k < K; ++k) {
      w[j][k] = 2 * M_PI * (0.1 + 0.5 * uni(rng));
      ph[j][k] = 2 * M_PI * uni(rng);
      a[j][k] = amp[j] / K * (0.5 + uni(rng));
    }
  SyntheticArm arm;

  const int sub = 5;
  const double dt = 1.0 / (o.rate_hz * sub);
  const auto T = static_cast<Eigen::Index>(o.duration_s * o.rate_hz);
  Recording r;
  r.source = "synthetic";
  r.time.resize(T);
  r.position.resize(T, N);
  r.velocity.resize(T, N);
  r.effort.resize(T, N);
  double s = 0.0, t = 0.0;
  // Gate: move for 2-6 s, hold for 0.5-2 s, raised-cosine transitions of 0.4 s.
  double phase_end = 3.0;
  bool moving = true;
  double gate = 1.0, gate_rate = 0.0;
  for (Eigen::Index i = 0; i < T; ++i) {
    double q[N], qd[N], qdd[N], tau[N];
    for (int k = 0; k < sub; ++k) {
      t += dt;
      if (o.pauses && t > phase_end) {
        moving = !moving;
        phase_end = t + (moving ? 2.0 + 4.0 * uni(rng) : 0.5 + 1.5 * uni(rng));
      }
      const double target = (!o.pauses || moving) ? 1.0 : 0.0;
      const double new_gate = gate + std::clamp(target - gate, -dt / 0.4, dt / 0.4);
      gate_rate = (new_gate - gate) / dt;
      gate = new_gate;
      s += gate * dt;
      for (int j = 0; j < N; ++j) {
        double p = center[j], dp = 0, ddp = 0;
        for (int m = 0; m < K; ++m) {
          p += a[j][m] * std::sin(w[j][m] * s + ph[j][m]);
          dp += a[j][m] * w[j][m] * std::cos(w[j][m] * s + ph[j][m]);
          ddp -= a[j][m] * w[j][m] * w[j][m] * std::sin(w[j][m] * s + ph[j][m]);
        }
        q[j] = p;
        qd[j] = dp * gate;
        qdd[j] = ddp * gate * gate + dp * gate_rate;
      }
      arm.advance_friction(qd, dt);
    }
    arm.compute_effort(q, qdd, tau);
    r.time(i) = static_cast<double>(i) / o.rate_hz;
    for (int j = 0; j < N; ++j) {
      r.position(i, j) = q[j];
      r.velocity(i, j) = qd[j];
      r.effort(i, j) = tau[j] + o.effort_noise * arm.Fc[j] * 10 * gauss(rng);
    }
  }
  return r;
}

}  // namespace rcm::test
