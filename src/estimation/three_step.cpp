#include "rcm/estimation/three_step.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_residual.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm {

namespace {

[[noreturn]] void throw_no_hold(const Recording& r, const Eigen::Vector3d& q0, const RestDetectionOptions& o) {
  InputLocation where;
  where.file = r.source;
  std::ostringstream msg;
  msg << "no hold at q0 = [" << q0.transpose() << "] of at least " << o.min_duration_s
      << " s (at rest: |qdot| <= " << o.max_angular_speed << " rad/s and " << o.max_linear_speed
      << " m/s, |q - q0| <= " << o.max_angle_from_q0 << " rad and " << o.max_insertion_from_q0 << " m)";
  throw InputError(where, msg.str());
}

// The direction of the motion that ended at the hold starting at `begin`: the
// side of the last sample before it that lay farther from the hold's position
// than the rest tolerance. 0 when there is none in the file.
int find_approach_direction(const Recording& r, Eigen::Index begin, int joint, double q_hold, double tolerance) {
  for (Eigen::Index t = begin - 1; t >= 0; --t) {
    const double d = q_hold - r.position(t, joint);
    if (std::abs(d) > tolerance) return d > 0.0 ? 1 : -1;
  }
  return 0;
}

}  // namespace

std::vector<RestSegment> find_rest_segments(const Recording& r, const Eigen::Vector3d& q0,
                                            const RestDetectionOptions& o) {
  const Eigen::Index T = r.time.size();
  auto at_rest = [&](Eigen::Index t) {
    for (int j = 0; j < 2; ++j)
      if (std::abs(r.velocity(t, j)) > o.max_angular_speed || std::abs(r.position(t, j) - q0[j]) > o.max_angle_from_q0)
        return false;
    return std::abs(r.velocity(t, 2)) <= o.max_linear_speed && std::abs(r.position(t, 2) - q0[2]) <= o.max_insertion_from_q0;
  };
  std::vector<RestSegment> out;
  Eigen::Index begin = 0;
  while (begin < T) {
    while (begin < T && !at_rest(begin)) ++begin;
    Eigen::Index end = begin;
    while (end < T && at_rest(end)) ++end;
    if (end > begin && r.time[end - 1] - r.time[begin] >= o.min_duration_s)
      out.push_back({begin, end, r.time[end - 1] - r.time[begin]});
    begin = end;
  }
  if (out.empty()) throw_no_hold(r, q0, o);
  return out;
}

RestSegment find_rest_segment(const Recording& r, const Eigen::Vector3d& q0, const RestDetectionOptions& o) {
  return find_rest_segments(r, q0, o).back();
}

std::string to_string(StaticStep step) { return step == StaticStep::last_hold ? "last-hold" : "balanced"; }

StaticStep parse_static_step(const std::string& text) {
  if (text == "last-hold") return StaticStep::last_hold;
  if (text == "balanced") return StaticStep::balanced;
  throw std::invalid_argument("expected balanced or last-hold, got '" + text + "'");
}

StaticHold compute_static_hold(const Recording& r, const Eigen::MatrixXd& tau_fs, const Eigen::Vector3d& q0,
                               const RestDetectionOptions& o, StaticStep step) {
  check_torque_prediction(r, tau_fs);
  StaticHold hold;
  hold.step = step;
  const Eigen::Vector3d tolerance(o.max_angle_from_q0, o.max_angle_from_q0, o.max_insertion_from_q0);
  for (const RestSegment& seg : find_rest_segments(r, q0, o)) {
    const Eigen::Index n = seg.end - seg.begin;
    HoldApproach h;
    h.segment = seg;
    h.tau_measured = r.effort.block(seg.begin, 0, n, 3).colwise().mean().transpose();
    h.tau_free_space = tau_fs.block(seg.begin, 0, n, 3).colwise().mean().transpose();
    const Eigen::Vector3d q_hold = r.position.block(seg.begin, 0, n, 3).colwise().mean().transpose();
    for (int j = 0; j < 3; ++j) h.direction[j] = find_approach_direction(r, seg.begin, j, q_hold[j], tolerance[j]);
    hold.holds.push_back(h);
  }
  hold.segment = hold.holds.back().segment;
  if (step == StaticStep::last_hold) {
    hold.tau_measured = hold.holds.back().tau_measured;
    hold.tau_free_space = hold.holds.back().tau_free_space;
    return hold;
  }
  for (int j = 0; j < 3; ++j) {
    // Per direction (-1, 0, +1): duration-weighted sums of both torques.
    double w[3] = {0, 0, 0}, m[3] = {0, 0, 0}, f[3] = {0, 0, 0};
    for (const HoldApproach& h : hold.holds) {
      const int k = h.direction[j] + 1;
      const double weight = static_cast<double>(h.segment.end - h.segment.begin);
      w[k] += weight;
      m[k] += weight * h.tau_measured[j];
      f[k] += weight * h.tau_free_space[j];
    }
    if (w[0] > 0 && w[2] > 0) {
      hold.direction_balanced[j] = true;
      hold.tau_measured[j] = 0.5 * (m[0] / w[0] + m[2] / w[2]);
      hold.tau_free_space[j] = 0.5 * (f[0] / w[0] + f[2] / w[2]);
    } else {
      const double total = w[0] + w[1] + w[2];
      hold.tau_measured[j] = (m[0] + m[1] + m[2]) / total;
      hold.tau_free_space[j] = (f[0] + f[1] + f[2]) / total;
    }
  }
  return hold;
}

