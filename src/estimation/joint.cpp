#include "rcm/estimation/joint.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>
#include <stdexcept>

#include "joint_model.hpp"
#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"
#include "rcm/kinematics/psm_model.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/dynamics/torque_residual.hpp"

namespace rcm {
namespace {

// One sample's normalized torque residual (dtau - b - tau_pred) / sigma, b the
// free-space model's torque offset (JointTissueModel::torque_offset), with its
// Jacobians in closed form: automatic differentiation of the same model costs
// several times more per evaluation, and the bootstrap evaluates it for every
// sample at every iteration of every replicate.
class JointResidual final : public ceres::SizedCostFunction<3, 3, 4, 3> {
 public:
  JointResidual(const JointSample& sample, const Eigen::Matrix3d& R_base_inc, double v0,
                const Eigen::Vector3d& sigma, const Eigen::Vector3d& dtau)
      : sample_(sample), R_base_inc_(R_base_inc), v0_(v0), inv_sigma_(sigma.cwiseInverse()), dtau_(dtau) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    Eigen::Vector3d tau;
    if (jacobians == nullptr) {
      detail::predict_joint_torque(sample_, R_base_inc_, v0_, parameters[0], parameters[1], tau.data());
    } else {
      Eigen::Matrix3d dtau_dp;
      Eigen::Matrix<double, 3, 4> dtau_dtissue;
      detail::compute_joint_torque_jacobians(sample_, R_base_inc_, v0_, parameters[0], parameters[1], tau, dtau_dp,
                                             dtau_dtissue);
      if (jacobians[0] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> J_p(jacobians[0]);
        J_p = -(inv_sigma_.asDiagonal() * dtau_dp);
      }
      if (jacobians[1] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 3, 4, Eigen::RowMajor>> J_tissue(jacobians[1]);
        J_tissue = -(inv_sigma_.asDiagonal() * dtau_dtissue);
      }
      if (jacobians[2] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> J_offset(jacobians[2]);
        J_offset = -Eigen::Matrix3d(inv_sigma_.asDiagonal());
      }
    }
    const Eigen::Map<const Eigen::Vector3d> offset(parameters[2]);
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = (dtau_ - offset - tau).cwiseProduct(inv_sigma_);
    return true;
  }

 private:
  const JointSample& sample_;
  const Eigen::Matrix3d& R_base_inc_;  // the incision frame's, alive for the solve
  double v0_;
  Eigen::Vector3d inv_sigma_, dtau_;
};

// Lets an interrupt end a solve between iterations rather than after hundreds
// of bootstrap solves.
struct InterruptCallback : ceres::IterationCallback {
  ceres::CallbackReturnType operator()(const ceres::IterationSummary&) override {
    return is_interrupt_requested() ? ceres::SOLVER_ABORT : ceres::SOLVER_CONTINUE;
  }
};

struct Fit {
  Eigen::Vector3d p;
  Eigen::Vector4d tissue;
  Eigen::Vector3d torque_offset = Eigen::Vector3d::Zero();
  double cost = 0.0;
  ceres::Solver::Summary summary;
};

// What one solve fits; the rest stays at its start.
struct Unknowns {
  bool offsets = false, tissue = false, cubic = false, torque_offset = false;
};

// One bounded robust solve; `dtau` overrides the samples' residuals (bootstrap).
Fit solve(const IncisionFrame& incision, const std::vector<JointSample>& samples,
          const std::vector<Eigen::Vector3d>* dtau, const JointEstimatorOptions& o, double v0, Eigen::Vector3d p0,
          Eigen::Vector4d tissue0, const Eigen::Vector3d& torque_offset0, Unknowns unknowns) {
  const bool fit_offsets = unknowns.offsets, fit_tissue = unknowns.tissue, fit_cubic = unknowns.cubic;
  Fit fit;
  fit.p = p0;
  fit.tissue = tissue0;
  fit.torque_offset = torque_offset0;
  ceres::Problem problem;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    auto* cost = new JointResidual(samples[i], incision.R_base_inc, v0, o.torque_sigma, dtau ? (*dtau)[i] : samples[i].dtau);
    problem.AddResidualBlock(cost, new ceres::HuberLoss(o.huber_scale), fit.p.data(), fit.tissue.data(),
                             fit.torque_offset.data());
  }
  if (!unknowns.torque_offset) problem.SetParameterBlockConstant(fit.torque_offset.data());
  if (fit_offsets) {
    for (int k = 0; k < 2; ++k) {
      problem.SetParameterLowerBound(fit.p.data(), k, -o.radial_max);
      problem.SetParameterUpperBound(fit.p.data(), k, o.radial_max);
    }
    problem.SetParameterLowerBound(fit.p.data(), 2, o.D_min);
    problem.SetParameterUpperBound(fit.p.data(), 2, o.D_max);
  } else {
    problem.SetParameterBlockConstant(fit.p.data());
  }
  if (fit_tissue) {
    for (int k = 0; k < 4; ++k) problem.SetParameterLowerBound(fit.tissue.data(), k, 0.0);
    if (!fit_cubic) problem.SetManifold(fit.tissue.data(), new ceres::SubsetManifold(4, {1}));
  } else {
    problem.SetParameterBlockConstant(fit.tissue.data());
  }
  ceres::Solver::Options opt;
  opt.linear_solver_type = ceres::DENSE_QR;
  opt.max_num_iterations = o.max_iterations;
  opt.function_tolerance = 1e-10;
  opt.parameter_tolerance = 1e-12;
  opt.logging_type = ceres::SILENT;
  opt.num_threads = 1;
  InterruptCallback interrupt;
  opt.callbacks.push_back(&interrupt);
  ceres::Solve(opt, &problem, &fit.summary);
  throw_if_interrupted("estimating in torque space");
  fit.cost = fit.summary.final_cost;
  return fit;
}

