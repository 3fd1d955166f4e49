#include "rcm/dynamics/regime.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "rcm/common/error.hpp"

namespace rcm::dynamics {

namespace {

const char* const kQuantityNames[3] = {"position", "velocity", "acceleration"};
const char* const kResidualDescription = "torque residual no incision force explains (a payload change?)";

// The causal acceleration estimate of the header: one update over dt > 0, in place.
inline void update_acceleration(double& acceleration, double& last_velocity, double dt, double velocity,
                                double filter_s) {
  const double raw = (velocity - last_velocity) / dt;
  acceleration = filter_s > 0 ? acceleration + dt / (filter_s + dt) * (raw - acceleration) : raw;
  last_velocity = velocity;
}

[[noreturn]] void fail(const std::string& source, const std::string& field, const std::string& what) {
  InputLocation where;
  where.file = source;
  where.field = field;
  where.kind = InputLocation::Kind::json_field;
  throw InputError(where, what);
}

Eigen::VectorXd read_vector(const nlohmann::json& j, const char* key, const std::string& source, Eigen::Index n) {
  const std::string field = std::string("regime.") + key;
  if (!j.contains(key)) fail(source, field, "missing");
  const auto& a = j.at(key);
  if (!a.is_array() || (n >= 0 && static_cast<Eigen::Index>(a.size()) != n))
    fail(source, field, n >= 0 ? fmt::format("expected an array of {} numbers", n) : "expected an array of numbers");
  Eigen::VectorXd v(static_cast<Eigen::Index>(a.size()));
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!a[i].is_number() || !std::isfinite(a[i].get<double>()))
      fail(source, fmt::format("{}[{}]", field, i), "expected a finite number");
    v[static_cast<Eigen::Index>(i)] = a[i].get<double>();
  }
  return v;
}

nlohmann::json to_array(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

}  // namespace

TrainingRegime compute_training_regime(const std::vector<Recording>& recordings, int num_joints,
                                       double acceleration_filter_s) {
  if (num_joints < 1 || num_joints > kMaxRegimeJoints)
    throw std::invalid_argument(fmt::format("compute_training_regime: {} joints (1..{})", num_joints, kMaxRegimeJoints));
  const double inf = std::numeric_limits<double>::infinity();
  TrainingRegime r;
  r.acceleration_filter_s = acceleration_filter_s;
  r.position_min = Eigen::VectorXd::Constant(num_joints, inf);
  r.position_max = Eigen::VectorXd::Constant(num_joints, -inf);
  r.velocity_min = r.position_min;
  r.velocity_max = r.position_max;
  r.acceleration_abs_max = Eigen::VectorXd::Zero(num_joints);
  for (const auto& rec : recordings) {
    if (rec.num_joints() < num_joints)
      throw std::invalid_argument(fmt::format("compute_training_regime: {} has {} joints", rec.source, rec.num_joints()));
    const Eigen::Index T = rec.time.size();
    for (int j = 0; j < num_joints; ++j) {
      double acceleration = 0.0, last_velocity = 0.0, last_time = 0.0;
      for (Eigen::Index t = 0; t < T; ++t) {
        r.position_min[j] = std::min(r.position_min[j], rec.position(t, j));
        r.position_max[j] = std::max(r.position_max[j], rec.position(t, j));
        r.velocity_min[j] = std::min(r.velocity_min[j], rec.velocity(t, j));
        r.velocity_max[j] = std::max(r.velocity_max[j], rec.velocity(t, j));
        if (t > 0 && rec.time(t) > last_time)
          update_acceleration(acceleration, last_velocity, rec.time(t) - last_time, rec.velocity(t, j),
                              acceleration_filter_s);
        else if (t == 0)
          last_velocity = rec.velocity(t, j);
        last_time = rec.time(t);
        r.acceleration_abs_max[j] = std::max(r.acceleration_abs_max[j], std::abs(acceleration));
      }
    }
    r.samples += static_cast<std::size_t>(T);
  }
  if (r.samples == 0) return TrainingRegime{};
  return r;
}

nlohmann::json regime_to_json(const TrainingRegime& r) {
  if (r.empty()) return nullptr;
  return {{"position_min", to_array(r.position_min)},
          {"position_max", to_array(r.position_max)},
          {"velocity_min", to_array(r.velocity_min)},
          {"velocity_max", to_array(r.velocity_max)},
          {"acceleration_abs_max", to_array(r.acceleration_abs_max)},
          {"acceleration_filter_s", r.acceleration_filter_s},
          {"samples", r.samples}};
}

