// results.json, report.md and figures/ of a study.
#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "rcm/common/error.hpp"
#include "rcm/common/interrupt.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/plot.hpp"

namespace rcm {
namespace {

std::string mm3(const Eigen::Vector3d& v) {
  return fmt::format("[{:.1f}, {:.1f}, {:.1f}]", 1e3 * v[0], 1e3 * v[1], 1e3 * v[2]);
}

// The trial whose truth is nearest to `target` (within 2 mm), if any.
const TrialOutcome* find_trial(const StudyResult& r, const Eigen::Vector3d& target) {
  const TrialOutcome* best = nullptr;
  double best_d = 0.002;
  for (const auto& t : r.trials)
    if (t.truth_m && (*t.truth_m - target).norm() <= best_d) {
      best_d = (*t.truth_m - target).norm();
      best = &t;
    }
  return best;
}

PlotSpec force_plot(const std::string& title, const TrialOutcome& t, const Eigen::MatrixXd& estimate,
                    const std::string& estimate_label, const Eigen::MatrixXd* reference,
                    const std::string& reference_label) {
  PlotSpec spec;
  spec.title = title;
  spec.x_label = "time (s)";
  spec.y_label = "force at the incision (N, base frame)";
  spec.legend = "outside right";
  spec.width_px = 1100;
  const char* axes[3] = {"x", "y", "z"};
  const Eigen::Index stride = std::max<Eigen::Index>(1, t.time.size() / 3000);
  for (int k = 0; k < 3; ++k) {
    PlotSeries est, ref;
    est.label = fmt::format("F{} {}", axes[k], estimate_label);
    ref.label = fmt::format("F{} {}", axes[k], reference_label);
    est.style = ref.style = PlotStyle::lines;
    est.line_width = 1.0;
    ref.line_width = 2.0;
    for (Eigen::Index i = 0; i < t.time.size(); i += stride) {
      const double x = t.time[i] - t.time[0];
      est.x.push_back(x);
      est.y.push_back(estimate(i, k));
      if (reference && reference->rows() > i) {
        ref.x.push_back(x);
        ref.y.push_back((*reference)(i, k));
      }
    }
    spec.series.push_back(est);
    if (!ref.x.empty()) spec.series.push_back(ref);
  }
  return spec;
}

// Draws into `made` as it goes, so that the figures drawn before an error or an
// interrupt (Interrupted, between figures) are still listed.
void make_figures(const StudyResult& r, const Session& session, const std::filesystem::path& dir,
                  std::vector<std::string>& made, std::string& note) {
  if (!is_gnuplot_available()) {
    note = "gnuplot was not found, so no figures were drawn (install gnuplot-nox).";
    return;
  }
  std::filesystem::create_directories(dir);
  auto draw = [&](const PlotSpec& spec, const std::string& name) {
    throw_if_interrupted("drawing the figures");
    save_plot(spec, dir / name);
    made.push_back(name);
  };
  // Fig. 3: the static force-angle sweep, when the session ships one.
  if (session.extra.contains("force_angle") && session.extra["force_angle"].is_string()) {
    const std::filesystem::path csv = session.manifest.parent_path() / session.extra["force_angle"].get<std::string>();
    const std::string text = read_text_file(csv);
    std::map<double, PlotSeries> by_offset;
    std::istringstream in(text);
    std::string line;
    std::getline(in, line);
    std::vector<std::string> header;
    {
      std::stringstream hs(line);
      std::string cell;
      while (std::getline(hs, cell, ',')) header.push_back(cell);
    }
    auto col = [&](const std::string& name) {
      for (std::size_t i = 0; i < header.size(); ++i)
        if (header[i] == name) return static_cast<int>(i);
      InputLocation where;
      where.file = csv.string();
      where.line = 1;
      where.field = name;
      throw InputError(where, "missing column");
    };
    const int c_off = col("offset_m"), c_theta = col("theta_rad"), c_force = col("force_n");
    while (std::getline(in, line)) {
      if (line.empty()) continue;
      std::vector<double> v;
      std::stringstream ls(line);
      std::string cell;
      while (std::getline(ls, cell, ',')) v.push_back(std::strtod(cell.c_str(), nullptr));
      if (static_cast<int>(v.size()) <= std::max({c_off, c_theta, c_force})) continue;
      PlotSeries& s = by_offset[v[static_cast<std::size_t>(c_off)]];
      s.label = fmt::format("D = {:.0f} mm", 1e3 * v[static_cast<std::size_t>(c_off)]);
      s.x.push_back(v[static_cast<std::size_t>(c_theta)] * 180.0 / M_PI);
      s.y.push_back(v[static_cast<std::size_t>(c_force)]);
    }
    PlotSpec spec;
    spec.title = "Static force-angle (Fig. 3)";
    spec.x_label = "pivot angle theta (deg)";
    spec.y_label = "|f| at the incision (N)";
    for (auto& [offset, s] : by_offset) spec.series.push_back(s);
    draw(spec, "fig3_force_angle");
  }
  // Fig. 4: the D = 30 mm trials, pure coaxial and hybrid, as in the paper.
  const TrialOutcome* pure = find_trial(r, Eigen::Vector3d(0, 0, 0.030));
  const TrialOutcome* hybrid = find_trial(r, Eigen::Vector3d(0.010, 0.015, 0.030));
  if (!pure && !r.trials.empty()) pure = &r.trials.front();
  if (pure) {
    draw(force_plot("(a) " + pure->name + ": estimated vs sensor", *pure, pure->f_estimated, "estimate",
                    pure->f_sensor.rows() ? &pure->f_sensor : nullptr, "sensor"),
         "fig4a_force");
  }
  if (hybrid && hybrid != pure) {
    draw(force_plot("(b) " + hybrid->name + ": estimated vs sensor", *hybrid, hybrid->f_estimated, "estimate",
                    hybrid->f_sensor.rows() ? &hybrid->f_sensor : nullptr, "sensor"),
         "fig4b_force");
    if (pure && pure->f_estimated.rows() == hybrid->f_coaxial_decoupled.rows()) {
      draw(force_plot("(c) decoupled coaxial force of " + hybrid->name + " vs pure coaxial " + pure->name, *hybrid,
                      hybrid->f_coaxial_decoupled, "decoupled", &pure->f_estimated, "pure coaxial"),
           "fig4c_decoupled");
    }
  }
  // Table IV as a picture: estimated vs true D and radial magnitude.
  {
    PlotSpec spec;
    spec.title = "Estimated vs true misalignment";
    spec.x_label = "true value (mm)";
    spec.y_label = "estimate (mm)";
    PlotSeries d, rad, ideal;
    d.label = "D";
    rad.label = "|radial|";
    ideal.label = "ideal";
    d.style = rad.style = PlotStyle::points;
    ideal.style = PlotStyle::lines;
    for (const auto& t : r.trials) {
      if (!t.truth_m) continue;
      d.x.push_back(1e3 * (*t.truth_m)[2]);
      d.y.push_back(1e3 * t.get_misalignment_m()[2]);
      rad.x.push_back(1e3 * t.truth_m->head<2>().norm());
      rad.y.push_back(1e3 * t.get_misalignment_m().head<2>().norm());
    }
    if (!d.x.empty()) {
      ideal.x = {0.0, 60.0};
      ideal.y = {0.0, 60.0};
      spec.series = {d, rad, ideal};
      draw(spec, "table4_estimates");
    }
  }
}

}  // namespace

std::string format_table_iv(const StudyResult& r) {
  const bool joint = r.method == "joint";
  std::string out = joint ? fmt::format("{:<18} {:>24} {:>24} {:>7} {:>24} {:>7} {:>30}\n", "trial", "truth [x, y, D] mm",
                                        "three-step [x, y, D] mm", "e mm", "joint [x, y, D] mm", "e mm",
                                        "joint 95 % interval half-width")
                          : fmt::format("{:<18} {:>24} {:>24} {:>8} {:>24} {:>8}\n", "trial", "truth [x, y, D] mm",
                                        "estimate [x, y, D] mm", "e mm", "paper f(q0,0) variant", "e mm");
  for (const auto& t : r.trials) {
    const std::string truth = t.truth_m ? mm3(*t.truth_m) : "-";
    const std::string e3 = t.get_three_step_error_m() ? fmt::format("{:.1f}", 1e3 * *t.get_three_step_error_m()) : "-";
    if (joint && t.joint) {
      const std::string ej = t.get_error_m() ? fmt::format("{:.1f}", 1e3 * *t.get_error_m()) : "-";
      const Eigen::Vector3d half = 0.5 * (t.joint->ci_high - t.joint->ci_low);
      out += fmt::format("{:<18} {:>24} {:>24} {:>7} {:>24} {:>7} {:>30}\n", t.name, truth, mm3(t.estimate.misalignment_m),
                         e3, mm3(t.joint->misalignment_m), ej, "+-" + mm3(half));
      continue;
    }
    std::string pv = "-", pe = "-";
    if (t.paper_variant) {
      pv = mm3(t.paper_variant->misalignment_m);
      if (t.truth_m) pe = fmt::format("{:.1f}", 1e3 * (t.paper_variant->misalignment_m - *t.truth_m).norm());
    }
    out += fmt::format("{:<18} {:>24} {:>24} {:>8} {:>24} {:>8}\n", t.name, truth, mm3(t.estimate.misalignment_m), e3, pv,
                       pe);
  }
  const nlohmann::json s = r.to_json()["summary"];
  auto line = [&](const char* key, const std::string& label) {
    if (s.contains(key) && !s[key].is_null())
      out += fmt::format("mean e, {}: {:.1f} +- {:.1f} mm over {} trials\n", label, 1e3 * s[key]["mean_m"].get<double>(),
                         1e3 * s[key]["sd_m"].get<double>(), s[key]["trials"].get<int>());
  };
  if (joint) {
    line("three_step_error_D_above_20mm", "three-step, D > 20 mm");
    line("three_step_error_D_up_to_20mm", "three-step, D <= 20 mm");
    line("error_D_above_20mm", "joint, D > 20 mm");
    line("error_D_up_to_20mm", "joint, D <= 20 mm");
    if (s.contains("ci95_coverage"))
      out += fmt::format("joint 95 % intervals cover the truth in {:.0f} % of trials\n", 100.0 * s["ci95_coverage"].get<double>());
    line("online_error_D_above_20mm", "online (final), D > 20 mm");
    line("online_error_D_up_to_20mm", "online (final), D <= 20 mm");
  } else {
    line("error_D_above_20mm", "D > 20 mm");
    line("error_D_up_to_20mm", "D <= 20 mm");
  }
  return out;
}

std::filesystem::path write_study_report(const StudyResult& r, const Session& session,
                                         const std::filesystem::path& out_dir) {
  std::filesystem::create_directories(out_dir);
  save_json_file(out_dir / "results.json", r.to_json());
  std::string figure_note;
  std::vector<std::string> figures;
  if (r.interrupted || is_interrupt_requested()) {
    // Whoever interrupted wants the run to end; figures can wait.
    figure_note = "Figures were not drawn: the run was interrupted.";
  } else {
    try {
      make_figures(r, session, out_dir / "figures", figures, figure_note);
    } catch (const Interrupted&) {
      figure_note = "The other figures were not drawn: the run was interrupted.";
    } catch (const std::runtime_error& e) {
      figure_note = std::string("figures could not be drawn: ") + e.what();
    }
  }

  std::string md;
  md += "# rcm study report\n\n";
  md += fmt::format("Session `{}`, method **{}**, free-space model **{}**, {:.0f} s in all.\n\n",
                    r.session_manifest.string(), r.method, dynamics::to_string(r.model_kind), r.seconds);
  if (r.interrupted)
    md += fmt::format("**Interrupted** after {} of {} trials: the tables cover the trials estimated.\n\n",
                      r.trials.size(), r.trials_planned);
  md += "## Free-space torque (Table II)\n\nHeld-out last 10 % of the free-space recordings, NRMSE = RMSE / (max - min) x 100.\n\n";
  md += "| joint | RMSE | NRMSE (%) | paper PM (%) |\n|---|---|---|---|\n";
  const char* paper_ii[3] = {"1.6", "1.5", "5.3"};
  for (const auto& e : r.free_space_errors)
    md += fmt::format("| {} | {:.4f} {} | {:.2f} | {} |\n", e.index, e.rmse, e.index == 3 ? "N" : "N m", e.nrmse_percent,
                      e.index <= 3 ? paper_ii[e.index - 1] : "-");
  if (r.fit) {
    md += fmt::format("\nFit: {}\n", r.fit->brief_report());
  }

  md += fmt::format("\n## Tissue law (step 2, D* = {:.1f} mm)\n\n", 1e3 * r.calibration_offset_m);
  md += fmt::format("Chosen: **g(x) = {}** (x = D tan(theta) in m, g in N).\n\n",
                    format_expression(r.tissue.best().expression, ExpressionFormat::plain, 6));
  md += fmt::format("Pairs: {} of {} calibration samples kept ({} with theta < threshold, {} singular, {} ill-conditioned, {} not finite).\n\n",
                    r.tissue_pairs_report.kept, r.tissue_pairs_report.samples, r.tissue_pairs_report.dropped_small_theta,
                    r.tissue_pairs_report.dropped_singular, r.tissue_pairs_report.dropped_ill_conditioned,
                    r.tissue_pairs_report.dropped_non_finite);
  md += "| complexity | loss (N^2) | score | BIC | expression |\n|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < r.tissue.front.size(); ++i) {
    const auto& e = r.tissue.front[i];
    md += fmt::format("| {} | {:.4g} | {:.4g} | {:.1f} | `{}`{} |\n", e.complexity, e.loss, e.score, e.bic,
                      format_expression(e.expression, ExpressionFormat::plain, 6), i == r.tissue.best_index ? " (best)" : "");
  }
  if (r.tissue_sensitivity)
    md += fmt::format("\nSensitivity to D* +- 3 mm: leading coefficient {:.0f} .. {:.0f} ({}; the paper: 651 .. 972).\n",
                      r.tissue_sensitivity->leading_min, r.tissue_sensitivity->leading_max,
                      r.tissue_sensitivity->same_family ? "same family at every offset" : "the family changes");

