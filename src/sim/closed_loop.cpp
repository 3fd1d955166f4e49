#include "rcm/sim/closed_loop.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcm/kinematics/incision.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/bench_arm.hpp"
#include "rcm/sim/tissue.hpp"

namespace rcm::sim {

Eigen::Vector3d IncisionMotion::get_misalignment(double t) const {
  Eigen::Vector3d m = offset_m;
  if (t >= step_time_s) m += step_m;
  if (t > drift_start_s) m += drift_m_per_s * (std::min(t, drift_end_s) - drift_start_s);
  if (breathing_hz > 0) m += breathing_amplitude_m * std::sin(2.0 * M_PI * breathing_hz * t);
  return m;
}

Eigen::Vector3d IncisionMotion::get_misalignment_rate(double t) const {
  Eigen::Vector3d rate = Eigen::Vector3d::Zero();
  if (t > drift_start_s && t < drift_end_s) rate += drift_m_per_s;
  if (breathing_hz > 0) {
    const double w = 2.0 * M_PI * breathing_hz;
    rate += breathing_amplitude_m * (w * std::cos(w * t));
  }
  return rate;
}

CorrectionOptions IncisionMotion::get_correction_options(const CorrectionOptions& bench) const {
  if (!(compensate_limit_m >= 0)) throw std::invalid_argument("IncisionMotion: compensate_limit_m must be >= 0");
  if (!(max_rate_m_per_s >= 0)) throw std::invalid_argument("IncisionMotion: max_rate_m_per_s must be >= 0");
  CorrectionOptions o = bench;
  if (compensate_limit_m > 0) o.compensate_limit_m = compensate_limit_m;
  if (max_rate_m_per_s > 0) o.max_rate_m_per_s = max_rate_m_per_s;
  return o;
}

std::vector<IncisionMotion> make_default_incision_motions() {
  IncisionMotion step;
  step.name = "step";
  step.step_m = Eigen::Vector3d(0.006, 0.0, 0.008);  // 10 mm
  step.step_time_s = 20.0;
  step.onset_s = 20.0;
  IncisionMotion drift;
  drift.name = "drift";
  drift.drift_m_per_s = Eigen::Vector3d(1.0, -1.0, 1.0).normalized() * 1.5e-4;
  drift.drift_start_s = 10.0;
  drift.drift_end_s = 70.0;
  drift.onset_s = 10.0;
  IncisionMotion breathing;
  breathing.name = "breathing";
  breathing.offset_m = Eigen::Vector3d(0.0, 0.0, 0.006);
  breathing.breathing_amplitude_m = Eigen::Vector3d(0.0, 0.0, 0.003);
  breathing.breathing_hz = 0.25;
  breathing.onset_s = 0.0;
  IncisionMotion large_step;
  large_step.name = "large_step";
  large_step.step_m = Eigen::Vector3d(0.010, 0.015, 0.030);
  large_step.step_time_s = 20.0;
  large_step.onset_s = 20.0;
  large_step.compensate_limit_m = 0.050;
  large_step.max_rate_m_per_s = 0.020;
  return {step, drift, breathing, large_step};
}

namespace {

// The configuration with the loop's stream rate (stream_rate_hz) and a physics
// rate that the stream's period divides.
SimConfig get_stream_config(const SimConfig& config, double stream_rate_hz) {
  if (!(stream_rate_hz > 0)) return config;
  SimConfig c = config;
  c.sensors.log_rate_hz = stream_rate_hz;
  c.controller.physics_rate_hz = stream_rate_hz * get_physics_steps_per_period(config, stream_rate_hz);
  return c;
}

ClosedLoopRun run_one(const SimConfig& base_config, const CorrectionLoop& loop, const IncisionMotion& motion,
                      const ClosedLoopOptions& o, bool closed) {
  const SimConfig config = get_stream_config(base_config, o.stream_rate_hz);
  const Eigen::Vector3d& q0 = config.protocol.q0;
  const Eigen::Matrix3d R = loop.corrector().incision().R_base_inc;
  ReferenceTrajectory reference;
  if (o.teleoperation)
    reference = make_teleop_reference(config, o.teleoperation_stream, o.duration_s);
  else
    reference.add_hold(0.0, q0);
  // The tissue's own parameters; its anchor follows the hooks.
  const TissueModel tissue(config.tissue, q0, motion.get_misalignment(0.0));

  ClosedLoopRun run;
  run.closed = closed;
  CorrectionLoop::Workspace ws = loop.create_workspace();
  // The shift commanded, and the one in effect on the arm (the RCM setpoint
  // minus the docked RCM), which the arm reports with each sample and the
  // estimator takes. Without a loop delay the two are one.
  Eigen::Vector3d commanded_base = Eigen::Vector3d::Zero(), shift_base = Eigen::Vector3d::Zero();
  // The setpoint jumps by each step (the elastic force sees it at once); the
  // damping sees that step's rate over the following sample period.
  Eigen::Vector3d shift_rate_base = Eigen::Vector3d::Zero();
  double shift_rate_until = -1.0;
  // Commands on their way to the arm (loop_delay_s > 0), oldest first: a ring
  // as long as the delay holds samples.
  struct PendingShift {
    double effective_s = 0.0, sample_dt = 0.0;
    Eigen::Vector3d shift_base, step_base;
  };
  const double sample_period = 1.0 / config.sensors.log_rate_hz;
  std::vector<PendingShift> pending(
      o.loop_delay_s > 0 ? static_cast<std::size_t>(std::ceil(o.loop_delay_s / sample_period)) + 2 : 0);
  std::size_t pending_first = 0, pending_count = 0;
  double last_sample_t = 0.0;
  bool have_sample = false;
  const double series_dt = 1.0 / o.series_rate_hz;
  double next_series = 0.0;
  ClosedLoopMeter meter(motion.onset_s, o.duration_s, o);
  Eigen::Vector3d z_sq_sum = Eigen::Vector3d::Zero(), covered = Eigen::Vector3d::Zero();
  int z_count = 0;
  CorrectionAction last_action = CorrectionAction::hold;
  HoldReason last_reason = HoldReason::no_onset;

  // The commands due on the arm by time t take effect, each metered against
  // the true misalignment left just before it. Both hooks call it: the order
  // in which a step asks for the misalignment and its rate is not fixed.
  auto take_due_shifts = [&](double t) {
    while (pending_count > 0 && pending[pending_first].effective_s <= t) {
      const PendingShift& p = pending[pending_first];
      meter.add_move(p.step_base, R * (motion.get_misalignment(t) - R.transpose() * shift_base));
      shift_base = p.shift_base;
      shift_rate_base = p.step_base / p.sample_dt;
      shift_rate_until = t + p.sample_dt;
      pending_first = (pending_first + 1) % pending.size();
      --pending_count;
    }
  };
  RunHooks hooks;
  hooks.get_misalignment = [&](double t) -> Eigen::Vector3d {
    take_due_shifts(t);
    return motion.get_misalignment(t) - R.transpose() * shift_base;
  };
  hooks.get_misalignment_rate = [&](double t) -> Eigen::Vector3d {
    take_due_shifts(t);
    const Eigen::Vector3d rate = t < shift_rate_until ? shift_rate_base : Eigen::Vector3d::Zero();
    return motion.get_misalignment_rate(t) - R.transpose() * rate;
  };
  hooks.on_sample = [&](double t, const Eigen::Vector3d& q, const Eigen::Vector3d& qd, const Eigen::Vector3d& effort,
                        const Eigen::Vector3d& f_true) {
    const Eigen::Vector3d remaining_inc = motion.get_misalignment(t) - R.transpose() * shift_base;
    const CorrectionOutput& c =
        loop.compute_sample(ws, t, q.data(), qd.data(), effort.data(), commanded_base, shift_base);
    const double sample_dt = have_sample ? t - last_sample_t : 0.0;
    have_sample = true;
    last_sample_t = t;
    if (pending.empty()) shift_rate_until = -1.0;
    if (!c.step_base.isZero()) {
      if (pending.empty()) {
        meter.add_move(c.step_base, R * remaining_inc);
        if (closed) {  // the setpoint moves
          commanded_base = shift_base = c.applied_base;
          if (sample_dt > 0) {
            shift_rate_base = c.step_base / sample_dt;
            shift_rate_until = std::numeric_limits<double>::infinity();  // until the next sample
          }
        }
      } else if (closed) {  // the command leaves; the arm takes it loop_delay_s later
        commanded_base = c.applied_base;
        if (pending_count == pending.size())
          throw std::logic_error("closed loop: more shifts on their way than the delay holds samples");
        pending[(pending_first + pending_count) % pending.size()] = {t + o.loop_delay_s,
                                                                      sample_dt > 0 ? sample_dt : sample_period,
                                                                      c.applied_base, c.step_base};
        ++pending_count;
      } else {
        meter.add_move(c.step_base, R * remaining_inc);
      }
    }
    if (c.action != last_action || c.reason != last_reason || run.advice.empty()) {
      run.advice.emplace_back(t, describe_correction(c, loop.corrector()));
      last_action = c.action;
      last_reason = c.reason;
    }
    const double f = f_true.norm();
    meter.add_sample(t, f, remaining_inc.norm());
    if (t >= motion.onset_s) run.max_fit_cost = std::max(run.max_fit_cost, c.fit_cost);
    if (t >= motion.onset_s + o.settled_after_s) {
      const OnlineOutput& e = get_online_output(ws.pipeline.estimator);
      if (e.misalignment_m.allFinite() && (e.sd_m.array() > 0).all()) {
        const Eigen::Vector3d z = (e.misalignment_m - remaining_inc).cwiseQuotient(e.sd_m);
        z_sq_sum += z.cwiseAbs2();
        covered += (z.array().abs() <= loop.corrector().options().confidence_z).cast<double>().matrix();
        ++z_count;
      }
    }
    if (t >= next_series) {
      next_series += series_dt;
      run.time_s.push_back(t);
      run.force_n.push_back(f);
      run.misalignment_m.push_back(remaining_inc.norm());
      run.action.push_back(c.action);
    }
  };
  simulate_run(config, reference, &tissue, {{"closed-loop " + motion.name, 0.0, o.duration_s}},
               derive_seed(config.seed, "noise:closed-loop:" + motion.name), &hooks);

  meter.get_figures(run);
  if (z_count > 0) {
    run.interval_rms_z = (z_sq_sum / z_count).cwiseSqrt();
    run.interval_coverage = covered / z_count;
  }
  run.final_shift_base = shift_base;
  const OnlineOutput& estimate = get_online_output(ws.pipeline.estimator);
  run.final_estimate_m = estimate.misalignment_m;
  run.final_truth_m = motion.get_misalignment(estimate.time) - R.transpose() * shift_base;
  run.alignment = check_alignment(estimate, loop.corrector().incision(), loop.corrector().options()).message;
  return run;
}

}  // namespace

ClosedLoopMeter::ClosedLoopMeter(double onset_s, double duration_s, const ClosedLoopOptions& o)
    : onset_s_(onset_s), duration_s_(duration_s), settled_after_s_(o.settled_after_s), threshold_n_(o.force_threshold_n) {}

void ClosedLoopMeter::add_sample(double t, double f, double remaining_m) {
  if (t >= onset_s_) peak_n_ = std::max(peak_n_, f);
  if (t >= onset_s_ + settled_after_s_) {
    sum_sq_after_settle_ += f * f;
    ++after_settle_;
  }
  if (f > threshold_n_) last_above_s_ = t;
  if (t >= duration_s_ - 10.0) {
    residual_sum_ += remaining_m;
    ++residual_count_;
  }
}

void ClosedLoopMeter::add_move(const Eigen::Vector3d& step_base, const Eigen::Vector3d& remaining_base) {
  ++moves_;
  if (step_base.dot(remaining_base) < 0) ++wrong_;
}

void ClosedLoopMeter::get_figures(ClosedLoopRun& run) const {
  run.peak_force_n = peak_n_;
  run.rms_force_after_settle_n = after_settle_ ? std::sqrt(sum_sq_after_settle_ / after_settle_) : 0.0;
  run.time_to_below_s.reset();
  if (last_above_s_ < duration_s_ - 5.0) run.time_to_below_s = std::max(0.0, last_above_s_ - onset_s_);
  run.residual_misalignment_m = residual_count_ ? residual_sum_ / residual_count_ : 0.0;
  run.moves = moves_;
  run.wrong_direction_moves = wrong_;
}

void ClosedLoopOptions::check() const {
  auto fail = [](const char* what) { throw std::invalid_argument(std::string("ClosedLoopOptions: ") + what); };
  if (!(duration_s > 20.0)) fail("duration_s must be > 20");
  if (!(settled_after_s >= 0)) fail("settled_after_s must be >= 0");
  if (!(force_threshold_n > 0)) fail("force_threshold_n must be > 0");
  if (!(series_rate_hz > 0)) fail("series_rate_hz must be > 0");
  if (!(stream_rate_hz == 0 || (stream_rate_hz >= 10 && stream_rate_hz <= 5000)))
    fail("stream_rate_hz must be 0 (the configuration's) or in [10, 5000] Hz");
  if (!(loop_delay_s >= 0 && loop_delay_s <= 10)) fail("loop_delay_s must be in [0, 10] s");
  if (teleoperation_stream.empty()) fail("teleoperation_stream must not be empty");
  correction.check();
}

const OptionTable<ClosedLoopOptions>& get_option_table(OptionTag<ClosedLoopOptions>) {
  static const auto table =
      OptionTable<ClosedLoopOptions>("ClosedLoopOptions")
          .add("duration_s", &ClosedLoopOptions::duration_s, "each run's length; the motions start at 20 s", "s",
               OptionLimits::above(20))
          .add("settled_after_s", &ClosedLoopOptions::settled_after_s,
               "the RMS force after settling is over the run from the motion's onset plus this", "s",
               OptionLimits::at_least(0))
          .add("force_threshold_n", &ClosedLoopOptions::force_threshold_n,
               "time to below: from the onset until the true force stays below this", "N", OptionLimits::above(0))
          .add("series_rate_hz", &ClosedLoopOptions::series_rate_hz, "rate of the time series kept for the figures",
               "Hz", OptionLimits::above(0))
          .add("teleoperation", &ClosedLoopOptions::teleoperation,
               "the surgeon's motion about the RCM (false: the arm holds at q0)", "")
          .add("stream_rate_hz", &ClosedLoopOptions::stream_rate_hz,
               "the rate the estimator reads the arm (0: the configuration's sensors.log_rate_hz; the physics rate "
               "becomes a whole multiple of it)",
               "Hz", OptionLimits::at_least(0))
          .add("loop_delay_s", &ClosedLoopOptions::loop_delay_s,
               "the arm's time from a sample to the RCM shift it leads to being in effect on the arm (a loop across "
               "processes); the estimator takes the shift the arm reports with each sample",
               "s", OptionLimits::within(0, 10))
          .add("teleoperation_stream", &ClosedLoopOptions::teleoperation_stream,
               "the draw of the surgeon's motion (the simulated PSM's n-th spell of teleoperation: teleop:n)", "")
          .add_check([](const ClosedLoopOptions& o) { o.check(); });
  return table;
}

OnlineEstimatorOptions make_closed_loop_online_options(const JointEstimatorOptions& joint) {
  OnlineEstimatorOptions o = make_online_options(joint);
  o.jump_threshold = 4.0;
  return o;
}

std::vector<ClosedLoopScenario> run_closed_loop_experiment(const SimConfig& config, const OnlinePipeline& pipeline,
                                                           const std::vector<IncisionMotion>& motions,
                                                           const ClosedLoopOptions& options) {
  options.check();
  std::vector<ClosedLoopScenario> out;
  for (const IncisionMotion& m : motions) {
    const CorrectionLoop loop(pipeline,
                              RcmCorrector(pipeline.estimator().incision(), m.get_correction_options(options.correction)));
    ClosedLoopScenario s;
    s.motion = m;
    s.open = run_one(config, loop, m, options, false);
    s.closed = run_one(config, loop, m, options, true);
    out.push_back(std::move(s));
  }
  return out;
}

namespace {

nlohmann::json run_json(const ClosedLoopRun& r) {
  nlohmann::json j;
  j["peak_force_n"] = r.peak_force_n;
  j["rms_force_after_settle_n"] = r.rms_force_after_settle_n;
  j["time_to_below_2n_s"] = r.time_to_below_s ? nlohmann::json(*r.time_to_below_s) : nlohmann::json(nullptr);
  j["residual_misalignment_m"] = r.residual_misalignment_m;
  j["wrong_direction_moves"] = r.wrong_direction_moves;
  j["moves"] = r.moves;
  j["max_fit_cost"] = r.max_fit_cost;
  j["final_shift_base_m"] = {r.final_shift_base[0], r.final_shift_base[1], r.final_shift_base[2]};
  j["final_estimate_m"] = {r.final_estimate_m[0], r.final_estimate_m[1], r.final_estimate_m[2]};
  j["final_truth_m"] = {r.final_truth_m[0], r.final_truth_m[1], r.final_truth_m[2]};
  j["alignment"] = r.alignment;
  j["interval_rms_z"] = {r.interval_rms_z[0], r.interval_rms_z[1], r.interval_rms_z[2]};
  j["interval_coverage"] = {r.interval_coverage[0], r.interval_coverage[1], r.interval_coverage[2]};
  nlohmann::json advice = nlohmann::json::array();
  for (const auto& [t, words] : r.advice) advice.push_back({{"time_s", t}, {"advice", words}});
  j["advice"] = advice;
  return j;
}

}  // namespace

nlohmann::json to_json(const std::vector<ClosedLoopScenario>& scenarios, const ClosedLoopOptions& o) {
  nlohmann::json j;
  j["format"] = "rcm-closed-loop/1";
  j["duration_s"] = o.duration_s;
  j["settled_after_s"] = o.settled_after_s;
  j["force_threshold_n"] = o.force_threshold_n;
  j["stream_rate_hz"] = o.stream_rate_hz;
  j["loop_delay_s"] = o.loop_delay_s;
  j["teleoperation_stream"] = o.teleoperation_stream;
  j["correction"] = {{"tolerance_m", o.correction.tolerance_m},
                     {"compensate_limit_m", o.correction.compensate_limit_m},
                     {"max_rate_m_per_s", o.correction.max_rate_m_per_s}};
  nlohmann::json s = nlohmann::json::object();
  for (const auto& sc : scenarios) {
    const IncisionMotion& m = sc.motion;
    const CorrectionOptions gates = m.get_correction_options(o.correction);
    s[m.name] = {{"onset_s", m.onset_s},
                 {"compensate_limit_m", gates.compensate_limit_m},
                 {"max_rate_m_per_s", gates.max_rate_m_per_s},
                 {"open", run_json(sc.open)},
                 {"closed", run_json(sc.closed)}};
  }
  j["scenarios"] = s;
  return j;
}

std::string format_closed_loop_table(const std::vector<ClosedLoopScenario>& scenarios) {
  std::string t =
      "| scenario | run | peak force (N) | RMS force after settling (N) | onset to force below 2 N (s) | residual "
      "misalignment (mm) | moves | wrong-direction moves |\n|---|---|---|---|---|---|---|---|\n";
  for (const auto& sc : scenarios)
    for (const ClosedLoopRun* r : {&sc.open, &sc.closed})
      t += fmt::format("| {} | {} | {:.1f} | {:.2f} | {} | {:.1f} | {} | {} |\n", sc.motion.name,
                       r->closed ? "closed" : "open", r->peak_force_n, r->rms_force_after_settle_n,
                       r->time_to_below_s ? fmt::format("{:.1f}", *r->time_to_below_s) : std::string("never"),
                       r->residual_misalignment_m * 1e3, r->closed ? std::to_string(r->moves) : std::string("-"),
                       r->wrong_direction_moves);
  return t;
}

std::vector<PlotFiles> save_closed_loop_plots(const std::filesystem::path& stem, const ClosedLoopScenario& sc) {
  auto series = [](const ClosedLoopRun& r, const std::vector<double>& y, double scale) {
    PlotSeries s;
    s.label = r.closed ? "closed loop" : "open loop";
    s.style = PlotStyle::lines;
    s.x = r.time_s;
    for (double v : y) s.y.push_back(v * scale);
    return s;
  };
  std::vector<PlotFiles> files;
  PlotSpec force;
  force.title = fmt::format("{}: true incision force", sc.motion.name);
  force.x_label = "time (s)";
  force.y_label = "|f| (N)";
  force.legend = "top right";
  force.series = {series(sc.open, sc.open.force_n, 1.0), series(sc.closed, sc.closed.force_n, 1.0)};
  files.push_back(save_plot(force, stem.string() + "_force"));
  PlotSpec mis = force;
  mis.title = fmt::format("{}: true misalignment (incision to RCM)", sc.motion.name);
  mis.y_label = "misalignment (mm)";
  mis.series = {series(sc.open, sc.open.misalignment_m, 1e3), series(sc.closed, sc.closed.misalignment_m, 1e3)};
  files.push_back(save_plot(mis, stem.string() + "_misalignment"));
  PlotSpec advice = force;
  advice.title = fmt::format("{}: advice (0 hold, 1 compensate, 2 reposition)", sc.motion.name);
  advice.y_label = "action";
  advice.y_range = std::make_pair(-0.2, 2.2);
  std::vector<double> open_action, closed_action;
  for (auto a : sc.open.action) open_action.push_back(static_cast<double>(a));
  for (auto a : sc.closed.action) closed_action.push_back(static_cast<double>(a));
  advice.series = {series(sc.open, open_action, 1.0), series(sc.closed, closed_action, 1.0)};
  files.push_back(save_plot(advice, stem.string() + "_advice"));
  return files;
}

}  // namespace rcm::sim