TrainingRegime regime_from_json(const nlohmann::json& j, const std::string& source) {
  if (j.is_null()) return TrainingRegime{};
  if (!j.is_object()) fail(source, "regime", "expected an object or null");
  TrainingRegime r;
  r.position_min = read_vector(j, "position_min", source, -1);
  const Eigen::Index n = r.position_min.size();
  if (n < 1 || n > kMaxRegimeJoints) fail(source, "regime.position_min", fmt::format("expected 1..{} joints", kMaxRegimeJoints));
  r.position_max = read_vector(j, "position_max", source, n);
  r.velocity_min = read_vector(j, "velocity_min", source, n);
  r.velocity_max = read_vector(j, "velocity_max", source, n);
  r.acceleration_abs_max = read_vector(j, "acceleration_abs_max", source, n);
  if (!(r.position_max.array() >= r.position_min.array()).all())
    fail(source, "regime.position_max", "expected position_max >= position_min");
  if (!(r.velocity_max.array() >= r.velocity_min.array()).all())
    fail(source, "regime.velocity_max", "expected velocity_max >= velocity_min");
  if (!(r.acceleration_abs_max.array() >= 0).all())
    fail(source, "regime.acceleration_abs_max", "expected values >= 0");
  if (!j.contains("acceleration_filter_s") || !j.at("acceleration_filter_s").is_number() ||
      !(j.at("acceleration_filter_s").get<double>() >= 0))
    fail(source, "regime.acceleration_filter_s", "expected a number >= 0");
  r.acceleration_filter_s = j.at("acceleration_filter_s").get<double>();
  if (j.contains("samples")) {
    if (!j.at("samples").is_number_unsigned()) fail(source, "regime.samples", "expected an integer >= 0");
    r.samples = j.at("samples").get<std::size_t>();
  }
  return r;
}

void RegimeCheckOptions::check() const {
  for (const auto& [value, name] : {std::pair{position_margin, "position_margin"},
                                    std::pair{velocity_margin, "velocity_margin"},
                                    std::pair{acceleration_margin, "acceleration_margin"}})
    if (!(value >= 0) || !std::isfinite(value))
      throw std::invalid_argument(fmt::format("RegimeCheckOptions: {} must be finite and >= 0", name));
  if (!(max_fit_cost > 0)) throw std::invalid_argument("RegimeCheckOptions: max_fit_cost must be > 0");
  if (!(residual_persistence_s >= 0) || !std::isfinite(residual_persistence_s))
    throw std::invalid_argument("RegimeCheckOptions: residual_persistence_s must be finite and >= 0");
}

std::string describe_regime_flags(std::uint32_t flags) {
  std::string out;
  for (int j = 0; j < kMaxRegimeJoints; ++j)
    for (int k = 0; k < 3; ++k)
      if (flags & regime_bit(j, static_cast<RegimeQuantity>(k)))
        out += fmt::format("{}joint {} {}", out.empty() ? "" : ", ", j + 1, kQuantityNames[k]);
  if (flags & get_residual_regime_flag())
    out += fmt::format("{}{}", out.empty() ? "" : ", ", kResidualDescription);
  return out;
}

RegimeMonitor::RegimeMonitor(TrainingRegime regime, const RegimeCheckOptions& options) : regime_(std::move(regime)) {
  options.check();
  if (regime_.empty()) return;
  const Eigen::ArrayXd range = (regime_.position_max - regime_.position_min).array();
  lo_q_ = regime_.position_min.array() - options.position_margin * range;
  hi_q_ = regime_.position_max.array() + options.position_margin * range;
  const Eigen::ArrayXd speed = regime_.velocity_min.array().abs().max(regime_.velocity_max.array().abs());
  lo_qd_ = regime_.velocity_min.array() - options.velocity_margin * speed;
  hi_qd_ = regime_.velocity_max.array() + options.velocity_margin * speed;
  max_qdd_ = regime_.acceleration_abs_max * (1.0 + options.acceleration_margin);
}

RegimeMonitor::Workspace RegimeMonitor::create_workspace() const {
  Workspace w;
  w.last_velocity = Eigen::VectorXd::Zero(regime_.num_joints());
  w.acceleration = Eigen::VectorXd::Zero(regime_.num_joints());
  return w;
}

void RegimeMonitor::reset(Workspace& w) const {
  w.last_velocity.setZero();
  w.acceleration.setZero();
  w.started = false;
  w.last_time = 0.0;
}