Eigen::VectorXd estimate_position_quantum(const Recording& r) {
  const Eigen::Index T = r.position.rows(), N = r.position.cols();
  Eigen::VectorXd quantum = Eigen::VectorXd::Zero(N);
  for (Eigen::Index j = 0; j < N; ++j) {
    double smallest = std::numeric_limits<double>::infinity();
    for (Eigen::Index t = 1; t < T; ++t) {
      const double step = std::abs(r.position(t, j) - r.position(t - 1, j));
      if (step > 0.0 && step < smallest) smallest = step;
    }
    if (std::isfinite(smallest)) quantum[j] = smallest;
  }
  return quantum;
}

Recording remove_position_chatter(const Recording& recording, const Eigen::VectorXd& width) {
  if (width.size() > recording.position.cols() || (width.array() < 0.0).any() || !width.allFinite())
    throw std::invalid_argument("remove_position_chatter: one finite width >= 0 per joint at most");
  Recording out = recording;
  const Eigen::Index T = out.position.rows();
  for (Eigen::Index j = 0; j < width.size(); ++j) {
    if (!(width[j] > 0.0) || T == 0) continue;
    const double half = 0.5 * width[j];
    double y = out.position(0, j);
    for (Eigen::Index t = 0; t < T; ++t) {
      const double q = out.position(t, j);
      y = std::clamp(y, q - half, q + half);
      out.position(t, j) = y;
    }
  }
  return out;
}

InverseDecomposition compute_inverse_decomposition(const IncisionFrame& incision, const Eigen::Vector3d& q,
                                                   const Eigen::Vector3d& dtau) {
  const ShaftDirections d = compute_shaft_directions(q);
  const double c2 = d.cos_q2;                                 // |dz3/dq1|; |dz3/dq2| = 1
  const double cos_theta = incision.z_inc_base().dot(d.z3);  // s = D / cos(theta)
  InverseDecomposition out;
  out.u = cos_theta * (d.dz3_dq1 * (dtau[0] / (c2 * c2)) + d.get_dz3_dq2() * dtau[1]);
  out.w = d.z3 * dtau[2];
  return out;
}

CoaxialProblem make_coaxial_problem(const IncisionFrame& incision, const Recording& trial,
                                    const Eigen::MatrixXd& tau_fs, const Eigen::Vector3d& dtau_radial,
                                    const CoaxialProblemOptions& options) {
  const Eigen::Index T = trial.time.size();
  const TorqueResidual dtau = compute_torque_residual(trial, tau_fs);
  CoaxialProblem p;
  p.radial = compute_inverse_decomposition(incision, incision.q0, dtau_radial);
  p.R_base_inc = incision.R_base_inc;
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Vector3d q = trial.position.row(t).head<3>().transpose();
    const double theta = compute_pivot_angle(incision, q);
    if (!(theta <= options.max_theta_rad)) continue;
    p.total.push_back(compute_inverse_decomposition(incision, q, dtau.row(t).transpose()));
    p.tan_theta.push_back(std::tan(theta));
    const Eigen::Vector3d z3 = compute_z3_base(q);
    p.stretch_per_D.push_back(z3 / incision.z_inc_base().dot(z3) - incision.z_inc_base());
    p.sample_index.push_back(t);
  }
  if (p.total.empty()) {
    InputLocation where;
    where.file = trial.source;
    throw InputError(where, "no sample with a usable pivot angle for the coaxial estimate");
  }
  return p;
}

