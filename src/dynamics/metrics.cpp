#include "rcm/dynamics/metrics.hpp"

#include <cmath>
#include <stdexcept>

#include "rcm/dynamics/torque_model.hpp"

namespace rcm::dynamics {

std::vector<JointTorqueError> compute_torque_errors(const Eigen::MatrixXd& measured,
                                                    const Eigen::MatrixXd& predicted) {
  if (measured.rows() != predicted.rows() || measured.cols() != predicted.cols())
    throw std::invalid_argument("compute_torque_errors: measured and predicted differ in shape");
  if (measured.rows() == 0) throw std::invalid_argument("compute_torque_errors: no samples");
  std::vector<JointTorqueError> errors;
  for (Eigen::Index j = 0; j < measured.cols(); ++j) {
    JointTorqueError e;
    e.index = static_cast<int>(j) + 1;
    e.rmse = std::sqrt((measured.col(j) - predicted.col(j)).squaredNorm() / static_cast<double>(measured.rows()));
    e.range = measured.col(j).maxCoeff() - measured.col(j).minCoeff();
    e.nrmse_percent = e.range > 0 ? 100.0 * e.rmse / e.range : std::numeric_limits<double>::infinity();
    errors.push_back(e);
  }
  return errors;
}

std::vector<JointTorqueError> evaluate_torque_model(const TorqueModel& model,
                                                    const std::vector<Recording>& recordings,
                                                    double first_fraction, PredictionMode mode) {
  Eigen::Index total = 0;
  std::vector<Eigen::Index> start(recordings.size());
  for (std::size_t r = 0; r < recordings.size(); ++r) {
    const auto T = static_cast<Eigen::Index>(recordings[r].num_samples());
    start[r] = static_cast<Eigen::Index>(std::floor(first_fraction * static_cast<double>(T)));
    total += T - start[r];
  }
  const int M = model.num_outputs();
  Eigen::MatrixXd measured(total, M), predicted(total, M);
  Eigen::Index row = 0;
  for (std::size_t r = 0; r < recordings.size(); ++r) {
    const Eigen::MatrixXd p = predict_torque(model, recordings[r], mode);
    const Eigen::Index n = p.rows() - start[r];
    predicted.middleRows(row, n) = p.bottomRows(n);
    measured.middleRows(row, n) = recordings[r].effort.leftCols(M).bottomRows(n);
    row += n;
  }
  return compute_torque_errors(measured, predicted);
}

nlohmann::json to_json(const std::vector<JointTorqueError>& errors) {
  nlohmann::json joints = nlohmann::json::array();
  for (const auto& e : errors)
    joints.push_back({{"index", e.index}, {"rmse", e.rmse}, {"nrmse_percent", e.nrmse_percent}, {"range", e.range}});
  return {{"joints", joints}};
}

}  // namespace rcm::dynamics
