#include "rcm/live/monitor_node.hpp"

#include <algorithm>
#include <cstdarg>
#include <cstdio>

#include "rcm/estimation/study.hpp"
#include "rcm/io/session.hpp"

namespace rcm {
namespace {

std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* fmt, ...) {
  char buf[512];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  return buf;
}

unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }

}  // namespace

void MonitorNodeParameters::check(const std::function<InputLocation(const std::string&)>& where) const {
  if (session.empty()) throw InputError(where("session"), "missing: the rcm-session/1 manifest (calibration, q0)");
  if (model_file.empty())
    throw InputError(where("model_file"),
                     "missing: a saved free-space model (free_space_model.json of `rcm run`, or `rcm dynamics fit`)");
  if (!(alarm_force_n > 0)) throw InputError(where("alarm_force_n"), "must be > 0");
  if (!(onset_threshold > 0)) throw InputError(where("onset_threshold"), "must be > 0");
  if (publish_every < 1) throw InputError(where("publish_every"), "must be >= 1");
  if (queue_size < 1) throw InputError(where("queue_size"), "must be >= 1");
  if (!(status_period_s >= 0)) throw InputError(where("status_period_s"), "must be >= 0");
  if (seed < 0) throw InputError(where("seed"), "must be >= 0");
  if (!(correction.tolerance_m > 0)) throw InputError(where("tolerance_m"), "must be > 0");
  if (!(correction.compensate_limit_m >= correction.tolerance_m))
    throw InputError(where("compensate_limit_m"), "must be >= tolerance_m");
  if (!(correction.max_rate_m_per_s > 0)) throw InputError(where("max_shift_rate_m_per_s"), "must be > 0");
  if (!(jump_threshold >= 0)) throw InputError(where("jump_threshold"), "must be >= 0 (0: off)");
  for (std::size_t i = 0; i < joint_names.size(); ++i) {
    if (joint_names[i].empty()) throw InputError(where("joint_names[" + std::to_string(i) + "]"), "empty joint name");
    for (std::size_t k = 0; k < i; ++k)
      if (joint_names[k] == joint_names[i])
        throw InputError(where("joint_names[" + std::to_string(i) + "]"), "'" + joint_names[i] + "' given twice");
  }
}

std::vector<std::string> parse_joint_names(const std::string& list, const InputLocation& where) {
  std::string text = list;
  for (char& c : text)
    if (c == '[' || c == ']' || c == '\'' || c == '"') c = ' ';
  std::vector<std::string> names;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find(',', start);
    if (end == std::string::npos) end = text.size();
    std::string name = text.substr(start, end - start);
    name.erase(0, name.find_first_not_of(' '));
    name.erase(name.find_last_not_of(' ') + 1);
    if (name.empty()) throw InputError(where, "empty joint name in '" + list + "'");
    for (const auto& n : names)
      if (n == name) throw InputError(where, "'" + name + "' given twice");
    names.push_back(name);
    start = end + 1;
  }
  return names;
}

std::unique_ptr<OnlinePipeline> make_monitor_pipeline(const MonitorNodeParameters& p, std::string* description) {
  const Session session = load_session(p.session);
  StudyOptions options;
  options.model_file = p.model_file;
  if (!p.tissue_model_file.empty()) options.tissue_model_file = p.tissue_model_file;
  options.fit.seed = static_cast<unsigned>(p.seed);
  options.joint.seed = static_cast<unsigned>(p.seed);
  options.read.dedupe = p.dedupe;
  const TorqueModelFitter no_fitter = [](dynamics::TorqueModelKind, const std::vector<Recording>&,
                                         const dynamics::FitOptions&) -> dynamics::FitResult {
    throw InputError(InputLocation::plain("", "model_file"), "the node does not fit free-space models");
  };
  const MonitorSetup setup = prepare_monitor(session, options, no_fitter);
  OnlineEstimatorOptions online = make_online_options(setup.joint_options);
  online.alarm_force_n = p.alarm_force_n;
  online.onset_threshold = p.onset_threshold;
  online.jump_threshold = p.jump_threshold;
  if (description)
    *description = format("free-space model %s (%d joints), tissue model %s: k1 %.1f N/m, k3 %.3g N/m^3, c %.2f N s/m, "
                          "F %.2f N",
                          dynamics::to_string(setup.free_space.model->kind()).c_str(),
                          setup.free_space.model->num_joints(), setup.tissue.family.c_str(), setup.tissue.parameters[0],
                          setup.tissue.parameters[1], setup.tissue.parameters[2], setup.tissue.parameters[3]);
  if (description && setup.free_space.model->get_output_delay_s() > 0)
    *description += format("; the model's torque, and so each estimate, trails the stream by %.3f s",
                           setup.free_space.model->get_output_delay_s());
  return std::make_unique<OnlinePipeline>(setup.free_space.model,
                                          OnlineEstimator(setup.incision, setup.tissue, online));
}

