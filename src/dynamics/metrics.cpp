#include "rcm/dynamics/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcm/dynamics/torque_model.hpp"

namespace rcm::dynamics {

TorqueErrorAccumulator::TorqueErrorAccumulator(int joints)
    : squares_(static_cast<std::size_t>(joints), 0.0),
      min_(static_cast<std::size_t>(joints), std::numeric_limits<double>::infinity()),
      max_(static_cast<std::size_t>(joints), -std::numeric_limits<double>::infinity()) {}

void TorqueErrorAccumulator::add(const Eigen::MatrixXd& measured, const Eigen::MatrixXd& predicted) {
  if (measured.rows() != predicted.rows() || measured.cols() != predicted.cols() ||
      measured.cols() != static_cast<Eigen::Index>(squares_.size()))
    throw std::invalid_argument("compute_torque_errors: measured and predicted differ in shape");
  for (Eigen::Index j = 0; j < measured.cols(); ++j) {
    const auto k = static_cast<std::size_t>(j);
    for (Eigen::Index t = 0; t < measured.rows(); ++t) {
      const double e = measured(t, j) - predicted(t, j);
      squares_[k] += e * e;
      min_[k] = std::min(min_[k], measured(t, j));
      max_[k] = std::max(max_[k], measured(t, j));
    }
  }
  rows_ += static_cast<std::size_t>(measured.rows());
}

std::vector<JointTorqueError> TorqueErrorAccumulator::get_errors() const {
  if (rows_ == 0) throw std::invalid_argument("compute_torque_errors: no samples");
  std::vector<JointTorqueError> errors;
  for (std::size_t j = 0; j < squares_.size(); ++j) {
    JointTorqueError e;
    e.index = static_cast<int>(j) + 1;
    e.rmse = std::sqrt(squares_[j] / static_cast<double>(rows_));
    e.range = max_[j] - min_[j];
    e.nrmse_percent = e.range > 0 ? 100.0 * e.rmse / e.range : std::numeric_limits<double>::infinity();
    errors.push_back(e);
  }
  return errors;
}

double compute_huber_scale(const Eigen::Ref<const Eigen::VectorXd>& e, double c) {
  if (!(c > 0)) throw std::invalid_argument("compute_huber_scale: c must be > 0");
  if (e.size() == 0) throw std::invalid_argument("compute_huber_scale: no samples");
  // kappa(c) = E[min(Z^2, c^2)] = (2 Phi(c) - 1) - 2 c phi(c) + c^2 P(|Z| > c).
  const double tail = std::erfc(c / std::sqrt(2.0));
  const double kappa = (1.0 - tail) - 2.0 * c * std::exp(-0.5 * c * c) / std::sqrt(2.0 * M_PI) + c * c * tail;
  // The fixed point from the RMS down: each step is the root mean square of
  // the errors clipped at c times the last scale, and the map is monotone.
  double s = std::sqrt(e.squaredNorm() / static_cast<double>(e.size()) / kappa);
  for (int it = 0; it < 200 && s > 0; ++it) {
    const double clip = c * s;
    const double next =
        std::sqrt(e.array().square().min(clip * clip).sum() / static_cast<double>(e.size()) / kappa);
    const bool done = std::abs(next - s) <= 1e-10 * s;
    s = next;
    if (done) break;
  }
  return s;
}

std::vector<JointTorqueError> compute_torque_errors(const Eigen::MatrixXd& measured,
                                                    const Eigen::MatrixXd& predicted) {
  TorqueErrorAccumulator accumulator(static_cast<int>(measured.cols()));
  accumulator.add(measured, predicted);
  std::vector<JointTorqueError> errors = accumulator.get_errors();
  for (Eigen::Index j = 0; j < measured.cols(); ++j)
    errors[static_cast<std::size_t>(j)].robust_sd = compute_huber_scale(measured.col(j) - predicted.col(j));
  return errors;
}

std::vector<JointTorqueError> evaluate_torque_model(const TorqueModel& model,
                                                    const std::vector<Recording>& recordings,
                                                    double first_fraction, PredictionMode mode) {
  TorqueErrorAccumulator errors(model.num_outputs());
  const int M = model.num_outputs();
  for (const Recording& r : recordings) {
    const auto T = static_cast<Eigen::Index>(r.num_samples());
    const auto start = static_cast<Eigen::Index>(std::floor(first_fraction * static_cast<double>(T)));
    const Eigen::MatrixXd p = predict_torque(model, r, mode);
    const Eigen::Index n = p.rows() - start;
    errors.add(r.effort.leftCols(M).bottomRows(n), p.bottomRows(n));
  }
  return errors.get_errors();
}

nlohmann::json to_json(const std::vector<JointTorqueError>& errors) {
  nlohmann::json joints = nlohmann::json::array();
  for (const auto& e : errors)
    joints.push_back({{"index", e.index}, {"rmse", e.rmse}, {"nrmse_percent", e.nrmse_percent}, {"range", e.range}});
  return {{"joints", joints}};
}

}  // namespace rcm::dynamics