std::uint32_t RegimeMonitor::compute_flags(Workspace& w, double time, const double* q, const double* qd) const {
  if (!known()) return 0;
  const int n = regime_.num_joints();
  // A repeated stamp carries no new acceleration; an earlier one restarts the estimate.
  const bool advance = w.started && time > w.last_time;
  const double dt = time - w.last_time;
  std::uint32_t flags = 0;
  for (int j = 0; j < n; ++j) {
    if (advance)
      update_acceleration(w.acceleration[j], w.last_velocity[j], dt, qd[j], regime_.acceleration_filter_s);
    else if (!w.started || time < w.last_time) {
      w.acceleration[j] = 0.0;
      w.last_velocity[j] = qd[j];
    }
    // Comparisons written so that a NaN is flagged too.
    if (!(q[j] >= lo_q_[j] && q[j] <= hi_q_[j])) flags |= regime_bit(j, RegimeQuantity::position);
    if (!(qd[j] >= lo_qd_[j] && qd[j] <= hi_qd_[j])) flags |= regime_bit(j, RegimeQuantity::velocity);
    if (!(std::abs(w.acceleration[j]) <= max_qdd_[j])) flags |= regime_bit(j, RegimeQuantity::acceleration);
  }
  w.last_time = time;
  w.started = true;
  return flags;
}

void RegimeSummary::add(double time, std::uint32_t flags) {
  ++samples;
  if (!flags) return;
  ++flagged;
  all_flags |= flags;
  if (!first_time_s) first_time_s = time;
  if (counts.size() < kRegimeBits) counts.resize(kRegimeBits, 0);
  for (int b = 0; b < kRegimeBits; ++b)
    if (flags & (std::uint32_t{1} << b)) ++counts[static_cast<std::size_t>(b)];
}

std::string RegimeSummary::to_text() const {
  if (!known) return "not checked: the free-space model carries no training regime (refit it to get one)";
  if (flagged == 0)
    return fmt::format("all {} samples inside the free-space model's training regime", samples);
  std::string parts;
  for (int b = 0; b < kRegimeBits; ++b)
    if (static_cast<std::size_t>(b) < counts.size() && counts[static_cast<std::size_t>(b)] > 0)
      parts += fmt::format("{}{} {:.1f} %", parts.empty() ? "" : ", ", describe_regime_flags(std::uint32_t{1} << b),
                           100.0 * static_cast<double>(counts[static_cast<std::size_t>(b)]) / static_cast<double>(samples));
  return fmt::format("{:.1f} % of {} samples outside the free-space model's training regime ({}), first at {:.3f} s",
                     100.0 * get_fraction(), samples, parts, first_time_s.value_or(0.0));
}

nlohmann::json RegimeSummary::to_json() const {
  nlohmann::json j;
  j["checked"] = known;
  j["samples"] = samples;
  j["flagged"] = flagged;
  j["fraction"] = get_fraction();
  j["first_time_s"] = first_time_s ? nlohmann::json(*first_time_s) : nlohmann::json(nullptr);
  nlohmann::json per = nlohmann::json::array();
  for (int b = 0; b < kRegimeBits; ++b)
    if (static_cast<std::size_t>(b) < counts.size() && counts[static_cast<std::size_t>(b)] > 0) {
      if (b == kResidualRegimeBit)
        per.push_back({{"joint", nullptr}, {"quantity", "residual"}, {"samples", counts[static_cast<std::size_t>(b)]}});
      else
        per.push_back({{"joint", b / 3 + 1},
                       {"quantity", kQuantityNames[b % 3]},
                       {"samples", counts[static_cast<std::size_t>(b)]}});
    }
  j["by_cause"] = per;
  return j;
}

void add_regime_samples(const RegimeMonitor& monitor, RegimeMonitor::Workspace& w, const Recording& recording,
                        RegimeSummary& s) {
  s.known = monitor.known();
  const int n = monitor.regime().num_joints();
  if (s.known && recording.num_joints() < n)
    throw std::invalid_argument(
        fmt::format("compute_regime_summary: {} has {} joints, the regime {}", recording.source, recording.num_joints(), n));
  Eigen::VectorXd q(std::max(n, 1)), qd(std::max(n, 1));
  for (Eigen::Index t = 0; t < recording.time.size(); ++t) {
    std::uint32_t flags = 0;
    if (s.known) {
      q = recording.position.row(t).head(n).transpose();
      qd = recording.velocity.row(t).head(n).transpose();
      flags = monitor.compute_flags(w, recording.time(t), q.data(), qd.data());
    }
    s.add(recording.time(t), flags);
  }
}

RegimeSummary compute_regime_summary(const RegimeMonitor& monitor, const Recording& recording) {
  RegimeSummary s;
  auto w = monitor.create_workspace();
  add_regime_samples(monitor, w, recording, s);
  return s;
}

}  // namespace rcm::dynamics