// Moving-block resampling of residuals around a fit: dtau = fitted + resid[blocks].
void draw_block_bootstrap(const std::vector<Eigen::Vector3d>& fitted, const std::vector<Eigen::Vector3d>& resid,
                          std::size_t block, std::mt19937_64& rng, std::vector<Eigen::Vector3d>& dtau) {
  const std::size_t n = fitted.size();
  std::uniform_int_distribution<std::size_t> pick(0, n > block ? n - block : 0);
  dtau.resize(n);
  for (std::size_t i = 0; i < n;) {
    const std::size_t from = pick(rng);
    for (std::size_t k = 0; k < block && i < n; ++k, ++i) dtau[i] = fitted[i] + resid[std::min(n - 1, from + k)];
  }
}

// Moving-block length (samples): twice the integrated autocorrelation time of the
// normalized residuals (the slowest joint), summed up to the first non-positive
// autocorrelation, and at least `min_block`. Blocks shorter than the residuals'
// memory make a bootstrap too confident; the free-space model's error is
// correlated over longer than a second when the model is good and the trajectory
// is slow.
std::size_t compute_block_length(const std::vector<Eigen::Vector3d>& resid, std::size_t min_block) {
  const std::size_t n = resid.size();
  const std::size_t max_lag = n / 10;
  double worst = 1.0;
  for (int j = 0; j < 3; ++j) {
    double mean = 0.0;
    for (const auto& r : resid) mean += r[j];
    mean /= static_cast<double>(n);
    double c0 = 0.0;
    for (const auto& r : resid) c0 += (r[j] - mean) * (r[j] - mean);
    if (!(c0 > 0.0)) continue;
    double tau = 1.0;
    for (std::size_t lag = 1; lag < max_lag; ++lag) {
      double c = 0.0;
      for (std::size_t i = lag; i < n; ++i) c += (resid[i][j] - mean) * (resid[i - lag][j] - mean);
      const double rho = c / c0;
      if (rho <= 0.0) break;
      tau += 2.0 * rho;
    }
    worst = std::max(worst, tau);
  }
  return std::clamp<std::size_t>(static_cast<std::size_t>(2.0 * worst), std::max<std::size_t>(1, min_block),
                                 std::max<std::size_t>(1, n / 5));
}

SolverReport to_report(const ceres::Solver::Summary& s, double seconds) {
  SolverReport r;
  r.converged = s.termination_type == ceres::CONVERGENCE;
  r.termination = ceres::TerminationTypeToString(s.termination_type);
  r.message = s.message;
  r.iterations = static_cast<int>(s.iterations.size()) - 1;
  r.initial_cost = s.initial_cost;
  r.final_cost = s.final_cost;
  r.seconds = seconds;
  return r;
}

}  // namespace

