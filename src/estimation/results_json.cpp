// results.json of a study (rcm-results/1 of session-format.md, with extra fields).
#include <cmath>

#include "rcm/dynamics/metrics.hpp"
#include "rcm/estimation/study.hpp"

namespace rcm {
namespace {

nlohmann::json vec_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

nlohmann::json solver_json(const SolverReport& s) {
  return {{"converged", s.converged}, {"termination", s.termination}, {"message", s.message},
          {"iterations", s.iterations}, {"initial_cost", s.initial_cost}, {"final_cost", s.final_cost}};
}

nlohmann::json estimate_json(const ThreeStepResult& r, const std::optional<Eigen::Vector3d>& truth) {
  nlohmann::json j = {{"misalignment_m", vec_json(r.misalignment_m)},
                      {"coaxial_solver", solver_json(r.solver)},
                      {"samples_used", r.samples_used},
                      {"radial", {{"force_inc_n", vec_json(r.f_radial_inc)},
                                  {"force_in_plane_n", r.f_radial_in_plane},
                                  {"inverse", to_string(r.radial_inverse)},
                                  {"extrapolated", r.radial_extrapolated},
                                  {"message", r.radial_message}}}};
  if (truth) j["error_m"] = (r.misalignment_m - *truth).norm();
  return j;
}

}  // namespace

nlohmann::json StudyResult::to_json() const {
  nlohmann::json j;
  j["format"] = "rcm-results/1";
  j["method"] = method;
  j["session"] = session_manifest.string();
  if (interrupted)
    j["interrupted"] = {{"trials_estimated", trials.size()}, {"trials_planned", trials_planned}};
  const TissueFrontEntry& best = tissue.best();
  j["tissue_model"] = {{"expression", format_expression(best.expression, ExpressionFormat::sympy)},
                       {"complexity", best.complexity},
                       {"loss", best.loss},
                       {"score", best.score},
                       {"bic", best.bic},
                       {"latex", format_expression(best.expression, ExpressionFormat::latex, 6)},
                       {"calibration_offset_m", calibration_offset_m},
                       {"pairs", {{"samples", tissue_pairs_report.samples},
                                  {"kept", tissue_pairs_report.kept},
                                  {"dropped_small_theta", tissue_pairs_report.dropped_small_theta},
                                  {"dropped_singular", tissue_pairs_report.dropped_singular},
                                  {"dropped_ill_conditioned", tissue_pairs_report.dropped_ill_conditioned},
                                  {"dropped_non_finite", tissue_pairs_report.dropped_non_finite}}}};
  if (tissue.law) j["tissue_model"]["fitted_range_m"] = {tissue.law->x_min(), tissue.law->x_max()};
  nlohmann::json front = nlohmann::json::array();
  for (const auto& e : tissue.front)
    front.push_back({{"complexity", e.complexity}, {"loss", e.loss}, {"score", e.score}, {"bic", e.bic},
                     {"expression", format_expression(e.expression, ExpressionFormat::sympy)}});
  j["tissue_model"]["front"] = front;
  if (tissue_sensitivity) {
    nlohmann::json s = {{"leading_coefficient_min", tissue_sensitivity->leading_min},
                        {"leading_coefficient_max", tissue_sensitivity->leading_max},
                        {"same_family", tissue_sensitivity->same_family}};
    for (const auto& e : tissue_sensitivity->entries)
      s["refits"].push_back({{"offset_m", e.offset_m}, {"leading_coefficient", e.leading_coefficient},
                             {"expression", format_expression(e.best.expression, ExpressionFormat::sympy)}});
    j["tissue_model"]["sensitivity"] = s;
  }
  j["free_space_model"] = {{"kind", dynamics::to_string(model_kind)}, {"test_errors", dynamics::to_json(free_space_errors)}};
  if (fit) j["free_space_model"]["fit"] = fit->to_json();

  if (method == "joint") {
    j["baseline"] = {{"used", baseline_hold.has_value()}, {"message", baseline_message}};
    if (baseline_hold) {
      j["baseline"]["torque_residual"] = vec_json(baseline_hold->get_dtau());
      j["baseline"]["holds"] = baseline_hold->holds.size();
    }
  }
  if (joint_tissue)
    j["joint_tissue_model"] = {{"family", joint_tissue->family},
                               {"k1_n_per_m", joint_tissue->parameters[0]},
                               {"k3_n_per_m3", joint_tissue->parameters[1]},
                               {"damping_n_s_per_m", joint_tissue->parameters[2]},
                               {"axial_friction_n", joint_tissue->parameters[3]},
                               {"bic", joint_tissue->bic},
                               {"parameter_sd", {std::sqrt(joint_tissue->covariance(0, 0)), std::sqrt(joint_tissue->covariance(1, 1)),
                                                 std::sqrt(joint_tissue->covariance(2, 2)), std::sqrt(joint_tissue->covariance(3, 3))}},
                               {"bootstrap_replicates", joint_tissue->bootstrap_replicates},
                               {"torque_offset", vec_json(joint_tissue->torque_offset)},
                               {"torque_offset_sd", vec_json(joint_tissue->torque_offset_covariance.diagonal().cwiseMax(0.0).cwiseSqrt())},
                               {"calibration_bias_m", vec_json(joint_tissue->calibration_bias_m)},
                               {"calibration_check", joint_tissue->calibration_check},
                               {"bootstrap_block_s", joint_tissue->bootstrap_block_s},
                               {"calibration_offset_sd_m", joint_tissue->calibration_offset_sd_m}};
  nlohmann::json trials_json = nlohmann::json::array();
  std::vector<double> e_far, e_near, e3_far, e3_near, eo_far, eo_near;
  double settle_max = 0.0;
  std::size_t covered = 0, with_interval = 0;
  for (const auto& t : trials) {
    nlohmann::json jt = estimate_json(t.estimate, t.truth_m);
    jt["three_step"] = estimate_json(t.estimate, t.truth_m);
    if (t.joint) {
      const JointEstimate& je = *t.joint;
      nlohmann::json jj = {{"misalignment_m", vec_json(je.misalignment_m)},
                           {"ci95_low_m", vec_json(je.ci_low)},
                           {"ci95_high_m", vec_json(je.ci_high)},
                           {"sd_m", vec_json(je.covariance.diagonal().cwiseSqrt())},
                           {"sd_bootstrap_m", vec_json(je.sd_bootstrap)},
                           {"sd_tissue_m", vec_json(je.sd_tissue)},
                           {"sd_systematic_m", vec_json(je.sd_systematic)},
                           {"sd_systematic_scale_m", vec_json(je.sd_systematic_scale)},
                           {"sd_calibration_offset_m", vec_json(je.sd_calibration_offset)},
                           {"sd_free_space_model_m", vec_json(je.sd_free_space_model)},
                           {"bootstrap_replicates", je.bootstrap_replicates},
                           {"bootstrap_block_s", je.bootstrap_block_s},
                           {"samples", je.samples},
                           {"solver", solver_json(je.solver)}};
      if (t.truth_m) {
        jj["error_m"] = (je.misalignment_m - *t.truth_m).norm();
        const bool inside = ((t.truth_m->array() >= je.ci_low.array()) && (t.truth_m->array() <= je.ci_high.array())).all();
        jj["truth_inside_ci95"] = inside;
        if (je.bootstrap_replicates > 0) {
          ++with_interval;
          covered += inside ? 1 : 0;
        }
      }
      jt["joint"] = jj;
      if (t.online) {
        const OnlineReplay& o = *t.online;
        auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };
        nlohmann::json jo = {{"misalignment_m", vec_json(o.final_output.misalignment_m)},
                             {"sd_m", vec_json(o.final_output.sd_m)},
                             {"onset_s", opt(o.onset_s)},
                             {"motion_start_s", opt(o.motion_start_s)},
                             {"settled_after_s", opt(o.settled_after_s)},
                             {"alarms", o.alarms.size()},
                             {"peak_force_n", o.peak_force_n},
                             {"mean_update_us", 1e6 * o.mean_update_s}};
        if (t.truth_m) {
          const double e = (o.final_output.misalignment_m - *t.truth_m).norm();
          jo["error_m"] = e;
          ((*t.truth_m)[2] > 0.020 + 1e-9 ? eo_far : eo_near).push_back(e);
        }
        if (o.settled_after_s) settle_max = std::max(settle_max, *o.settled_after_s);
        jt["online"] = jo;
      }
      jt["misalignment_m"] = jj["misalignment_m"];
      if (t.truth_m) jt["error_m"] = jj["error_m"];
      else jt.erase("error_m");
    }
    jt["name"] = t.name;
    if (t.truth_m) jt["truth_m"] = vec_json(*t.truth_m);
    if (t.hold) {
      nlohmann::json holds = nlohmann::json::array();
      for (const HoldApproach& h : t.hold->holds)
        holds.push_back({{"duration_s", h.segment.duration_s},
                         {"samples", h.segment.end - h.segment.begin},
                         {"approach_direction", {h.direction[0], h.direction[1], h.direction[2]}},
                         {"tau_measured", vec_json(h.tau_measured)},
                         {"tau_free_space", vec_json(h.tau_free_space)}});
      const auto& b = t.hold->direction_balanced;
      jt["static_hold"] = {{"static_step", to_string(t.hold->step)},
                           {"duration_s", t.hold->segment.duration_s},
                           {"samples", t.hold->segment.end - t.hold->segment.begin},
                           {"tau_measured", vec_json(t.hold->tau_measured)},
                           {"tau_free_space", vec_json(t.hold->tau_free_space)},
                           {"direction_balanced", {b[0], b[1], b[2]}},
                           {"holds", holds}};
    }
    if (t.paper_variant) jt["paper_f_q0_0_variant"] = estimate_json(*t.paper_variant, t.truth_m);
    if (t.force_rmse) jt["force_rmse_n"] = vec_json(*t.force_rmse);
    jt["force_offset_used_m"] = t.force_offset_used_m;
    jt["ill_conditioned_samples"] = t.ill_conditioned_samples;
    jt["regime"] = t.regime.to_json();
    jt["seconds"] = t.seconds;
    if (auto e = t.get_error_m()) ((*t.truth_m)[2] > 0.020 + 1e-9 ? e_far : e_near).push_back(*e);
    if (auto e = t.get_three_step_error_m()) ((*t.truth_m)[2] > 0.020 + 1e-9 ? e3_far : e3_near).push_back(*e);
    trials_json.push_back(jt);
  }
  j["trials"] = trials_json;
  auto stats = [](const std::vector<double>& v) -> nlohmann::json {
    if (v.empty()) return nullptr;
    double mean = 0, var = 0;
    for (double x : v) mean += x;
    mean /= static_cast<double>(v.size());
    for (double x : v) var += (x - mean) * (x - mean);
    const double sd = v.size() > 1 ? std::sqrt(var / static_cast<double>(v.size() - 1)) : 0.0;
    return {{"mean_m", mean}, {"sd_m", sd}, {"trials", v.size()}};
  };
  j["summary"] = {{"error_D_above_20mm", stats(e_far)}, {"error_D_up_to_20mm", stats(e_near)}, {"seconds", seconds}};
  if (method == "joint") {
    j["summary"]["three_step_error_D_above_20mm"] = stats(e3_far);
    j["summary"]["three_step_error_D_up_to_20mm"] = stats(e3_near);
    if (with_interval > 0) j["summary"]["ci95_coverage"] = static_cast<double>(covered) / static_cast<double>(with_interval);
    j["summary"]["online_error_D_above_20mm"] = stats(eo_far);
    j["summary"]["online_error_D_up_to_20mm"] = stats(eo_near);
    j["summary"]["online_settled_after_s_max"] = settle_max;
  }
  return j;
}

}  // namespace rcm
