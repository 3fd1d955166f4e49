#pragma once
// Reference motions of the simulated bench: teleoperation-like paths (smooth,
// band-limited, with pauses), quintic point-to-point moves and holds, chained
// into one piecewise reference that the position controller tracks.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "rcm/kinematics/psm_model.hpp"
#include "rcm/sim/sim_config.hpp"

namespace rcm::sim {

struct ReferenceSample {
  Eigen::Vector3d q = Eigen::Vector3d::Zero();
  Eigen::Vector3d qd = Eigen::Vector3d::Zero();
  Eigen::Vector3d qdd = Eigen::Vector3d::Zero();
};

// A path in its own time, t >= 0.
class ReferencePath {
 public:
  virtual ~ReferencePath() = default;
  virtual ReferenceSample evaluate(double t) const = 0;
};

// q_j(t) = q0_j + A_j tanh(u_j(tau(t))), u_j a sum of sinusoids with random
// frequencies in [min, max] Hz and u_j(0) = 0; tau(t) is a time warp whose rate
// falls smoothly to zero in pauses, so the robot stops wherever it is. Starts at
// q0 at rest. Smooth (C2) everywhere; never leaves q0 +- A.
class TeleopPath : public ReferencePath {
 public:
  TeleopPath(const TrajectoryParams& params, const Eigen::Vector3d& q0, std::uint64_t seed,
             double duration_s);
  ReferenceSample evaluate(double t) const override;

 private:
  struct Pause { double a, b, r; double lost_before; };
  double warp(double t, double* rate, double* rate_dot) const;
  using Harmonics = std::array<std::vector<std::array<double, 3>>, 3>;  // per joint: amplitude, omega, phase
  // u of one segment's draw and its first two derivatives in warped time.
  void evaluate_segment(std::size_t segment, int joint, double tau, double decay, double* u, double* du,
                        double* ddu) const;
  Eigen::Vector3d q0_, amplitude_;
  std::vector<Harmonics> segments_;
  double segment_s_ = 60.0, blend_s_ = 4.0;
  std::vector<Pause> pauses_;
};

// A periodic excitation (the dVRK's dynamics-identification runs): per joint
// f_j(t) = sum_k a_jk sin(k w t) + b_jk (cos(k w t) - 1), w = 2 pi / period,
// k = 1..harmonics, random coefficients falling as 1/k and scaled so that
// sum_k |a_jk| + 2 |b_jk| = A_j; q_j = q0_j + r(t) f_j(t) with r a C2 ramp from 0
// to 1 over ramp_s. Starts at q0 at rest, never leaves q0 +- A, and after the
// ramp repeats exactly every period.
class ExcitationPath : public ReferencePath {
 public:
  ExcitationPath(const TrajectoryParams& params, const Eigen::Vector3d& q0, std::uint64_t seed);
  ReferenceSample evaluate(double t) const override;

 private:
  Eigen::Vector3d q0_;
  double omega_ = 1.0, ramp_s_ = 1.0;
  std::array<std::vector<std::array<double, 2>>, 3> coeff_;  // per joint, per harmonic: a, b
};

// A path through given samples (a joint trajectory file, JointTrajectory),
// joints 1-3: cubic Hermite interpolation of position and velocity between
// samples, so position and velocity are continuous and the acceleration is
// piecewise linear. Its time starts at the first sample; before it and after
// the last sample the path holds that sample's position at rest.
class SampledPath : public ReferencePath {
 public:
  SampledPath(const Eigen::VectorXd& time, const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity);
  ReferenceSample evaluate(double t) const override;
  double duration_s() const { return time_.size() ? time_[time_.size() - 1] : 0.0; }

 private:
  Eigen::VectorXd time_;  // from 0
  Eigen::MatrixXd q_, qd_;  // samples x 3
};

// A trajectory file (rcm/io/joint_trajectory.hpp) as a SampledPath; a
// position of joints 1-3 outside the robot's joint limits is an InputError
// naming the file, line and column.
std::shared_ptr<const SampledPath> load_sampled_path(const std::filesystem::path& path, const PsmModel& robot);

// Fifth-order polynomial from (q, qd, qdd) to (q1, 0, 0) over T seconds.
struct QuinticMove {
  double t0 = 0.0, duration = 1.0;
  Eigen::Matrix<double, 3, 6> coeff = Eigen::Matrix<double, 3, 6>::Zero();
  static QuinticMove make(double t0, double duration, const ReferenceSample& from,
                          const Eigen::Vector3d& to);
  ReferenceSample evaluate(double t) const;
};

// Pieces in time order; each covers [t_start, next t_start). A path piece is
// evaluated at (t - t_start); before the first piece the first one is held.
class ReferenceTrajectory {
 public:
  void add_path(double t_start, std::shared_ptr<const ReferencePath> path);
  void add_move(double t_start, double duration, const Eigen::Vector3d& to);  // from the reference at t_start
  void add_hold(double t_start, const Eigen::Vector3d& q);
  ReferenceSample evaluate(double t) const;

 private:
  struct Piece {
    double t_start;
    int kind;  // 0 path, 1 move, 2 hold
    std::shared_ptr<const ReferencePath> path;
    QuinticMove move;
    Eigen::Vector3d hold;
  };
  std::vector<Piece> pieces_;
};

}  // namespace rcm::sim
