// rcm tissue fit: symbolic regression of the tissue law g (paper III-C step 2,
// V-D) from x = D* tan(theta), y = |f_inc| pairs, given directly (--pairs) or
// computed from a session's calibration recording (--session).

#include <fmt/format.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"
#include "rcm/tissue/tissue_fit.hpp"
#include "rcm/tissue/tissue_pairs.hpp"
#include "study_cli.hpp"

namespace {
namespace cmd_tissue {

struct Options {
  std::string pairs_file, session_file, model_file, force_source = "estimated";
  std::string out_law, write_pairs;
  std::optional<double> offset;
  // The tissue fields of the study's options: the same defaults as `rcm run`.
  rcm::cli::OptionFlags<rcm::StudyOptions> study;
  bool json = false;
};

nlohmann::json number_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

nlohmann::json entry_json(const rcm::TissueFrontEntry& e) {
  return {{"complexity", e.complexity},
          {"loss", number_or_null(e.loss)},
          {"score", number_or_null(e.score)},  // null: +inf after a zero loss
          {"expression", rcm::format_expression(e.expression, rcm::ExpressionFormat::sympy)},
          {"plain", rcm::format_expression(e.expression, rcm::ExpressionFormat::plain)},
          {"latex", rcm::format_expression(e.expression, rcm::ExpressionFormat::latex)},
          {"bic", number_or_null(e.bic)},
          {"num_constants", e.expression.num_constants()}};
}

nlohmann::json report_json(const rcm::TissuePairsReport& r) {
  return {{"samples", r.samples},
          {"kept", r.kept},
          {"dropped_small_theta", r.dropped_small_theta},
          {"dropped_singular", r.dropped_singular},
          {"dropped_ill_conditioned", r.dropped_ill_conditioned},
          {"dropped_non_finite", r.dropped_non_finite}};
}

void progress(const Options& o, const std::string& line) {
  (void)o;
  std::cerr << line << '\n';
}

void run(const Options& o) {
  rcm::StudyOptions study;
  o.study.apply(study);
  const rcm::TissueFitOptions& fit_options = study.tissue;
  const double delta = study.tissue_sensitivity_delta_m;
  const double min_theta = study.tissue_pairs.min_theta_rad;
  if (o.offset && !(std::isfinite(*o.offset) && *o.offset != 0.0)) {
    throw rcm::InputError(rcm::cli::flag_location("--offset"), "expected a non-zero offset in m");
  }

  rcm::TissuePairs pairs;
  std::optional<rcm::TissuePairsReport> report;
  std::function<rcm::TissuePairs(double)> make_pairs;  // for the sensitivity
  std::optional<double> D_star = o.offset;
  std::string sensitivity_note;
  // Kept alive for make_pairs.
  auto recording = std::make_shared<rcm::Recording>();
  auto tau_fs = std::make_shared<Eigen::MatrixXd>();

  if (!o.pairs_file.empty()) {
    pairs = rcm::load_tissue_pairs(o.pairs_file);
    progress(o, fmt::format("read {} pairs from {}", pairs.size(), o.pairs_file));
    if (D_star) {
      make_pairs = [pairs, D = *D_star](double d) { return rcm::compute_rescaled_pairs(pairs, D, d); };
      sensitivity_note = "x rescaled by D/D*, y held fixed (a pairs file carries no torques)";
    }
  } else {
    const rcm::Session session = rcm::load_session(o.session_file);
    if (!session.calibration) {
      throw rcm::InputError({o.session_file, 0, 0, "calibration"},
                            "the session has no calibration recording (paper step 2)");
    }
    if (!D_star) D_star = session.calibration->coaxial_offset_m;
    *recording = rcm::load_recording(session.calibration->recording, rcm::get_read_options(session, {}));
    progress(o, fmt::format("calibration {}: {} samples, D* = {:.4f} m", recording->source,
                            recording->num_samples(), *D_star));
    const rcm::TissuePairOptions pair_options = study.tissue_pairs;
    const Eigen::Vector3d q0 = session.q0;
    if (o.force_source == "measured") {
      make_pairs = [recording, q0, pair_options](double d) {
        return rcm::compute_tissue_pairs_from_measured_force(*recording, q0, d, pair_options).pairs;
      };
      const auto result = rcm::compute_tissue_pairs_from_measured_force(*recording, q0, *D_star, pair_options);
      pairs = result.pairs;
      report = result.report;
      progress(o, "force source: the recording's force columns (sensor reference, not the sensorless estimate)");
    } else {
      if (o.model_file.empty()) {
        throw rcm::InputError(rcm::cli::flag_location("--model"),
                              "--session needs the free-space torque model (rcm dynamics fit --out MODEL) "
                              "to estimate the incision force; or --force-source measured to use the "
                              "recording's force columns");
      }
      const auto model = rcm::dynamics::load_torque_model(o.model_file);
      if (model->num_outputs() < 3) {
        throw rcm::InputError({o.model_file, 0, 0, ""},
                              fmt::format("the model predicts {} joints; the incision force needs joints 1-3",
                                          model->num_outputs()));
      }
      const std::string period = rcm::dynamics::check_sample_period(*model, *recording);
      if (!period.empty()) progress(o, "warning: " + period);
      progress(o, fmt::format("predicting free-space torques with {} ({})", o.model_file,
                              rcm::dynamics::to_string(model->kind())));
      *tau_fs = rcm::dynamics::predict_torque(*model, *recording);
      make_pairs = [recording, tau_fs, q0, pair_options](double d) {
        return rcm::compute_tissue_pairs(*recording, *tau_fs, q0, d, pair_options).pairs;
      };
      const auto result = rcm::compute_tissue_pairs(*recording, *tau_fs, q0, *D_star, pair_options);
      pairs = result.pairs;
      report = result.report;
    }
    progress(o, fmt::format("pairs: {} kept of {} samples (theta < {:.4f} rad: {}, singular J_D: {}, "
                            "ill-conditioned J_D: {}, non-finite: {})",
                            report->kept, report->samples, min_theta, report->dropped_small_theta,
                            report->dropped_singular, report->dropped_ill_conditioned,
                            report->dropped_non_finite));
    sensitivity_note = "pairs recomputed at each offset (x and J_D both change)";
  }
  if (!o.write_pairs.empty()) rcm::save_tissue_pairs(o.write_pairs, pairs);

  progress(o, "fitting g by enumeration up to complexity " + std::to_string(fit_options.max_complexity));
  const rcm::TissueFitResult fit = rcm::fit_tissue_law(pairs, fit_options);
  progress(o, fit.summary.brief_report());

  std::optional<rcm::TissueSensitivity> sensitivity;
  if (make_pairs && D_star && delta > 0.0) {
    progress(o, fmt::format("sensitivity: refitting at D* +- {:.4f} m ({} offsets)", delta,
                            study.tissue_sensitivity_steps));
    sensitivity =
        rcm::fit_tissue_sensitivity(make_pairs, *D_star, delta, study.tissue_sensitivity_steps, fit_options);
  } else if (delta > 0.0 && !o.pairs_file.empty()) {
    progress(o, "sensitivity skipped: give --offset D* (the offset the pairs were made with)");
  }
  if (!o.out_law.empty()) {
    rcm::save_tissue_law(o.out_law, *fit.law);
    progress(o, "wrote " + o.out_law);
  }

  if (o.json) {
    nlohmann::json out;
    nlohmann::json front = nlohmann::json::array();
    for (const auto& e : fit.front) front.push_back(entry_json(e));
    out["front"] = std::move(front);
    out["best"] = entry_json(fit.best());
    out["law"] = rcm::to_json(*fit.law);
    nlohmann::json hof = nlohmann::json::array();
    for (const auto& e : fit.hall_of_fame) hof.push_back(entry_json(e));
    out["hall_of_fame"] = std::move(hof);
    out["summary"] = {{"pairs", fit.summary.num_pairs},
                      {"candidates", fit.summary.num_candidates},
                      {"duplicates", fit.summary.num_duplicates},
                      {"failed", fit.summary.num_failed},
                      {"ceres_solves", fit.summary.num_ceres_solves},
                      {"x_range_m", {fit.summary.x_min, fit.summary.x_max}},
                      {"max_complexity", fit_options.max_complexity},
                      {"bins", fit_options.bins}};
    if (report) out["pairs"] = report_json(*report);
    if (D_star) out["offset_m"] = *D_star;
    if (sensitivity) {
      nlohmann::json entries = nlohmann::json::array();
      for (const auto& e : sensitivity->entries) {
        entries.push_back({{"offset_m", e.offset_m},
                           {"expression", rcm::format_expression(e.best.expression, rcm::ExpressionFormat::sympy)},
                           {"complexity", e.best.complexity},
                           {"leading_coefficient", e.leading_coefficient}});
      }
      out["sensitivity"] = {{"delta_m", delta},
                            {"leading_coefficient_min", sensitivity->leading_min},
                            {"leading_coefficient_max", sensitivity->leading_max},
                            {"same_family", sensitivity->same_family},
                            {"method", sensitivity_note},
                            {"entries", std::move(entries)}};
    }
    rcm::cli::print_json(out);
    return;
  }

  std::vector<std::vector<std::string>> rows;
  for (std::size_t k = 0; k < fit.front.size(); ++k) {
    const auto& e = fit.front[k];
    rows.push_back({std::to_string(e.complexity), fmt::format("{:.6g}", e.loss),
                    std::isfinite(e.score) ? fmt::format("{:.6g}", e.score) : "inf",
                    fmt::format("{:.6g}", e.bic),
                    rcm::format_expression(e.expression, rcm::ExpressionFormat::plain, 6) +
                        (k == fit.best_index ? "   <- best" : "")});
  }
  std::cout << "Pareto front (loss = mean squared error, N^2; score = -dln(loss)/dcomplexity)\n";
  std::cout << rcm::cli::format_table({"complexity", "loss", "score", "BIC", "expression"}, rows);
  const rcm::TissueLaw& g = *fit.law;
  std::cout << fmt::format("\nchosen g (x = D tan(theta) in m, y in N), fitted on x in [{:.6g}, {:.6g}] m:\n",
                           g.x_min(), g.x_max());
  std::cout << "  plain  " << g.to_string(rcm::ExpressionFormat::plain) << '\n';
  std::cout << "  sympy  " << g.to_string(rcm::ExpressionFormat::sympy) << '\n';
  std::cout << "  latex  " << g.to_string(rcm::ExpressionFormat::latex) << '\n';
  std::cout << "  monotone on the fitted range: " << rcm::to_string(g.monotonicity())
            << (g.monotonicity() == rcm::Monotonicity::not_monotone ? " (g^-1 unavailable)" : "") << '\n';
  if (sensitivity) {
    std::cout << fmt::format("\nsensitivity, D* = {:.4f} m +- {:.4f} m ({}):\n", *D_star, delta, sensitivity_note);
    for (const auto& e : sensitivity->entries) {
      std::cout << fmt::format("  D = {:.4f} m   {}\n", e.offset_m,
                               rcm::format_expression(e.best.expression, rcm::ExpressionFormat::plain, 6));
    }
    std::cout << fmt::format("  leading coefficient {:.6g} .. {:.6g}; {}\n", sensitivity->leading_min,
                             sensitivity->leading_max,
                             sensitivity->same_family ? "same family at every offset" : "the family changes");
  }
}

const bool registered = rcm::cli::register_command({"tissue", 50, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* tissue = app.add_subcommand("tissue", "Tissue law g: x = D tan(theta) -> |f_inc| (paper step 2)");
  tissue->require_subcommand(1);
  CLI::App* fit = tissue->add_subcommand(
      "fit", "Symbolic regression of g over {1, x, x^2, x^3, sin, cos, exp}: Pareto front and the chosen law");
  auto* pairs = fit->add_option("--pairs", o->pairs_file, "CSV with header x,y (x = D tan(theta) in m, y = force in N)")
                    ->check(CLI::ExistingFile);
  auto* session = fit->add_option("--session", o->session_file,
                                  "rcm-session/1 manifest: pairs from its calibration recording")
                      ->check(CLI::ExistingFile);
  pairs->excludes(session);
  session->excludes(pairs);
  fit->add_option("--model", o->model_file, "free-space torque model (rcm dynamics fit --out), for --session")
      ->check(CLI::ExistingFile);
  fit->add_option("--force-source", o->force_source,
                  "with --session: 'estimated' (J_D^-T (tau - tau_fs), needs --model; default) or 'measured' "
                  "(the recording's force columns, a sensor reference)")
      ->check(CLI::IsMember({"estimated", "measured"}));
  fit->add_option("--offset", o->offset,
                  "D* in m: with --pairs, the offset the pairs were made with (enables the sensitivity); "
                  "with --session, overrides calibration.coaxial_offset_m");
  o->study.add(fit, "--delta", {"tissue_sensitivity_delta_m"}, "sensitivity: refit at D* +- delta (0: none)");
  o->study.add(fit, "--sensitivity-steps", {"tissue_sensitivity_steps"}, "sensitivity: offsets in [D*-delta, D*+delta]");
  o->study.add(fit, "--max-complexity", {"tissue.max_complexity"});
  o->study.add(fit, "--bins", {"tissue.bins"});
  o->study.add(fit, "--min-theta", {"tissue_pairs.min_theta_rad"},
               "with --session: drop samples with a pivot angle below this");
  fit->add_option("--out", o->out_law, "write the chosen law (rcm-tissue-law/1 JSON)");
  fit->add_option("--write-pairs", o->write_pairs, "write the pairs that were fitted (CSV x,y)");
  fit->add_flag("--json", o->json, "print one JSON object");
  fit->callback([o] {
    if (o->pairs_file.empty() && o->session_file.empty()) {
      throw rcm::InputError(rcm::cli::flag_location("--pairs"), "give --pairs PAIRS.csv or --session SESSION.json");
    }
    run(*o);
  });
}});

}  // namespace cmd_tissue
}  // namespace