void MonitorNode::TimingStats::add(double s) {
  ++count;
  sum_s += s;
  max_s = std::max(max_s, s);
}

MonitorNode::MonitorNode(const MonitorNodeParameters& parameters, std::unique_ptr<OnlinePipeline> pipeline,
                         LiveMonitor::ZeroStamp zero_stamp, MonitorSink& sink)
    : params_(parameters),
      pipeline_(std::move(pipeline)),
      monitor_(*pipeline_, parameters.joint_names, zero_stamp),
      corrector_(pipeline_->estimator().incision(), parameters.correction),
      correction_ws_(corrector_.create_workspace()),
      sink_(sink) {
  regime_.known = pipeline_->regime_monitor().known();
}

void MonitorNode::start(const std::string& input_topic_name) {
  sink_.publish_flag(MonitorFlag::onset, false);
  sink_.publish_flag(MonitorFlag::alarm, false);
  sink_.publish_rejected(0);
  sink_.publish_flag(MonitorFlag::out_of_regime, false);
  sink_.publish_advice(describe_correction(correction_ws_.output, corrector_));
  if (!regime_.known)
    sink_.log(LogLevel::warn, "rcm: the free-space model carries no training regime: out_of_regime is never raised "
                              "(refit it)");
  sink_.log(LogLevel::info, format("rcm: listening on %s; publishing %s{misalignment,misalignment_sd,incision_force,"
                                   "onset,alarm,rejected_samples,out_of_regime,correction,advice}; alarm above %.1f N; "
                                   "aligned within %.1f mm, software shifts up to %.1f mm%s",
                                   input_topic_name.c_str(), params_.get_output_prefix().c_str(),
                                   params_.alarm_force_n, 1e3 * params_.correction.tolerance_m,
                                   1e3 * params_.correction.compensate_limit_m,
                                   params_.software_rcm
                                       ? format("; software RCM: commands the shift on %sshift at up to %.1f mm/s",
                                                params_.get_output_prefix().c_str(),
                                                1e3 * params_.correction.max_rate_m_per_s)
                                             .c_str()
                                       : ""));
}