void JointEstimatorOptions::check() const {
  if (!(D_min < D_max)) throw std::invalid_argument("JointEstimatorOptions: D_min must be below D_max");
  if (!(radial_max > 0)) throw std::invalid_argument("JointEstimatorOptions: radial_max must be > 0");
  if (!(torque_sigma.minCoeff() > 0)) throw std::invalid_argument("JointEstimatorOptions: torque_sigma must be > 0");
  if (!(huber_scale > 0)) throw std::invalid_argument("JointEstimatorOptions: huber_scale must be > 0");
  if (!(calibration_offset_sd_m >= 0))
    throw std::invalid_argument("JointEstimatorOptions: calibration_offset_sd_m must be >= 0");
  if (bootstrap_replicates < 0) throw std::invalid_argument("JointEstimatorOptions: bootstrap_replicates must be >= 0");
  if (!(bootstrap_block_s > 0) || !(sample_period_s > 0))
    throw std::invalid_argument("JointEstimatorOptions: bootstrap_block_s and sample_period_s must be > 0");
  for (double d : D_starts)
    if (d < D_min || d > D_max) throw std::invalid_argument("JointEstimatorOptions: every D start must lie within the bounds");
  if (!torque_bias.allFinite()) throw std::invalid_argument("JointEstimatorOptions: torque_bias must be finite");
}

std::vector<JointSample> make_joint_samples(const IncisionFrame& incision, const Recording& r,
                                            const Eigen::MatrixXd& tau_fs, double max_theta_rad) {
  const TorqueResidual dtau = compute_torque_residual(r, tau_fs);
  std::vector<JointSample> out;
  out.reserve(static_cast<std::size_t>(r.time.size()));
  JointSample s;
  for (Eigen::Index t = 0; t < r.time.size(); ++t) {
    if (compute_joint_sample(incision, r.position.row(t).head<3>().transpose(), r.velocity.row(t).head<3>().transpose(),
                             dtau.row(t).transpose(), max_theta_rad, s))
      out.push_back(s);
  }
  return out;
}

bool compute_joint_sample(const IncisionFrame& incision, const Eigen::Vector3d& q, const Eigen::Vector3d& qd,
                          const Eigen::Vector3d& dtau, double max_theta_rad, JointSample& s) {
  const ShaftDirections d = compute_shaft_directions(q);
  s.z3 = d.z3;
  s.cos_theta = incision.z_inc_base().dot(s.z3);
  if (!(std::atan2(incision.z_inc_base().cross(s.z3).norm(), s.cos_theta) <= max_theta_rad)) return false;
  s.dz3_dq1 = d.dz3_dq1;
  s.dz3_dq2 = d.get_dz3_dq2();
  s.z3_dot = s.dz3_dq1 * qd[0] + s.dz3_dq2 * qd[1];
  s.qd3 = qd[2];
  s.dtau = dtau;
  return true;
}

Eigen::Vector3d compute_joint_model_force(const IncisionFrame& incision, const JointTissueModel& tissue,
                                          const JointSample& sample, const Eigen::Vector3d& misalignment_m) {
  double tau[3];
  Eigen::Vector3d f;
  detail::predict_joint_torque(sample, incision.R_base_inc, tissue.axial_velocity_scale, misalignment_m.data(),
                               tissue.parameters.data(), tau, &f);
  return f;
}

Eigen::Vector3d compute_joint_model_torque(const IncisionFrame& incision, const JointTissueModel& tissue,
                                           const JointSample& sample, const Eigen::Vector3d& misalignment_m) {
  Eigen::Vector3d tau;
  detail::predict_joint_torque(sample, incision.R_base_inc, tissue.axial_velocity_scale, misalignment_m.data(), tissue.parameters.data(),
          tau.data());
  return tau;
}