bool compute_coaxial_residuals(const CoaxialProblem& p, const TissueLaw& g, double D, double* residuals,
                               double* jacobian) {
  if (!(std::abs(D) > 1e-9) || !std::isfinite(D)) return false;
  const Eigen::Vector3d du = -p.radial.u, dw = -p.radial.w;
  const double inv_D = 1.0 / D;
  for (std::size_t t = 0; t < p.total.size(); ++t) {
    const Eigen::Vector3d u = p.total[t].u + du;
    const Eigen::Vector3d fc = u * inv_D + (p.total[t].w + dw);
    const double n = fc.norm();
    const double x = D * p.tan_theta[t];
    residuals[t] = g.evaluate(x) - n;
    if (jacobian) {
      // d|f_c|/dD = f_c . (-u / D^2) / |f_c|
      const double dn = n > 0.0 ? fc.dot(-u * inv_D * inv_D) / n : 0.0;
      jacobian[t] = g.derivative(x) * p.tan_theta[t] - dn;
    }
    if (!std::isfinite(residuals[t])) return false;
  }
  return true;
}

RadialOffset compute_radial_offset(const CoaxialProblem& p, const TissueLaw& g, double D) {
  RadialOffset out;
  const Eigen::Vector3d f_base = p.radial.evaluate(D);
  out.f_radial_inc = p.R_base_inc.transpose() * f_base;
  const Eigen::Vector3d f_plane(out.f_radial_inc[0], out.f_radial_inc[1], 0.0);  // incision frame
  out.f_in_plane = f_plane.norm();
  if (!(out.f_in_plane > 0.0)) return out;
  TissueInverseResult inv = g.compute_inverse(out.f_in_plane);
  if (inv.status == TissueInverseStatus::out_of_range && g.monotonicity() != Monotonicity::not_monotone) {
    // The radial force may exceed what the calibration swept (or lie below its
    // smallest pivot): extend g's domain rather than clip, and say so.
    const TissueLaw extended(g.expression(), std::min(0.0, g.x_min()), 3.0 * g.x_max());
    inv = extended.compute_inverse(out.f_in_plane);
    out.extrapolated = true;
  }
  out.inverse = inv.status;
  out.message = inv.message;
  if (inv.status != TissueInverseStatus::ok) return out;
  const Eigen::Vector3d e = f_plane / out.f_in_plane;
  out.dp_r_base = p.R_base_inc * (-inv.x * e);
  // f_plane(D) = P R^T (u / D + w): d/dD = P R^T (-u / D^2).
  Eigen::Vector3d df = p.R_base_inc.transpose() * (-p.radial.u / (D * D));
  df[2] = 0.0;
  const double dm = e.dot(df);
  const double slope = g.derivative(inv.x);
  const double dx = slope != 0.0 ? dm / slope : 0.0;
  const Eigen::Vector3d de = (df - e * dm) / out.f_in_plane;
  out.d_dp_r_dD = p.R_base_inc * (-(dx * e + inv.x * de));
  return out;
}

bool compute_total_force_residuals(const CoaxialProblem& p, const TissueLaw& g, double D, double* residuals,
                                   double* jacobian) {
  if (!(std::abs(D) > 1e-9) || !std::isfinite(D)) return false;
  const RadialOffset radial = compute_radial_offset(p, g, D);
  if (radial.inverse != TissueInverseStatus::ok) return false;
  const double inv_D = 1.0 / D;
  for (std::size_t t = 0; t < p.total.size(); ++t) {
    const Eigen::Vector3d& a = p.stretch_per_D[t];
    const Eigen::Vector3d stretch = D * a - radial.dp_r_base;
    const double x = stretch.norm();
    const Eigen::Vector3d fe = p.total[t].evaluate(D);
    const double n = fe.norm();
    residuals[t] = g.evaluate(x) - n;
    if (jacobian) {
      const double dx = x > 0.0 ? stretch.dot(a - radial.d_dp_r_dD) / x : 0.0;
      const double dn = n > 0.0 ? fe.dot(-p.total[t].u * inv_D * inv_D) / n : 0.0;
      jacobian[t] = g.derivative(x) * dx - dn;
    }
    if (!std::isfinite(residuals[t])) return false;
  }
  return true;
}

namespace {

class CoaxialCost final : public ceres::CostFunction {
 public:
  CoaxialCost(const CoaxialProblem& problem, const TissueLaw& g, CoaxialForce mode)
      : problem_(problem), g_(g), mode_(mode) {
    set_num_residuals(static_cast<int>(problem.total.size()));
    mutable_parameter_block_sizes()->push_back(1);
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    double* J = jacobians && jacobians[0] ? jacobians[0] : nullptr;
    if (mode_ == CoaxialForce::total) return compute_total_force_residuals(problem_, g_, parameters[0][0], residuals, J);
    return compute_coaxial_residuals(problem_, g_, parameters[0][0], residuals, J);
  }

