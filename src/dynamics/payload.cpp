#include "rcm/dynamics/payload.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/rigid_body.hpp"

namespace rcm::dynamics {

namespace {

constexpr int G = LinearTorqueModel::kGravityTerms;

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

const char* const kTermNames[kPayloadTerms] = {"h_x", "h_y", "h_z", "m"};

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
  j["payload"] = {{"first_moment_n_m", {payload[0], payload[1], payload[2]}}, {"weight_n", payload[3]}};
  j["rms_before"] = {rms_before[0], rms_before[1], rms_before[2]};
  j["rms_after"] = {rms_after[0], rms_after[1], rms_after[2]};
  j["instrument_axis"] = {instrument_axis[0], instrument_axis[1], instrument_axis[2]};
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
  const Eigen::Matrix<double, G, kPayloadTerms> B = compute_payload_coefficient_map(p.gravity_direction, e);

  // Normal equations of the residual r = effort - model on the payload terms,
  // pooled over every recording.
  Eigen::Matrix<double, kPayloadTerms, kPayloadTerms> A = Eigen::Matrix<double, kPayloadTerms, kPayloadTerms>::Zero();
  Eigen::Matrix<double, kPayloadTerms, 1> b = Eigen::Matrix<double, kPayloadTerms, 1>::Zero();
  Eigen::Vector3d sum_sq = Eigen::Vector3d::Zero();
  std::size_t samples = 0;
  std::vector<Eigen::MatrixXd> residuals;
  residuals.reserve(recordings.size());
  Eigen::Matrix<double, 3, G> Yg;
  for (const Recording& rec : recordings) {
    if (rec.num_joints() < 3)
      throw InputError(InputLocation::plain(rec.source, "position"),
                       fmt::format("expected joints 1-3 (yaw, pitch, insertion); the recording has {}", rec.num_joints()));
    const Eigen::MatrixXd predicted = predict_torque(model, rec);
    Eigen::MatrixXd r = rec.effort.leftCols(3) - predicted.leftCols(3);
    for (Eigen::Index t = 0; t < r.rows(); ++t) {
      // A recording's matrices are column-major: joint values of one sample are not contiguous.
      const double q[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
      LinearTorqueModel::compute_gravity_regressor(q, Yg);
      const Eigen::Matrix<double, 3, kPayloadTerms> Y = Yg * B;
      A.noalias() += Y.transpose() * Y;
      b.noalias() += Y.transpose() * r.row(t).transpose();
      sum_sq += r.row(t).transpose().cwiseAbs2();
    }
    samples += static_cast<std::size_t>(r.rows());
    residuals.push_back(std::move(r));
  }
  if (samples == 0)
    throw InputError(InputLocation::plain("", "recordings"), "expected at least one sample with the payload");

  // Scaled to unit diagonal, the normal matrix's smallest to largest eigenvalue
  // says whether the motion tells the four terms apart.
  const Eigen::Vector4d d = A.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::Matrix4d As = d.asDiagonal() * A * d.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eig(As, Eigen::EigenvaluesOnly);
  const double rcond = eig.eigenvalues()[0] / std::max(eig.eigenvalues()[3], 1e-300);
  if (!(rcond >= options.min_reciprocal_condition)) {
    // The weakest direction, named by its largest term.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> vecs(As);
    Eigen::Index worst = 0;
    vecs.eigenvectors().col(0).cwiseAbs().maxCoeff(&worst);
    throw InputError(InputLocation::plain(recordings.front().source, "position"),
                     fmt::format("expected motion that identifies the payload: the recordings leave its term {} undetermined "
                                 "(reciprocal condition {:.2g}); move pitch and insertion over a wider range",
                                 kTermNames[worst], rcond));
  }

  PayloadRefit out;
  out.payload = A.ldlt().solve(b);
  out.instrument_axis = e;
  out.reciprocal_condition = rcond;
  out.samples = samples;
  LinearTorqueParameters refit = p;
  refit.gravity += B * out.payload;
  Eigen::Vector3d sum_sq_after = Eigen::Vector3d::Zero();
  std::size_t k = 0;
  for (const Recording& rec : recordings) {
    const Eigen::MatrixXd& r = residuals[k++];
    for (Eigen::Index t = 0; t < r.rows(); ++t) {
      const double q[3] = {rec.position(t, 0), rec.position(t, 1), rec.position(t, 2)};
      LinearTorqueModel::compute_gravity_regressor(q, Yg);
      sum_sq_after += (r.row(t).transpose() - Yg * B * out.payload).cwiseAbs2();
    }
  }
  out.rms_before = (sum_sq / static_cast<double>(samples)).cwiseSqrt();
  out.rms_after = (sum_sq_after / static_cast<double>(samples)).cwiseSqrt();

  TorqueModelInfo info = model.info();
  info.training["payload_refit"] = out.to_json();
  out.model = std::make_unique<LinearTorqueModel>(std::move(info), std::move(refit));
  return out;
}

}  // namespace rcm::dynamics