namespace {

// The tissue parameters at the known offset [0, 0, D*], with the free-space
// model's torque offset when the options fit it: the linear family and, unless
// `family` names one, the stiffening one, chosen by BIC counting one effective
// sample per second of data (model errors are correlated over about that long).
struct TissueFit {
  Fit fit;
  bool stiff = false;
  double bic = 0.0;
};
TissueFit fit_tissue_at(const IncisionFrame& incision, const std::vector<JointSample>& samples, double D_star,
                        const JointEstimatorOptions& o, double v0, const std::optional<bool>& stiff_family) {
  const Eigen::Vector3d p(0.0, 0.0, D_star);
  Unknowns u;
  u.tissue = true;
  u.torque_offset = o.fit_torque_offset;
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  const double n_eff = std::max(10.0, static_cast<double>(samples.size()) * o.sample_period_s);
  const double n = static_cast<double>(samples.size());
  auto bic = [&](double cost, int k) { return n_eff * std::log(std::max(cost, 1e-300) / n) + k * std::log(n_eff); };
  const int k_offset = o.fit_torque_offset ? 3 : 0;
  TissueFit out;
  out.fit = solve(incision, samples, nullptr, o, v0, p, Eigen::Vector4d(800, 0, 0, 0), zero, u);
  out.bic = bic(out.fit.cost, 3 + k_offset);
  if (stiff_family && !*stiff_family) return out;
  u.cubic = true;
  Fit cubic = solve(incision, samples, nullptr, o, v0, p, out.fit.tissue, out.fit.torque_offset, u);
  const double bic_cubic = bic(cubic.cost, 4 + k_offset);
  if (stiff_family || bic_cubic < out.bic) {
    out.fit = std::move(cubic);
    out.bic = bic_cubic;
    out.stiff = true;
  }
  return out;
}

// The offsets that fit the samples best with the tissue and the torque offset
// held (multi-start over options.D_starts).
Fit solve_offsets(const IncisionFrame& incision, const std::vector<JointSample>& samples, const JointEstimatorOptions& o,
                  double v0, const Eigen::Vector4d& tissue, const Eigen::Vector3d& torque_offset) {
  Fit best;
  best.cost = std::numeric_limits<double>::infinity();
  Unknowns u;
  u.offsets = true;
  for (double D0 : o.D_starts) {
    Fit f = solve(incision, samples, nullptr, o, v0, Eigen::Vector3d(0, 0, D0), tissue, torque_offset, u);
    if (f.cost < best.cost) best = std::move(f);
  }
  return best;
}

}  // namespace