void MonitorNode::compute_message(const JointStateView& message, std::int64_t stamp_ns, std::int64_t receive_time_ns) {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  const LiveMonitor::Verdict verdict = monitor_.compute_message(message, stamp_ns, receive_time_ns);
  const auto stepped = clock::now();
  if (verdict != LiveMonitor::Verdict::accepted) {
    on_rejected(verdict, message, stamp_ns);
    return;
  }
  step_.add(std::chrono::duration<double>(stepped - start).count());
  const OnlineOutput& out = monitor_.get_output();
  if (monitor_.get_counters().accepted == 1) on_first_sample(stamp_ns);
  if (monitor_.get_last_missing() > 0) on_gap(stamp_ns);
  if (monitor_.get_counters().retimed != retimed_) {
    retimed_ = monitor_.get_counters().retimed;
    sink_.log(LogLevel::warn,
              format("rcm: the publisher's clock moved: following its stamps from %.6f s (estimator time %.3f s)",
                     static_cast<double>(stamp_ns) * 1e-9, out.time));
  }

  // Only a new estimate goes on (a model whose torque trails brings none for
  // its delay's first samples), stamped with the time of its sample.
  if (out.updates == updates_) {
    callback_.add(std::chrono::duration<double>(clock::now() - start).count());
    return;
  }
  updates_ = out.updates;
  const CorrectionOutput& correction = corrector_.compute_correction(correction_ws_, out, shift_base_);
  if (params_.software_rcm && !correction.step_base.isZero()) {
    // The arm holds the shift commanded: from the next sample on the estimate
    // is relative to the RCM as it then is.
    shift_base_ = correction.applied_base;
    monitor_.apply_rcm_shift(correction.step_base);
    ++shift_moves_;
  }
  if (++since_publish_ >= params_.publish_every) {
    since_publish_ = 0;
    sink_.publish_correction(monitor_.get_output_time_ns(), correction);
    if (params_.software_rcm) sink_.publish_shift(monitor_.get_output_time_ns(), shift_base_);
    sink_.publish_estimate(monitor_.get_output_time_ns(), out);
  }
  if (correction.changed) {
    const std::string advice = describe_correction(correction, corrector_);
    sink_.publish_advice(advice);
    sink_.log(correction.action == CorrectionAction::hold ? LogLevel::info : LogLevel::warn,
              format("rcm: t = %.3f s: ADVICE %s", out.time, advice.c_str()));
  }
  if (out.onset != onset_) {
    onset_ = out.onset;
    sink_.publish_flag(MonitorFlag::onset, onset_);
    if (onset_) sink_.log(LogLevel::warn, format("rcm: t = %.3f s: ONSET of a misalignment detected", out.onset_time));
  }
  if (out.alarm != alarm_) {
    alarm_ = out.alarm;
    sink_.publish_flag(MonitorFlag::alarm, alarm_);
    if (alarm_)
      sink_.log(LogLevel::error, format("rcm: t = %.3f s: ALARM: incision force %.1f N above %.1f N", out.time,
                                        out.force_norm_n, params_.alarm_force_n));
    else
      sink_.log(LogLevel::warn, format("rcm: t = %.3f s: alarm cleared (%.1f N)", out.time, out.force_norm_n));
  }
  regime_.add(out.time, out.regime_flags);
  if (out.out_of_regime != out_of_regime_) {
    out_of_regime_ = out.out_of_regime;
    sink_.publish_flag(MonitorFlag::out_of_regime, out_of_regime_);
    if (out_of_regime_)
      sink_.log(LogLevel::warn,
                format("rcm: t = %.3f s: OUT OF REGIME: %s beyond the free-space model's training data", out.time,
                       dynamics::describe_regime_flags(out.regime_flags).c_str()),
                1.0);
  }
  if (params_.status_period_s > 0 && out.time >= next_status_s_) {
    next_status_s_ = out.time + params_.status_period_s;
    sink_.log(LogLevel::info,
              format("rcm: t = %.1f s: dr_x %.2f, dr_y %.2f, D %.2f mm (sd %.2f, %.2f, %.2f), |f| %.1f N%s%s%s",
                     out.time, 1e3 * out.misalignment_m[0], 1e3 * out.misalignment_m[1], 1e3 * out.misalignment_m[2],
                     1e3 * out.sd_m[0], 1e3 * out.sd_m[1], 1e3 * out.sd_m[2], out.force_norm_n,
                     out.onset ? "" : " (no onset yet)", out.alarm ? " ALARM" : "",
                     out.out_of_regime ? " (out of regime)" : ""));
  }
  callback_.add(std::chrono::duration<double>(clock::now() - start).count());
}

void MonitorNode::on_first_sample(std::int64_t stamp_ns) {
  const JointStateMap& map = monitor_.get_joint_map();
  std::string order;
  for (const auto& n : map.names()) order += (order.empty() ? "" : ", ") + n;
  sink_.log(LogLevel::info,
            format("rcm: first sample at stamp %.6f s: %d joints %s%s%s; time from %s",
                   static_cast<double>(stamp_ns) * 1e-9, map.num_joints(),
                   map.by_name() ? "by name: " : "by position (the message has no names)", order.c_str(),
                   params_.joint_names.empty() && map.by_name() ? " (the first message's order)" : "",
                   monitor_.uses_receive_time() ? "the receive time (the stamps are zero)" : "header.stamp"));
}