  md += "\n## Force at the incision (Table III)\n\nRMSE per axis of J_D^{-T}(tau - tau_fs) against the force columns, at the true D.\n\n";
  md += "| trial | Fx (N) | Fy (N) | Fz (N) |\n|---|---|---|---|\n";
  for (const auto& t : r.trials)
    if (t.force_rmse)
      md += fmt::format("| {} | {:.2f} | {:.2f} | {:.2f} |\n", t.name, (*t.force_rmse)[0], (*t.force_rmse)[1], (*t.force_rmse)[2]);
  md += "| paper, [0, 0, 30] mm | 1.4 | 0.7 | 2.1 |\n| paper, [10, 15, 30] mm | 2.0 | 1.4 | 1.8 |\n";

  if (r.method == "joint") {
    const std::string step = r.trials.empty() || !r.trials.front().hold ? std::string("no static file")
                                                                          : to_string(r.trials.front().hold->step);
    md += "\n## Misalignment (Table IV): three-step vs joint\n\nThree-step: paper Algorithm 1 with the hold's tau_fs carried "
          "through the return motion (static step: " + step + "). Joint: all three offsets in torque space over the "
          "trial and its static file, with 95 % intervals from a moving-block residual bootstrap, the tissue "
          "parameters' uncertainty, the systematic error the model makes on the calibration (as it is and relative "
          "to D*) and the free-space model's error at rest on the aligned baseline (" + r.baseline_message +
          ").\n\n```\n" + format_table_iv(r) + "```\n";
    if (r.joint_tissue)
      md += fmt::format("\nTissue model in torque space ({}): k1 = {:.1f} N/m, k3 = {:.4g} N/m^3, damping {:.2f} N s/m, "
                        "axial friction {:.2f} N.\n",
                        r.joint_tissue->family, r.joint_tissue->parameters[0], r.joint_tissue->parameters[1],
                        r.joint_tissue->parameters[2], r.joint_tissue->parameters[3]);
    md += "\n## Online estimator (every trial streamed sample by sample)\n\nBank of EKFs on [dr_x, dr_y, D] over the "
          "trial file only (no static hold), as `rcm monitor` replays it. Settled: time from the first motion until the "
          "estimate stays within 5 mm of its final value.\n\n";
    md += "| trial | final [x, y, D] mm | e mm | 2 sd mm | onset s | settled s | alarms | peak force N | us/sample |\n"
          "|---|---|---|---|---|---|---|---|---|\n";
    for (const auto& t : r.trials) {
      if (!t.online) continue;
      const OnlineReplay& o = *t.online;
      auto opt = [](const std::optional<double>& v) { return v ? fmt::format("{:.2f}", *v) : std::string("-"); };
      md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {:.1f} | {:.1f} |\n", t.name,
                        mm3(o.final_output.misalignment_m),
                        t.truth_m ? fmt::format("{:.2f}", 1e3 * (o.final_output.misalignment_m - *t.truth_m).norm()) : "-",
                        mm3(2.0 * o.final_output.sd_m), opt(o.onset_s), opt(o.settled_after_s), o.alarms.size(),
                        o.peak_force_n, 1e6 * o.mean_update_s);
    }
  } else {
    md += "\n## Misalignment (Table IV)\n\nMain estimate: tau_fs of the static hold from the model run over the whole static file (friction memory carried). "
          "Beside it, the paper's variant with tau_fs = f(q0, 0).\n\n```\n" + format_table_iv(r) + "```\n";
  }
  md += "\nPaper (Table IV): mean e 4.2 +- 2.1 mm for D > 20 mm; 10.8-17.2 mm for D <= 20 mm.\n";

  md += "\n## Free-space model regime\n\nSamples of each trial whose position, velocity or acceleration lies beyond "
        "what the free-space model was fitted on (with margins): its torque, and every force and offset computed from it, "
        "are extrapolations there. With the joint method, also the samples of the trial streamed through the online "
        "estimator whose torque residual no incision force explained for 2 s (a payload the free-space model never "
        "saw).\n\n";
  for (const auto& t : r.trials) md += fmt::format("- {}: {}\n", t.name, t.regime.to_text());

  md += "\n## Solver summaries\n\n| trial | coaxial solve | samples | radial inverse |\n|---|---|---|---|\n";
  for (const auto& t : r.trials)
    md += fmt::format("| {} | {} | {} | {}{} |\n", t.name, t.estimate.solver.brief_report(), t.estimate.samples_used,
                      to_string(t.estimate.radial_inverse), t.estimate.radial_extrapolated ? " (g extrapolated)" : "");

  md += "\n## Figures\n\n";
  if (!figure_note.empty()) md += figure_note + "\n";
  for (const auto& f : figures) md += fmt::format("![{0}](figures/{0}.png)\n\n", f);
  const std::filesystem::path report = out_dir / "report.md";
  write_file_atomic(report, md);
  return report;
}

}  // namespace rcm