JointTissueModel fit_joint_tissue_model(const IncisionFrame& incision, const std::vector<JointSample>& calibration,
                                        double D_star, const JointEstimatorOptions& o) {
  o.check();
  if (calibration.size() < 50) {
    InputLocation where;
    where.file = "calibration";
    throw InputError(where, "too few calibration samples for the tissue model (" + std::to_string(calibration.size()) + ")");
  }
  const double v0 = JointTissueModel{}.axial_velocity_scale;
  const Eigen::Vector3d p(0.0, 0.0, D_star);
  const TissueFit chosen = fit_tissue_at(incision, calibration, D_star, o, v0, std::nullopt);
  const bool stiff = chosen.stiff;
  JointTissueModel out;
  out.axial_velocity_scale = v0;
  out.parameters = chosen.fit.tissue;
  out.torque_offset = chosen.fit.torque_offset;
  out.family = stiff ? "stiffening" : "linear";
  out.cost = chosen.fit.cost;
  out.bic = chosen.bic;
  out.calibration_offset_m = D_star;

  // The self-check on data the fit did not use: the models fitted on one half
  // of the calibration (in time) re-estimate the offsets of the other half;
  // any departure from [0, 0, D*] is what a trial may carry too. RMS over the
  // two halves. A calibration too short to halve is checked on itself.
  const std::size_t half = calibration.size() / 2;
  if (half >= 50) {
    const std::vector<JointSample> first(calibration.begin(), calibration.begin() + static_cast<std::ptrdiff_t>(half)),
        second(calibration.begin() + static_cast<std::ptrdiff_t>(half), calibration.end());
    Eigen::Vector3d sq = Eigen::Vector3d::Zero();
    for (int fold = 0; fold < 2; ++fold) {
      const std::vector<JointSample>& fitted_on = fold == 0 ? first : second;
      const std::vector<JointSample>& checked_on = fold == 0 ? second : first;
      const Fit model = fit_tissue_at(incision, fitted_on, D_star, o, v0, stiff).fit;
      const Fit found = solve_offsets(incision, checked_on, o, v0, model.tissue, model.torque_offset);
      sq += (found.p - p).array().square().matrix();
    }
    out.calibration_bias_m = (0.5 * sq).cwiseSqrt();
    out.calibration_check = "held-out halves";
  } else {
    out.calibration_bias_m = (solve_offsets(incision, calibration, o, v0, out.parameters, out.torque_offset).p - p).cwiseAbs();
    out.calibration_check = "in-sample";
  }

  Unknowns refit;
  refit.tissue = true;
  refit.cubic = stiff;
  refit.torque_offset = o.fit_torque_offset;
  if (o.calibration_offset_sd_m > 0) {
    const Eigen::Vector3d shifted(0.0, 0.0, D_star + o.calibration_offset_sd_m);
    const Fit f = solve(incision, calibration, nullptr, o, v0, shifted, out.parameters, out.torque_offset, refit);
    out.dparameters_dD_star = (f.tissue - out.parameters) / o.calibration_offset_sd_m;
    out.dtorque_offset_dD_star = (f.torque_offset - out.torque_offset) / o.calibration_offset_sd_m;
    out.calibration_offset_sd_m = o.calibration_offset_sd_m;
  }

  if (o.calibration_bootstrap_replicates > 1) {
    std::vector<Eigen::Vector3d> fitted(calibration.size()), resid(calibration.size()), dtau;
    for (std::size_t i = 0; i < calibration.size(); ++i) {
      fitted[i] = compute_joint_model_torque(incision, out, calibration[i], p) + out.torque_offset;
      resid[i] = calibration[i].dtau - fitted[i];
    }
    const std::size_t block =
        compute_block_length(resid, static_cast<std::size_t>(o.bootstrap_block_s / o.sample_period_s));
    out.bootstrap_block_s = static_cast<double>(block) * o.sample_period_s;
    std::mt19937_64 rng(o.seed ^ 0x7157u);
    std::vector<Eigen::Vector4d> draws;
    std::vector<Eigen::Vector3d> offset_draws;
    for (int b = 0; b < o.calibration_bootstrap_replicates; ++b) {
      draw_block_bootstrap(fitted, resid, block, rng, dtau);
      const Fit f = solve(incision, calibration, &dtau, o, v0, p, out.parameters, out.torque_offset, refit);
      draws.push_back(f.tissue);
      offset_draws.push_back(f.torque_offset);
    }
    const double m = static_cast<double>(draws.size());
    Eigen::Vector4d mean = Eigen::Vector4d::Zero();
    Eigen::Vector3d offset_mean = Eigen::Vector3d::Zero();
    for (std::size_t b = 0; b < draws.size(); ++b) {
      mean += draws[b] / m;
      offset_mean += offset_draws[b] / m;
    }
    for (std::size_t b = 0; b < draws.size(); ++b) {
      out.covariance += (draws[b] - mean) * (draws[b] - mean).transpose() / (m - 1.0);
      out.torque_offset_covariance +=
          (offset_draws[b] - offset_mean) * (offset_draws[b] - offset_mean).transpose() / (m - 1.0);
    }
    out.bootstrap_replicates = o.calibration_bootstrap_replicates;
  }
  return out;
}