 private:
  const CoaxialProblem& problem_;
  const TissueLaw& g_;
  CoaxialForce mode_;
};

double solve_with(const CoaxialProblem& problem, const TissueLaw& g, CoaxialForce mode,
                  const ThreeStepOptions& options, SolverReport* report) {
  options.check();
  const auto start = std::chrono::steady_clock::now();
  // Bounded trust region on D (the paper: lsqnonlin, trust-region-reflective).
  double D = options.D_initial.value_or(0.5 * (options.D_min + options.D_max));
  if (std::abs(D) < 1e-6) D = 1e-3;  // psi is undefined at D = 0
  ceres::Problem ceres_problem;
  ceres_problem.AddResidualBlock(new CoaxialCost(problem, g, mode), nullptr, &D);
  ceres_problem.SetParameterLowerBound(&D, 0, options.D_min);
  ceres_problem.SetParameterUpperBound(&D, 0, options.D_max);
  ceres::Solver::Options solver_options;
  solver_options.minimizer_type = ceres::TRUST_REGION;
  solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.gradient_tolerance = 1e-14;
  solver_options.parameter_tolerance = 1e-12;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.logging_type = ceres::SILENT;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &ceres_problem, &summary);
  if (report) {
    report->converged = summary.termination_type == ceres::CONVERGENCE;
    report->termination = ceres::TerminationTypeToString(summary.termination_type);
    report->message = summary.message;
    report->iterations = static_cast<int>(summary.iterations.size()) - 1;
    report->initial_cost = summary.initial_cost;
    report->final_cost = summary.final_cost;
    report->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return D;
}

}  // namespace

std::string SolverReport::brief_report() const {
  std::ostringstream s;
  s << termination << ", " << iterations << " iterations, cost " << initial_cost << " -> " << final_cost;
  return s.str();
}

void ThreeStepOptions::check() const {
  if (!(D_min < D_max) || !std::isfinite(D_min) || !std::isfinite(D_max))
    throw std::invalid_argument("ThreeStepOptions: D_min must be below D_max");
  if (D_initial && !(*D_initial >= D_min && *D_initial <= D_max))
    throw std::invalid_argument("ThreeStepOptions: D_initial must lie within [D_min, D_max]");
  if (!(function_tolerance > 0.0)) throw std::invalid_argument("ThreeStepOptions: function_tolerance must be > 0");
  if (max_iterations < 1) throw std::invalid_argument("ThreeStepOptions: max_iterations must be >= 1");
}

double solve_coaxial_offset(const CoaxialProblem& problem, const TissueLaw& g, const ThreeStepOptions& options,
                            SolverReport* report) {
  return solve_with(problem, g, CoaxialForce::difference, options, report);
}

double solve_coaxial_offset_total(const CoaxialProblem& problem, const TissueLaw& g, const ThreeStepOptions& options,
                                  SolverReport* report) {
  return solve_with(problem, g, CoaxialForce::total, options, report);
}

nlohmann::json coaxial_problem_to_json(const CoaxialProblem& p, const TissueLaw& g, const ThreeStepOptions& options) {
  nlohmann::json u = nlohmann::json::array(), w = nlohmann::json::array();
  for (const auto& d : p.total) {
    u.push_back({d.u[0], d.u[1], d.u[2]});
    w.push_back({d.w[0], d.w[1], d.w[2]});
  }
  return {{"format", "rcm-coaxial-problem/1"},
          {"tan_theta", p.tan_theta},
          {"u", u},
          {"w", w},
          {"radial_u", {p.radial.u[0], p.radial.u[1], p.radial.u[2]}},
          {"radial_w", {p.radial.w[0], p.radial.w[1], p.radial.w[2]}},
          {"g", to_json(g)},
          {"g_sympy", g.to_string(ExpressionFormat::sympy)},
          {"D_min", options.D_min},
          {"D_max", options.D_max},
          {"D_initial", options.D_initial.value_or(0.5 * (options.D_min + options.D_max))},
          {"function_tolerance", options.function_tolerance}};
}