void MonitorNode::on_gap(std::int64_t stamp_ns) {
  const LiveMonitor::Counters& c = monitor_.get_counters();
  const double interval_ms = 1e-6 * static_cast<double>(monitor_.get_median_interval_ns());
  sink_.log(LogLevel::warn,
            format("rcm: %llu message(s) missing before stamp %.6f s: %.1f ms without one, the stream's interval "
                   "%.3f ms (lost on the way, overwritten in a full queue, or never sent) [%llu missing in %llu "
                   "gap(s) so far]",
                   ull(monitor_.get_last_missing()), static_cast<double>(stamp_ns) * 1e-9,
                   1e-6 * static_cast<double>(monitor_.get_last_interval_ns()), interval_ms,
                   ull(c.missing), ull(c.gaps)),
            c.gaps <= 10 ? 0.0 : 2.0);
}

void MonitorNode::on_rejected(LiveMonitor::Verdict verdict, const JointStateView& message, std::int64_t stamp_ns) {
  const std::uint64_t n = monitor_.get_counters().get_rejected();
  sink_.publish_rejected(n);
  sink_.log(LogLevel::warn,
            format("rcm: sample rejected (%s): %s [%llu rejected so far]", to_string(verdict),
                   monitor_.describe_rejection(verdict, message, stamp_ns).c_str(), ull(n)),
            n <= 10 ? 0.0 : 2.0);
}

std::string MonitorNode::get_summary() const {
  const auto& c = monitor_.get_counters();
  std::string s = format(
      "rcm: %llu samples accepted, %llu rejected (duplicate stamp %llu, out of order %llu, zero stamp %llu, "
      "malformed %llu, too few joints %llu, time jump %llu); %llu missing in %llu gap(s) of the stamps%s\n",
      ull(c.accepted), ull(c.get_rejected()), ull(c.duplicate_stamp), ull(c.out_of_order), ull(c.bad_stamp),
      ull(c.malformed), ull(c.too_few_joints), ull(c.time_jump), ull(c.missing), ull(c.gaps),
      c.retimed ? format("; the publisher's clock moved %llu time(s) and was followed", ull(c.retimed)).c_str() : "");
  s += format(
      "rcm: per sample: model + estimator %.2f us mean, %.1f us max; whole callback with publishing %.2f us mean, "
      "%.1f us max\n",
      step_.mean_us(), 1e6 * step_.max_s, callback_.mean_us(), 1e6 * callback_.max_s);
  s += "rcm: regime: " + regime_.to_text() + "\n";
  if (monitor_.started()) {
    const OnlineOutput& o = monitor_.get_output();
    if (pipeline_->model().get_output_delay_s() > 0)
      s += format("rcm: %llu samples estimated: the estimate trails the stream by %.3f s (the free-space model's "
                  "delay), the last ones were not\n",
                  ull(o.updates), pipeline_->model().get_output_delay_s());
    s += format("rcm: final estimate dr_x %.2f +- %.2f, dr_y %.2f +- %.2f, D %.2f +- %.2f mm (1 sd); onset %s\n",
                1e3 * o.misalignment_m[0], 1e3 * o.sd_m[0], 1e3 * o.misalignment_m[1], 1e3 * o.sd_m[1],
                1e3 * o.misalignment_m[2], 1e3 * o.sd_m[2], o.onset ? "detected" : "not detected");
    s += "rcm: advice: " + describe_correction(correction_ws_.output, corrector_) + "\n";
    if (params_.software_rcm)
      s += format("rcm: software RCM: %llu moves commanded; shift in effect %.2f, %.2f, %.2f mm (base frame)\n",
                  ull(shift_moves_), 1e3 * shift_base_[0], 1e3 * shift_base_[1], 1e3 * shift_base_[2]);
  }
  return s;
}

}  // namespace rcm