JointEstimate estimate_joint(const IncisionFrame& incision, const JointTissueModel& tissue,
                             const std::vector<JointSample>& samples, const JointEstimatorOptions& o) {
  o.check();
  if (samples.size() < 50) {
    InputLocation where;
    where.file = "trial";
    throw InputError(where, "too few samples for the joint estimate (" + std::to_string(samples.size()) + ")");
  }
  const auto start = std::chrono::steady_clock::now();
  const double v0 = tissue.axial_velocity_scale;
  const Eigen::Vector3d& b = tissue.torque_offset;
  const Fit best = solve_offsets(incision, samples, o, v0, tissue.parameters, b);
  Unknowns offsets_only;
  offsets_only.offsets = true;
  // The offsets re-solved from the optimum with the model or the residuals moved.
  auto resolve = [&](const Eigen::Vector4d& tissue_parameters, const Eigen::Vector3d& torque_offset,
                     const std::vector<Eigen::Vector3d>* dtau) {
    return solve(incision, samples, dtau, o, v0, best.p, tissue_parameters, torque_offset, offsets_only).p;
  };
  JointEstimate out;
  out.misalignment_m = best.p;
  out.samples = samples.size();
  out.solver = to_report(best.summary,
                         std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());

  // Covariance at the optimum, scaled by the residual variance.
  {
    Fit at = best;
    ceres::Problem problem;
    for (const auto& s : samples)
      problem.AddResidualBlock(new JointResidual(s, incision.R_base_inc, v0, o.torque_sigma, s.dtau), nullptr,
                               at.p.data(), at.tissue.data(), at.torque_offset.data());
    problem.SetParameterBlockConstant(at.tissue.data());
    problem.SetParameterBlockConstant(at.torque_offset.data());
    ceres::Covariance::Options co;
    ceres::Covariance covariance(co);
    std::vector<std::pair<const double*, const double*>> blocks = {{at.p.data(), at.p.data()}};
    if (covariance.Compute(blocks, &problem)) {
      double c[9];
      covariance.GetCovarianceBlock(at.p.data(), at.p.data(), c);
      double cost = 0.0;
      problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
      const double dof = std::max(1.0, 3.0 * static_cast<double>(samples.size()) - 3.0);
      out.covariance = Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(c) * (2.0 * cost / dof);
    }
  }

  // Moving-block bootstrap of the residuals around the fitted model.
  if (o.bootstrap_replicates > 0) {
    const std::size_t n = samples.size();
    std::vector<Eigen::Vector3d> fitted(n), resid(n), dtau;
    for (std::size_t i = 0; i < n; ++i) {
      fitted[i] = compute_joint_model_torque(incision, tissue, samples[i], best.p) + b;
      resid[i] = samples[i].dtau - fitted[i];
    }
    const std::size_t block =
        compute_block_length(resid, static_cast<std::size_t>(o.bootstrap_block_s / o.sample_period_s));
    out.bootstrap_block_s = static_cast<double>(block) * o.sample_period_s;
    std::mt19937_64 rng(o.seed);
    std::vector<Eigen::Vector3d> draws;
    for (int r = 0; r < o.bootstrap_replicates; ++r) {
      draw_block_bootstrap(fitted, resid, block, rng, dtau);
      draws.push_back(resolve(tissue.parameters, b, &dtau));
    }
    out.bootstrap_replicates = o.bootstrap_replicates;
    for (int k = 0; k < 3; ++k) {
      std::vector<double> v;
      for (const auto& d : draws) v.push_back(d[k]);
      std::sort(v.begin(), v.end());
      auto quantile = [&](double q) {
        const double pos = q * static_cast<double>(v.size() - 1);
        const std::size_t lo = static_cast<std::size_t>(pos);
        const std::size_t hi = std::min(v.size() - 1, lo + 1);
        return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
      };
      out.sd_bootstrap[k] = (quantile(0.975) - quantile(0.025)) / (2.0 * 1.96);
    }
  }

  // The tissue parameters' uncertainty, through dp/dtissue by re-solving with
  // each parameter moved by its standard deviation.
  Eigen::Matrix<double, 3, 4> S = Eigen::Matrix<double, 3, 4>::Zero();
  for (int j = 0; j < 4; ++j) {
    const double sd = std::sqrt(std::max(0.0, tissue.covariance(j, j)));
    if (!(sd > 0.0)) continue;
    Eigen::Vector4d moved = tissue.parameters;
    moved[j] += sd;
    S.col(j) = (resolve(moved, b, nullptr) - best.p) / sd;
  }
  const Eigen::Matrix3d cov_tissue = S * tissue.covariance * S.transpose();
  // The torque offset's uncertainty the same way, joint by joint.
  Eigen::Matrix3d S_offset = Eigen::Matrix3d::Zero();
  for (int j = 0; j < 3; ++j) {
    const double sd = std::sqrt(std::max(0.0, tissue.torque_offset_covariance(j, j)));
    if (!(sd > 0.0)) continue;
    Eigen::Vector3d moved = b;
    moved[j] += sd;
    S_offset.col(j) = (resolve(tissue.parameters, moved, nullptr) - best.p) / sd;
  }
  const Eigen::Matrix3d cov_offset = S_offset * tissue.torque_offset_covariance * S_offset.transpose();
  out.sd_tissue = (cov_tissue + cov_offset).diagonal().cwiseMax(0.0).cwiseSqrt();
  out.sd_systematic = tissue.calibration_bias_m.cwiseAbs();
  if (std::abs(tissue.calibration_offset_m) > 0.0)
    out.sd_systematic_scale =
        tissue.calibration_bias_m.norm() / std::abs(tissue.calibration_offset_m) * best.p.cwiseAbs();
  if (tissue.calibration_offset_sd_m > 0) {
    const Eigen::Vector4d moved = tissue.parameters + tissue.dparameters_dD_star * tissue.calibration_offset_sd_m;
    const Eigen::Vector3d moved_offset = b + tissue.dtorque_offset_dD_star * tissue.calibration_offset_sd_m;
    out.sd_calibration_offset = (resolve(moved, moved_offset, nullptr) - best.p).cwiseAbs();
  }
  // The free-space model's error off the trials, as a torque offset on each
  // joint in turn: what it moves the estimate by adds in quadrature.
  if ((o.torque_bias.array() != 0.0).any()) {
    Eigen::Vector3d sq = Eigen::Vector3d::Zero();
    std::vector<Eigen::Vector3d> shifted(samples.size());
    for (int j = 0; j < 3; ++j) {
      if (o.torque_bias[j] == 0.0) continue;
      for (std::size_t i = 0; i < samples.size(); ++i) {
        shifted[i] = samples[i].dtau;
        shifted[i][j] += o.torque_bias[j];
      }
      sq += (resolve(tissue.parameters, b, &shifted) - best.p).array().square().matrix();
    }
    out.sd_free_space_model = sq.cwiseSqrt();
  }
  const Eigen::Vector3d half = 1.96 * (out.sd_bootstrap.array().square() + out.sd_tissue.array().square() +
                                       out.sd_systematic.array().square() + out.sd_systematic_scale.array().square() +
                                       out.sd_calibration_offset.array().square() +
                                       out.sd_free_space_model.array().square())
                                          .sqrt()
                                          .matrix();
  out.ci_low = best.p - half;
  out.ci_high = best.p + half;
  return out;
}

