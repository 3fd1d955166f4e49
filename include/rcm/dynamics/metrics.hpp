#pragma once
// Table II of the paper: per-joint RMSE and NRMSE = RMSE / (max - min of the
// measured torque on the evaluated data) x 100.

#include <Eigen/Core>
#include <limits>
#include <nlohmann/json.hpp>
#include <vector>

#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/recording.hpp"

namespace rcm::dynamics {


struct JointTorqueError {
  int index = 0;               // 1-based joint number
  double rmse = 0.0;           // N m (N for the insertion joint)
  double nrmse_percent = 0.0;  // RMSE / (max - min) x 100
  double range = 0.0;          // max - min of the measured torque
  // The spread of the error's bulk (compute_huber_scale, clipped at 3 of
  // itself, as the online estimate weighs its innovations). Rare spikes (a
  // servo setpoint late by a period, a bump) can hold most of the RMSE and
  // leave this alone. NaN from TorqueErrorAccumulator, which keeps no samples.
  double robust_sd = std::numeric_limits<double>::quiet_NaN();
};

// Huber's scale of the errors e about zero (his "proposal 2"): the s with
// mean(min(e^2, c^2 s^2)) = kappa(c) s^2, kappa(c) = E[min(Z^2, c^2)] for a
// standard normal Z, so that s is the standard deviation of normal errors
// and a share of spikes moves it by about their share, not their size. A bias
// counts (the scale is about zero, not the median). 0 for no error.
double compute_huber_scale(const Eigen::Ref<const Eigen::VectorXd>& e, double c = 3.0);

// measured and predicted: T x M with the same shape; throws std::invalid_argument otherwise.
std::vector<JointTorqueError> compute_torque_errors(const Eigen::MatrixXd& measured,
                                                    const Eigen::MatrixXd& predicted);

// The same over rows given in parts (recordings read in chunks), in memory
// that does not grow with their number: the sums of squares run sample by
// sample, as compute_torque_errors() sums them.
class TorqueErrorAccumulator {
 public:
  explicit TorqueErrorAccumulator(int joints);
  // measured and predicted: rows x joints; throws std::invalid_argument otherwise.
  void add(const Eigen::MatrixXd& measured, const Eigen::MatrixXd& predicted);
  // Throws std::invalid_argument when no row was added.
  std::vector<JointTorqueError> get_errors() const;

 private:
  std::vector<double> squares_, min_, max_;
  std::size_t rows_ = 0;
};

// Runs the model over every recording (state reset at each start; predict_torque
// or, in streaming mode, predict_torque_streaming) and pools the samples of all
// recordings, from `first_fraction` of each recording on (0 = all).
std::vector<JointTorqueError> evaluate_torque_model(const TorqueModel& model,
                                                    const std::vector<Recording>& recordings,
                                                    double first_fraction = 0.0,
                                                    PredictionMode mode = PredictionMode::batch);

// {"joints": [{"index": 1, "rmse": r, "nrmse_percent": p}, ...]} (docs/formats.md).
nlohmann::json to_json(const std::vector<JointTorqueError>& errors);

}  // namespace rcm::dynamics
