#include "rcm/dynamics/payload.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/rigid_body.hpp"
#include "gram_conditioning.hpp"
#include "rigid_body_fit.hpp"
#include "gravity_terms.hpp"

namespace rcm::dynamics {

namespace {

using detail::G;

// The 17 gravity coefficients of the four payload terms: compute_gravity_moment_map
// of the moments v1 = h, v2 = m e.
Eigen::Matrix<double, G, kPayloadTerms> compute_payload_coefficient_map(const Eigen::Vector3d& g,
                                                                        const Eigen::Vector3d& e) {
  Eigen::Matrix<double, G, kGravityMoments> P;
  compute_gravity_moment_map(g, P);
  Eigen::Matrix<double, kGravityMoments, kPayloadTerms> S = Eigen::Matrix<double, kGravityMoments, kPayloadTerms>::Zero();
  S(1, 0) = S(2, 1) = S(3, 2) = 1.0;  // v1 = h
  S.block<3, 1>(4, 3) = e;            // v2 = m e
  return P * S;
}

// The refit's terms: the seven moments of the rigid links' potential under a
// gravity direction (rigid_body.hpp: v0_y, v1, v2) and the payload's inertia
// about the yaw and pitch axes, the change of those joints' armatures.
constexpr int kRefitTerms = kGravityMoments + 2;
const char* const kTermNames[kRefitTerms] = {"v0_y", "v1_x", "v1_y", "v1_z", "v2_x",
                                             "v2_y", "v2_z", "inertia_yaw", "inertia_pitch"};
// The columns the normal equations are summed over: the 17 generic potential
// terms and the two armatures.
constexpr int kColumns = G + 2;
using Reduction = Eigen::Matrix<double, kColumns, kRefitTerms>;

Reduction compute_reduction(const Eigen::Vector3d& g) {
  Eigen::Matrix<double, G, kGravityMoments> P;
  compute_gravity_moment_map(g, P);
  Reduction T = Reduction::Zero();
  T.topLeftCorner<G, kGravityMoments>() = P;
  T.bottomRightCorner<2, 2>().setIdentity();
  return T;
}

}  // namespace

void compute_payload_regressor(const Eigen::Vector3d& g, const Eigen::Vector3d& e, const double* q,
                               Eigen::Matrix<double, 3, kPayloadTerms>& Y) {
  Eigen::Matrix<double, 3, G> Yg;
  LinearTorqueModel::compute_gravity_regressor(q, Yg);
  Y.noalias() = Yg * compute_payload_coefficient_map(g, e);
}

Eigen::Vector3d get_instrument_axis(const LinearTorqueParameters& p) {
  if (p.gravity_direction.size() != 3 || p.gravity.size() != G)
    throw InputError(InputLocation::plain("", "free-space model"),
                     "expected a linear model with the rigid-body structure (its gravity direction); this one has the "
                     "generic potential, whose terms do not say where a payload's weight acts");
  Eigen::Matrix<double, G, kGravityMoments> P;
  compute_gravity_moment_map(p.gravity_direction, P);
  const Eigen::Matrix<double, kGravityMoments, 1> v = P.colPivHouseholderQr().solve(p.gravity);
  const Eigen::Vector3d v2 = v.tail<3>();
  // The sliding body's weight against the whole potential's scale: a model
  // whose v2 is lost in rounding has no axis to give.
  if (!(v2.norm() > 1e-6 * std::max(v.norm(), 1e-300)))
    throw InputError(InputLocation::plain("", "free-space model"),
                     "expected a potential with a sliding body (its weight along the instrument), to align the "
                     "payload with; this one has none");
  return v2.normalized();
}

nlohmann::json PayloadRefit::to_json() const {
  nlohmann::json j;
  j["payload"] = {{"first_moment_n_m", {payload[0], payload[1], payload[2]}},
                  {"weight_n", payload[3]},
                  {"inertia_kg_m2", {inertia[0], inertia[1]}}};
  j["rms_before"] = {rms_before[0], rms_before[1], rms_before[2]};
  j["rms_after"] = {rms_after[0], rms_after[1], rms_after[2]};
  j["instrument_axis"] = {instrument_axis[0], instrument_axis[1], instrument_axis[2]};
  j["gravity_direction"] = {gravity_direction[0], gravity_direction[1], gravity_direction[2]};
  j["reciprocal_condition"] = reciprocal_condition;
  j["samples"] = samples;
  return j;
}

PayloadRefit refit_payload(const LinearTorqueModel& model, const std::vector<Recording>& recordings,
                           const PayloadRefitOptions& options) {
  const LinearTorqueParameters& p = model.parameters();
  if (model.num_outputs() < 3)
    throw InputError(InputLocation::plain("", "free-space model"),
                     fmt::format("expected a model of joints 1-3 (yaw, pitch, insertion); this one predicts {}",
                                 model.num_outputs()));
  const Eigen::Vector3d e = get_instrument_axis(p);
  // The moments of the model's potential, against which the payload's are the change.
  Eigen::Matrix<double, G, kGravityMoments> P_model;
  compute_gravity_moment_map(p.gravity_direction, P_model);
  const Eigen::Matrix<double, kGravityMoments, 1> v_model = P_model.colPivHouseholderQr().solve(p.gravity);

  // Normal equations of the residual of the model without its potential,
  // r = effort - model + potential, on the 17 potential terms and the yaw and
  // pitch armatures' columns, per joint (A = sum over joints of A_j), pooled
  // over every recording: they also give each joint's residual after the
  // refit, |r_j - Y_j x|^2 = |r_j|^2 - 2 x.b_j + x' A_j x, without a second pass.
  using Normal = Eigen::Matrix<double, kColumns, kColumns>;
  using Terms = Eigen::Matrix<double, kColumns, 1>;
  std::array<Normal, 3> A_joint;
  std::array<Terms, 3> b_joint;
  std::array<double, 3> yy_joint{};
  for (int j = 0; j < 3; ++j) {
    A_joint[j].setZero();
    b_joint[j].setZero();
  }
  Eigen::Vector3d sum_sq = Eigen::Vector3d::Zero();  // of effort - model
  std::size_t samples = 0;
  Eigen::Matrix<double, 3, G> Yg;
  for (const Recording& rec : recordings) {
    if (rec.num_joints() < 3)
      throw InputError(InputLocation::plain(rec.source, "position"),
                       fmt::format("expected joints 1-3 (yaw, pitch, insertion); the recording has {}", rec.num_joints()));
    const Eigen::MatrixXd predicted = predict_torque(model, rec);
    // The armature's column is whatever qddot estimate the model multiplies it
    // by: the change of the prediction when the armature grows by one.
    Eigen::MatrixXd qdd(predicted.rows(), 2);
    for (int j = 0; j < 2; ++j) {
      LinearTorqueParameters unit = p;
      unit.armature[j] += 1.0;
      qdd.col(j) = predict_torque(LinearTorqueModel(model.info(), std::move(unit)), rec).col(j) - predicted.col(j);
    }
    Eigen::Matrix<double, 3, kColumns> Y = Eigen::Matrix<double, 3, kColumns>::Zero();
    for (Eigen::Index t = 0; t < predicted.rows(); ++t) {
      // A recording's matrices are column-major: joint values of one sample are not contiguous.
      const double q[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
      LinearTorqueModel::compute_gravity_regressor(q, Yg);
      Y.leftCols<G>() = Yg;
      Y(0, G) = qdd(t, 0);
      Y(1, G + 1) = qdd(t, 1);
      const Eigen::Vector3d potential = Yg * p.gravity;
      for (int j = 0; j < 3; ++j) {
        const double residual = rec.effort(t, j) - predicted(t, j);
        const double r = residual + potential[j];
        A_joint[j].noalias() += Y.row(j).transpose() * Y.row(j);
        b_joint[j].noalias() += r * Y.row(j).transpose();
        yy_joint[j] += r * r;
        sum_sq[j] += residual * residual;
      }
    }
    samples += static_cast<std::size_t>(predicted.rows());
  }
  if (samples == 0)
    throw InputError(InputLocation::plain("", "recordings"), "expected at least one sample with the payload");
  const Normal A = A_joint[0] + A_joint[1] + A_joint[2];
  const Terms b = b_joint[0] + b_joint[1] + b_joint[2];
  const double yy = yy_joint[0] + yy_joint[1] + yy_joint[2];

  // Whether the motion tells the nine terms apart: at the model's direction
  // before the search (an arm at rest is refused before anything is fitted),
  // and at the direction found.
  auto check_conditioning = [&](const Reduction& T) {
    const Eigen::Matrix<double, kRefitTerms, kRefitTerms> Ar = T.transpose() * A * T;
    double lo = 0.0, hi = 0.0;
    Eigen::Index worst = 0;
    const bool nonzero = detail::get_scaled_extreme_eigenvalues(Ar, lo, hi, &worst);
    const double rcond = nonzero ? lo / hi : 0.0;
    if (!(rcond >= options.min_reciprocal_condition)) {
      if (nonzero) worst = detail::get_weakest_column(Ar);
      throw InputError(InputLocation::plain(recordings.front().source, "position"),
                       fmt::format("expected motion that identifies the payload: the recordings leave its term {} "
                                   "undetermined (reciprocal condition {:.2g}); move yaw, pitch and insertion over a "
                                   "wider range",
                                   kTermNames[worst], rcond));
    }
    return rcond;
  };
  check_conditioning(compute_reduction(p.gravity_direction));

  // The gravity direction is searched again with the payload: on one path it
  // is weakly identified, and the payload's torque depends on it.
  struct Solution {
    double loss = 0.0;
    Eigen::Matrix<double, kRefitTerms, 1> x;
    Eigen::Vector3d g;
  };
  Solution best = detail::search_gravity_direction([&](const Eigen::Vector3d& g) {
    const Reduction T = compute_reduction(g);
    const Eigen::Matrix<double, kRefitTerms, kRefitTerms> Ar = T.transpose() * A * T;
    const Eigen::Matrix<double, kRefitTerms, 1> br = T.transpose() * b;
    Solution s;
    s.x = Ar.ldlt().solve(br);
    s.loss = yy - 2.0 * s.x.dot(br) + s.x.dot(Ar * s.x);
    s.g = g;
    return s;
  });
  // g and -g with opposite moments are one potential: the one nearer the
  // model's, so that the moments compare with its own.
  if (best.g.dot(p.gravity_direction) < 0) {
    best.g = -best.g;
    best.x.head<kGravityMoments>() = -best.x.head<kGravityMoments>();
  }
  const Reduction T = compute_reduction(best.g);

  PayloadRefit out;
  const Eigen::Matrix<double, kGravityMoments, 1> dv = best.x.head<kGravityMoments>() - v_model;
  out.payload << dv.segment<3>(1), dv.tail<3>().dot(e);
  out.inertia = best.x.tail<2>();
  out.gravity_direction = best.g;
  out.instrument_axis = e;
  out.reciprocal_condition = check_conditioning(T);
  out.samples = samples;
  LinearTorqueParameters refit = p;
  const Terms theta = T * best.x;
  refit.gravity = theta.head<G>();
  refit.gravity_direction = best.g;
  refit.armature.head<2>() += out.inertia;
  for (int j = 0; j < 3; ++j) {
    const double after = yy_joint[j] - 2.0 * theta.dot(b_joint[j]) + theta.dot(A_joint[j] * theta);
    out.rms_before[j] = std::sqrt(sum_sq[j] / static_cast<double>(samples));
    out.rms_after[j] = std::sqrt(std::max(after, 0.0) / static_cast<double>(samples));
  }

  TorqueModelInfo info = model.info();
  info.training["payload_refit"] = out.to_json();
  out.model = std::make_unique<LinearTorqueModel>(std::move(info), std::move(refit));
  return out;
}

}  // namespace rcm::dynamics
