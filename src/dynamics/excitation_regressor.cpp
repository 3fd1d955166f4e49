// The conditioning of the linear model's regressor over a motion
// (excitation.hpp, RegressorConditioning): what `rcm excite` optimises and
// reports, and what a recorded motion can be compared with.
#include <algorithm>
#include <cmath>
#include <limits>

#include "rcm/dynamics/excitation.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "gram_conditioning.hpp"
#include "gravity_terms.hpp"

namespace rcm::dynamics {

namespace {
using detail::G;
static_assert(G == 17, "RegressorConditioning::kColumns counts 17 gravity terms");
// Index of joint j's friction block column b (0 armature, 1 viscous, 2 Coulomb, 3 offset).
constexpr int block_column(int j, int b) { return G + kInertiaTerms + 4 * j + b; }
}  // namespace

RegressorConditioning::RegressorConditioning(const Eigen::Vector3d& dahl_displacement)
    : dahl_displacement_(dahl_displacement) {
  reset();
}

void RegressorConditioning::reset() {
  z_.setZero();
  q_last_.setZero();
  has_last_ = false;
  samples_ = 0;
  gram_.setZero();
}

void RegressorConditioning::compute_dahl_step(const Eigen::Vector3d& q) {
  if (has_last_)
    for (int j = 0; j < 3; ++j) z_[j] = compute_dahl_state(z_[j], q[j] - q_last_[j], dahl_displacement_[j]);
  q_last_ = q;
  has_last_ = true;
}

void RegressorConditioning::add_sample(const Eigen::Vector3d& q, const Eigen::Vector3d& qd,
                                       const Eigen::Vector3d& qdd) {
  compute_dahl_step(q);
  LinearTorqueModel::compute_gravity_regressor(q.data(), Yg_);
  compute_inertia_regressor(q.data(), qd.data(), qdd.data(), Yi_);
  rows_.setZero();
  rows_.leftCols<G>() = Yg_;
  rows_.middleCols<kInertiaTerms>(G) = Yi_;
  for (int j = 0; j < 3; ++j) {
    rows_(j, block_column(j, 0)) = qdd[j];
    rows_(j, block_column(j, 1)) = qd[j];
    rows_(j, block_column(j, 2)) = z_[j];
    // The insertion's offset is the gravity regressor's q3 column: left out.
    if (j < 2) rows_(j, block_column(j, 3)) = 1.0;
  }
  // Lower triangle only: what the eigensolver reads.
  gram_.selfadjointView<Eigen::Lower>().rankUpdate(rows_.transpose());
  ++samples_;
}


double RegressorConditioning::get_condition_number() const {
  double lo = 0.0, hi = 0.0;
  if (!detail::get_scaled_extreme_eigenvalues(gram_, lo, hi) || !(lo > 0.0)) return std::numeric_limits<double>::infinity();
  return std::sqrt(hi / lo);
}

double RegressorConditioning::get_log_condition_number() const {
  constexpr double kFloor = 1e-20;
  double lo = 0.0, hi = 0.0;
  if (!detail::get_scaled_extreme_eigenvalues(gram_, lo, hi)) return 0.5 * -std::log(kFloor);
  return 0.5 * std::log(hi / std::max(lo, kFloor * hi));
}

Eigen::Vector3d get_excitation_dahl_displacement(const ExcitationLimits& limits) {
  return 3e-4 * (limits.position_max - limits.position_min);
}

double compute_regressor_condition_number(const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity,
                                          const Eigen::MatrixXd& acceleration,
                                          const Eigen::Vector3d& dahl_displacement) {
  if (position.cols() < 3 || velocity.cols() < 3 || acceleration.cols() < 3 || velocity.rows() != position.rows() ||
      acceleration.rows() != position.rows())
    throw std::invalid_argument("compute_regressor_condition_number: T x >= 3 positions, velocities, accelerations");
  RegressorConditioning conditioning(dahl_displacement);
  for (Eigen::Index t = 0; t < position.rows(); ++t)
    conditioning.add_sample(position.row(t).head<3>().transpose(), velocity.row(t).head<3>().transpose(),
                            acceleration.row(t).head<3>().transpose());
  return conditioning.get_condition_number();
}

std::vector<int> count_velocity_reversals(const Eigen::MatrixXd& velocity, double floor_fraction) {
  std::vector<int> out(static_cast<std::size_t>(velocity.cols()), 0);
  for (Eigen::Index j = 0; j < velocity.cols(); ++j) {
    if (velocity.rows() == 0) continue;
    const double floor = floor_fraction * velocity.col(j).cwiseAbs().maxCoeff();
    int last = 0;
    for (Eigen::Index t = 0; t < velocity.rows(); ++t) {
      const double v = velocity(t, j);
      const int sign = v > floor ? 1 : (v < -floor ? -1 : 0);
      if (sign == 0) continue;
      if (last != 0 && sign != last) ++out[static_cast<std::size_t>(j)];
      last = sign;
    }
  }
  return out;
}

}  // namespace rcm::dynamics