const OptionTable<JointEstimatorOptions>& get_option_table(OptionTag<JointEstimatorOptions>) {
  static const auto table =
      OptionTable<JointEstimatorOptions>("JointEstimatorOptions")
          .add("D_min", &JointEstimatorOptions::D_min, "lower bound of the coaxial offset D", "m")
          .add("D_max", &JointEstimatorOptions::D_max, "upper bound of D", "m")
          .add("radial_max", &JointEstimatorOptions::radial_max, "bound of |dr_x| and |dr_y|", "m",
               OptionLimits::above(0))
          .add("D_starts", &JointEstimatorOptions::D_starts, "starts of the multi-start solve, within the bounds", "m")
          .add("torque_sigma", &JointEstimatorOptions::torque_sigma,
               "scale of the torque residual per joint: the free-space model's error", "N m, N m, N",
               OptionLimits::above(0))
          .add("huber_scale", &JointEstimatorOptions::huber_scale, "residuals beyond this are down-weighted", "sigma",
               OptionLimits::above(0))
          .add("bootstrap_replicates", &JointEstimatorOptions::bootstrap_replicates,
               "block-bootstrap replicates of a trial's interval", "", OptionLimits::at_least(0))
          .add("calibration_bootstrap_replicates", &JointEstimatorOptions::calibration_bootstrap_replicates,
               "bootstrap replicates of the tissue parameters on the calibration", "", OptionLimits::at_least(0))
          .add("bootstrap_block_s", &JointEstimatorOptions::bootstrap_block_s,
               "shortest bootstrap block (longer when the residuals' memory is)", "s", OptionLimits::above(0))
          .add("calibration_offset_sd_m", &JointEstimatorOptions::calibration_offset_sd_m,
               "how well the calibration's D* is known, one sd", "m", OptionLimits::at_least(0))
          .add("sample_period_s", &JointEstimatorOptions::sample_period_s, "period of the samples", "s",
               OptionLimits::above(0))
          .add("torque_bias", &JointEstimatorOptions::torque_bias,
               "the free-space model's torque error on the arm as it is now (0: not known)", "N m, N m, N")
          .add("fit_torque_offset", &JointEstimatorOptions::fit_torque_offset,
               "identify the free-space model's torque offset on the calibration with the tissue law and take it off "
               "every residual")
          .add("seed", &JointEstimatorOptions::seed, "seed of the bootstrap")
          .add("max_iterations", &JointEstimatorOptions::max_iterations, "Ceres iteration limit", "",
               OptionLimits::at_least(1))
          .add_check([](const JointEstimatorOptions& o) { o.check(); });
  return table;
}

}  // namespace rcm
