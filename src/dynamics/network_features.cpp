// The network inputs that carry memory: the filtered acceleration and the
// Dahl friction states, streamed sample by sample (AccelerationFilter,
// DahlFilter) or over a whole recording (compute_*_features).
#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics {

AccelerationFilter::AccelerationFilter(const Eigen::VectorXf& filter_s, int joints)
    : tau_(filter_s.cast<double>()),
      qd_prev_(Eigen::VectorXd::Zero(joints)),
      a_(Eigen::VectorXd::Zero(filter_s.size() * joints)) {}

void AccelerationFilter::reset() {
  a_.setZero();
  started_ = false;
}

void AccelerationFilter::update(double t, const double* qd) {
  const Eigen::Index N = qd_prev_.size();
  const double dt = t - t_prev_;
  if (started_ && dt == 0.0) return;  // a repeated time stamp carries no new difference
  if (!started_ || !(dt > 0)) {
    a_.setZero();
  } else {
    for (Eigen::Index f = 0; f < tau_.size(); ++f) {
      const double alpha = dt / (tau_[f] + dt);
      for (Eigen::Index k = 0; k < N; ++k) {
        double& a = a_[f * N + k];
        a += alpha * ((qd[k] - qd_prev_[k]) / dt - a);
      }
    }
  }
  for (Eigen::Index k = 0; k < N; ++k) qd_prev_[k] = qd[k];
  t_prev_ = t;
  started_ = true;
}

DahlFilter::DahlFilter(const Eigen::VectorXf& displacement, int joints)
    : inverse_x_c_(displacement.cast<double>().array().inverse()),
      q_prev_(Eigen::ArrayXd::Zero(joints)),
      dq_(Eigen::ArrayXd::Zero(displacement.size())),
      sign_(Eigen::ArrayXd::Zero(displacement.size())),
      z_(Eigen::VectorXd::Zero(displacement.size())) {}

void DahlFilter::reset() {
  z_.setZero();
  started_ = false;
}

void DahlFilter::update(const double* q) {
  const Eigen::Index N = q_prev_.size();
  const Eigen::Map<const Eigen::ArrayXd> q_now(q, N);
  if (started_ && z_.size() > 0) {
    dq_.head(N) = q_now - q_prev_;  // the same displacement drives every x_c of a joint
    for (Eigen::Index f = 1; f < z_.size() / N; ++f) dq_.segment(f * N, N) = dq_.head(N);
    // compute_dahl_state for every state at once with Eigen's vectorized exp
    // (scalar std::exp cost 0.3 us of the 4.9 us default step); dq = 0 gives
    // sign 0 and a factor 1, so a joint at rest keeps its state as there.
    sign_ = dq_.sign();
    z_.array() = sign_ + (z_.array() - sign_) * (-dq_.abs() * inverse_x_c_).exp();
  }
  q_prev_ = q_now;
  started_ = true;
}

Eigen::MatrixXd compute_dahl_features(const Eigen::VectorXf& displacement, const Eigen::MatrixXd& position,
                                      int joints) {
  DahlFilter filter(displacement, joints);
  Eigen::MatrixXd out(position.rows(), displacement.size());
  Eigen::VectorXd q(joints);
  for (Eigen::Index t = 0; t < position.rows(); ++t) {
    q = position.row(t).head(joints).transpose();
    filter.update(q.data());
    out.row(t) = filter.values().transpose();
  }
  return out;
}

Eigen::MatrixXd compute_acceleration_features(const Eigen::VectorXf& filter_s, const Eigen::VectorXd& time,
                                              const Eigen::MatrixXd& velocity, int joints) {
  AccelerationFilter filter(filter_s, joints);
  Eigen::MatrixXd out(time.size(), filter_s.size() * joints);
  Eigen::VectorXd qd(joints);
  for (Eigen::Index t = 0; t < time.size(); ++t) {
    qd = velocity.row(t).head(joints).transpose();
    filter.update(time[t], qd.data());
    out.row(t) = filter.values().transpose();
  }
  return out;
}

}  // namespace rcm::dynamics