ThreeStepResult estimate_three_step(const IncisionFrame& incision, const TissueLaw& g, const Recording& trial,
                                    const Eigen::MatrixXd& tau_fs_trial, const Eigen::Vector3d& dtau_radial,
                                    const ThreeStepOptions& options) {
  const CoaxialProblem problem = make_coaxial_problem(incision, trial, tau_fs_trial, dtau_radial, options.coaxial);
  ThreeStepResult result;
  result.samples_used = problem.total.size();
  // The paper's solve: the answer for a linear g, and the start for the total one.
  double D = solve_coaxial_offset(problem, g, options, &result.solver);
  if (options.coaxial_force == CoaxialForce::total && compute_radial_offset(problem, g, D).inverse ==
                                                          TissueInverseStatus::ok) {
    ThreeStepOptions from_difference = options;
    from_difference.D_initial = D;
    SolverReport total;
    D = solve_coaxial_offset_total(problem, g, from_difference, &total);
    total.initial_cost = result.solver.initial_cost;
    total.iterations += result.solver.iterations;
    total.seconds += result.solver.seconds;
    result.solver = total;
  }
  // Step 3d at D~, in the pad plane.
  const RadialOffset radial = compute_radial_offset(problem, g, D);
  result.f_radial_inc = radial.f_radial_inc;
  result.f_radial_in_plane = radial.f_in_plane;
  result.radial_inverse = radial.inverse;
  result.radial_extrapolated = radial.extrapolated;
  result.radial_message = radial.message;
  const Eigen::Vector3d dp_r_inc = incision.R_base_inc.transpose() * radial.dp_r_base;
  result.misalignment_m << dp_r_inc[0], dp_r_inc[1], D;
  return result;
}

const OptionTable<RestDetectionOptions>& get_option_table(OptionTag<RestDetectionOptions>) {
  static const auto table =
      OptionTable<RestDetectionOptions>("RestDetectionOptions")
          .add("max_angular_speed", &RestDetectionOptions::max_angular_speed,
               "joints 1-2 slower than this count as at rest", "rad/s", OptionLimits::at_least(0))
          .add("max_linear_speed", &RestDetectionOptions::max_linear_speed,
               "joint 3 slower than this counts as at rest", "m/s", OptionLimits::at_least(0))
          .add("max_angle_from_q0", &RestDetectionOptions::max_angle_from_q0,
               "joints 1-2 within this of q0 count as at q0", "rad", OptionLimits::at_least(0))
          .add("max_insertion_from_q0", &RestDetectionOptions::max_insertion_from_q0,
               "joint 3 within this of q0 counts as at q0", "m", OptionLimits::at_least(0))
          .add("min_duration_s", &RestDetectionOptions::min_duration_s, "shortest hold at q0", "s",
               OptionLimits::above(0));
  return table;
}

std::string to_string(CoaxialForce mode) { return mode == CoaxialForce::total ? "total" : "difference"; }

const OptionChoices<CoaxialForce>& get_option_choices(OptionTag<CoaxialForce>) {
  static const OptionChoices<CoaxialForce> choices = {{"total", CoaxialForce::total},
                                                      {"difference", CoaxialForce::difference}};
  return choices;
}

const OptionChoices<StaticStep>& get_option_choices(OptionTag<StaticStep>) {
  static const OptionChoices<StaticStep> choices = {{"balanced", StaticStep::balanced},
                                                    {"last-hold", StaticStep::last_hold}};
  return choices;
}

const OptionTable<CoaxialProblemOptions>& get_option_table(OptionTag<CoaxialProblemOptions>) {
  static const auto table = OptionTable<CoaxialProblemOptions>("CoaxialProblemOptions")
                                .add("max_theta_rad", &CoaxialProblemOptions::max_theta_rad,
                                     "samples whose pivot angle exceeds this are left out (J_D amplifies noise)",
                                     "rad", OptionLimits::above_up_to(0, M_PI / 2));
  return table;
}

const OptionTable<ThreeStepOptions>& get_option_table(OptionTag<ThreeStepOptions>) {
  static const auto table =
      OptionTable<ThreeStepOptions>("ThreeStepOptions")
          .add("D_min", &ThreeStepOptions::D_min, "lower bound of the coaxial offset D (paper Eq. 16)", "m")
          .add("D_max", &ThreeStepOptions::D_max, "upper bound of D", "m")
          .add("D_initial", &ThreeStepOptions::D_initial, "initial guess of D (null: the middle of the bounds)", "m")
          .add("function_tolerance", &ThreeStepOptions::function_tolerance,
               "relative change of the cost that ends the solve (paper IV-D)", "", OptionLimits::above(0))
          .add("max_iterations", &ThreeStepOptions::max_iterations, "Ceres iteration limit", "",
               OptionLimits::at_least(1))
          .add("coaxial_force", &ThreeStepOptions::coaxial_force,
               "step 3c: total (g of the whole stretch against |f_e|) or difference (the paper's g(D tan theta) "
               "against |f_e - f_r|, exact for a linear g only)")
          .add_section("coaxial", &ThreeStepOptions::coaxial, "which samples the coaxial problem (step 3c) uses")
          .add_check([](const ThreeStepOptions& o) { o.check(); });
  return table;
}

}  // namespace rcm
