#include "rcm/sim/sim_config.hpp"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "sim_config_parts.hpp"

namespace rcm::sim {

void detail::fail_config_field(const std::string& source, const std::string& field, const std::string& what) {
  InputLocation loc;
  loc.file = source;
  loc.field = field;
  loc.kind = InputLocation::Kind::json_field;
  throw InputError(loc, what);
}

namespace {

using detail::kJointKeys;

using FieldRef = std::variant<double*, int*, bool*, std::string*, std::uint64_t*, Eigen::Vector3d*,
                              std::vector<double>*, std::vector<Eigen::Vector2d>*>;

struct Field {
  std::string path;
  FieldRef ref;
  std::string help;
};

// The single table of configurable fields. Paths are JSON paths into the config.
std::vector<Field> get_fields(SimConfig& c) {
  std::vector<Field> f;
  auto add = [&f](std::string path, FieldRef ref, std::string help) {
    f.push_back({std::move(path), ref, std::move(help)});
  };
  add("seed", &c.seed, "master random seed (paths and noise)");
  add("robot", &c.robot, "robot model (built-in name or rcm-robot/1 file); joint limits");
  add("threads", &c.threads, "worker threads (results do not depend on it)");
  auto body = [&](const std::string& key, RigidBodyParams& b, const std::string& what) {
    add("arm." + key + ".mass_kg", &b.mass_kg, what + ": mass, kg");
    add("arm." + key + ".com_m", &b.com_m, what + ": centre of mass in its frame, m");
    add("arm." + key + ".inertia_diag_kg_m2", &b.inertia_diag_kg_m2,
        what + ": principal inertia about the COM, kg m^2");
  };
  body("yaw_link", c.arm.yaw_link, "yaw link (base frame turned by q1 about the yaw axis)");
  body("pitch_link", c.arm.pitch_link, "pitch parallelogram, lumped (frame-3 axes)");
  body("insertion_stage", c.arm.insertion_stage,
       "insertion carriage + instrument (frame-3 axes, COM at com + q3 e_z)");
  add("arm.gravity_base_m_s2", &c.arm.gravity_base_m_s2, "gravity in the base frame, m/s^2");
  add("arm.insertion_counterbalance_n", &c.arm.insertion_counterbalance_n,
      "insertion counterbalance spring force along -z3, N");
  add("arm.insertion_stiffness_n_per_m", &c.arm.insertion_stiffness_n_per_m,
      "stiffness of an elastic element along the insertion (its force along -z3 grows by this per m of q3), N/m");
  add("arm.preset", &c.arm.preset, "rigid | cable: transmissions and effort noise (applied first)");
  for (int j = 0; j < 3; ++j) {
    JointTransmissionParams& t = c.arm.transmission[static_cast<std::size_t>(j)];
    const std::string k = std::string("arm.transmission.") + kJointKeys[j];
    const bool lin = j == 2;
    add(k + ".rotor_inertia", &t.rotor_inertia,
        std::string("motor and gearhead reflected to the joint, ") + (lin ? "kg" : "kg m^2"));
    add(k + ".stiffness", &t.stiffness, std::string("cable, motor to link, ") + (lin ? "N/m" : "N m/rad") + "; 0: rigid");
    add(k + ".damping", &t.damping, std::string("cable damping, ") + (lin ? "N s/m" : "N m s/rad"));
    add(k + ".friction_link_share", &t.friction_link_share,
        "share of the joint's friction on the link side of the cable, 0..1");
  }
  add("friction.preset", &c.friction_preset, "real | hysteretic | smooth (applied first)");
  for (int j = 0; j < 3; ++j) {
    JointFrictionParams& p = c.friction[static_cast<std::size_t>(j)];
    const std::string k = std::string("friction.") + kJointKeys[j];
    const std::string u = j == 2 ? "N" : "N m";
    const std::string v = j == 2 ? "m/s" : "rad/s";
    const std::string x = j == 2 ? "m" : "rad";
    add(k + ".coulomb_pos", &p.coulomb_pos, "LuGre Coulomb level moving in +q, " + u + " (0 with coulomb_neg: no LuGre element)");
    add(k + ".coulomb_neg", &p.coulomb_neg, "LuGre Coulomb level moving in -q, " + u);
    add(k + ".stiction_ratio", &p.stiction_ratio, "stiction / Coulomb (Stribeck peak), -");
    add(k + ".stribeck_velocity", &p.stribeck_velocity, "Stribeck velocity, " + v);
    add(k + ".viscous", &p.viscous, "viscous coefficient, " + u + " per " + v);
    add(k + ".bristle_stiffness", &p.bristle_stiffness, "LuGre sigma_0, " + u + "/" + x);
    add(k + ".bristle_damping", &p.bristle_damping, "LuGre sigma_1, " + u + " per " + v);
    add(k + ".offset", &p.offset, "constant bias (cable preload), " + u);
    add(k + ".slip_elements", &p.slip_elements,
        "Maxwell-slip elements, each [breakaway displacement " + x + ", force " + u + "], at most " +
            std::to_string(kMaxSlipElements));
    add(k + ".slip_damping", &p.slip_damping, "damping of the slip elements while they stick, " + u + " per " + v);
  }
  auto& C = c.controller;
  add("controller.physics_rate_hz", &C.physics_rate_hz, "integration and control rate, Hz");
  add("controller.kp", &C.kp, "PD stiffness, N m/rad, N m/rad, N/m");
  add("controller.kd", &C.kd, "PD damping, N m s/rad, N m s/rad, N s/m");
  add("controller.feedforward", &C.feedforward, "rigid-body inverse dynamics of the reference fed forward");
  add("controller.velocity_filter_hz", &C.velocity_filter_hz,
      "cut-off of the filter on differentiated encoders, Hz");
  add("controller.settle_s", &C.settle_s, "simulated before the first logged sample, s");
  auto& S = c.sensors;
  add("sensors.log_rate_hz", &S.log_rate_hz, "logging rate, Hz (divides physics_rate_hz)");
  add("sensors.effort_noise", &S.effort_noise, "effort noise std, N m, N m, N");
  add("sensors.position_quantum", &S.position_quantum, "encoder resolution, rad, rad, m");
  add("sensors.velocity_noise", &S.velocity_noise, "logged velocity noise std, rad/s, rad/s, m/s");
  add("sensors.velocity_noise_fade", &S.velocity_noise_fade,
      "motor speed below which the velocity noise fades to 0, rad/s, rad/s, m/s");
  add("sensors.force_noise_n", &S.force_noise_n, "ATI noise std per axis, N");
  add("sensors.repeat_row_probability", &S.repeat_row_probability,
      "probability that a logged row repeats the previous one");
  add("sensors.noise", &S.noise, "false: exact sensors (no noise, no quantization)");
  auto& T = c.trajectory;
  add("trajectory.amplitude", &T.amplitude, "excursion around q0, rad, rad, m");
  add("trajectory.min_frequency_hz", &T.min_frequency_hz, "lowest component, Hz");
  add("trajectory.max_frequency_hz", &T.max_frequency_hz, "highest component (band limit), Hz");
  add("trajectory.harmonics", &T.harmonics, "sinusoids per joint");
  add("trajectory.segment_s", &T.segment_s, "s, a new draw of the harmonics every segment (long recordings)");
  add("trajectory.blend_s", &T.blend_s, "s, cross-fade between segments");
  add("trajectory.pause_fraction", &T.pause_fraction, "share of time in pauses, 0..0.8");
  add("trajectory.pause_min_s", &T.pause_min_s, "shortest pause, s");
  add("trajectory.pause_max_s", &T.pause_max_s, "longest pause, s");
  add("trajectory.max_theta_rad", &T.max_theta_rad, "largest pivot angle the ranges may reach, rad");
  add("trajectory.free_space_path", &T.free_space_path, "free-space recording: teleoperation | excitation | file");
  add("trajectory.free_space_file", &T.free_space_file,
      "file: the joint trajectory CSV the free-space recording plays (rcm excite)");
  add("trajectory.excitation_period_s", &T.excitation_period_s, "excitation: fundamental period, s");
  add("trajectory.excitation_harmonics", &T.excitation_harmonics, "excitation: harmonics of the fundamental");
  add("trajectory.excitation_ramp_s", &T.excitation_ramp_s, "excitation: fade-in from rest at q0, s");
  add("trajectory.excitation_falloff", &T.excitation_falloff,
      "excitation: harmonic k's coefficients drawn with std k^-falloff");
  auto& X = c.tissue;
  add("tissue.preset", &X.preset, "linear | stiffening | viscoelastic | sliding (applied first)");
  add("tissue.stiffness_n_per_m", &X.stiffness_n_per_m, "k1 of g(x) = k1 x + k3 x^3, N/m");
  add("tissue.cubic_n_per_m3", &X.cubic_n_per_m3, "k3 of g, N/m^3");
  add("tissue.damping_n_s_per_m", &X.damping_n_s_per_m, "damping of the stretch rate, N s/m");
  add("tissue.axial_friction_n", &X.axial_friction_n, "sliding friction of the shaft in the incision, N");
  add("tissue.axial_bristle_n_per_m", &X.axial_bristle_n_per_m, "its presliding stiffness, N/m");
  add("tissue.axial_bristle_damping_n_s_per_m", &X.axial_bristle_damping_n_s_per_m,
      "its presliding damping, N s/m");
  add("tissue.min_pad_cosine", &X.min_pad_cosine, "refuse poses with cos(theta) below this");
  auto& P = c.protocol;
  add("protocol.q0", &P.q0, "docking configuration, rad, rad, m");
  add("protocol.free_space_s", &P.free_space_s, "free-space teleoperation, s (total)");
  add("protocol.free_space_files", &P.free_space_files, "split free space into this many files");
  add("protocol.baseline_approach_s", &P.baseline_approach_s, "baseline: approach to q0, s");
  add("protocol.baseline_hold_s", &P.baseline_hold_s, "baseline: hold at q0, s");
  add("protocol.baseline_start_offset", &P.baseline_start_offset,
      "baseline: start pose relative to q0, rad, rad, m");
  add("protocol.calibration_offset_m", &P.calibration_offset_m, "known pure coaxial offset D*, m");
  add("protocol.calibration_s", &P.calibration_s, "calibration teleoperation, s");
  add("protocol.trial_s", &P.trial_s, "trial teleoperation, s");
  add("protocol.trial_paths", &P.trial_paths,
      "own (each trial its own draw of teleoperation) | shared (every trial the calibration's path)");
  add("protocol.static_return_s", &P.static_return_s, "static file: return to q0, s");
  add("protocol.static_hold_s", &P.static_hold_s, "static file: time at q0, shared by its holds, s");
  add("protocol.static_approaches", &P.static_approaches,
      "static file: holds at q0, each approached from the other side (1: the paper's)");
  add("protocol.static_approach_offset", &P.static_approach_offset,
      "static file: how far out the arm goes between holds, rad, rad, m");
  add("protocol.coaxial_offsets_m", &P.coaxial_offsets_m, "trial coaxial offsets D, m");
  add("protocol.radial_offsets_m", &P.radial_offsets_m, "trial radial offsets [dr_x, dr_y], m");
  add("protocol.write_truth", &P.write_truth, "write *_truth.csv next to every recording");
  auto& F = c.force_angle;
  add("force_angle.offsets_m", &F.offsets_m, "coaxial offsets of the sweep, m");
  add("force_angle.angles_deg", &F.angles_deg, "pivot angles, deg, visited in order");
  add("force_angle.pivot_joint", &F.pivot_joint, "1 = yaw, 2 = pitch");
  add("force_angle.move_s", &F.move_s, "move between angles, s");
  add("force_angle.hold_s", &F.hold_s, "hold at each angle, s");
  add("force_angle.average_s", &F.average_s, "averaged at the end of each hold, s");
  add("force_angle.plot", &F.plot, "draw force_angle.png/.svg with gnuplot");
  auto& V = c.speed;
  add("speed.duration_s", &V.duration_s, "speed experiment: full-speed recording after the fade-in, s");
  add("speed.slowdown", &V.slowdown,
      "speed experiment: the slow run's period and duration x this, its log rate / this");
  add("speed.period_s", &V.period_s, "speed experiment: the path's fundamental period at full speed, s");
  add("speed.harmonics", &V.harmonics, "speed experiment: harmonics of the fundamental");
  add("speed.ramp_s", &V.ramp_s, "speed experiment: fade-in from rest at q0 at full speed, s");
  add("speed.amplitude", &V.amplitude, "speed experiment: the path's bound around q0, rad, rad, m");
  add("speed.falloff", &V.falloff, "speed experiment: harmonic k's coefficients drawn with std k^-falloff");
  return f;
}

std::string value_to_text(const FieldRef& ref) {
  struct V {
    std::string operator()(const double* d) const { return fmt::format("{}", *d); }
    std::string operator()(const int* i) const { return std::to_string(*i); }
    std::string operator()(const bool* b) const { return *b ? "true" : "false"; }
    std::string operator()(const std::string* s) const { return "\"" + *s + "\""; }
    std::string operator()(const std::uint64_t* u) const { return std::to_string(*u); }
    std::string operator()(const Eigen::Vector3d* v) const {
      return fmt::format("[{}, {}, {}]", (*v)[0], (*v)[1], (*v)[2]);
    }
    std::string operator()(const std::vector<double>* v) const {
      std::string s = "[";
      for (std::size_t i = 0; i < v->size(); ++i) s += (i ? ", " : "") + fmt::format("{}", (*v)[i]);
      return s + "]";
    }
    std::string operator()(const std::vector<Eigen::Vector2d>* v) const {
      std::string s = "[";
      for (std::size_t i = 0; i < v->size(); ++i)
        s += (i ? ", " : "") + fmt::format("[{}, {}]", (*v)[i].x(), (*v)[i].y());
      return s + "]";
    }
  };
  return std::visit(V{}, ref);
}

nlohmann::json value_to_json(const FieldRef& ref) {
  struct V {
    nlohmann::json operator()(const double* d) const { return *d; }
    nlohmann::json operator()(const int* i) const { return *i; }
    nlohmann::json operator()(const bool* b) const { return *b; }
    nlohmann::json operator()(const std::string* s) const { return *s; }
    nlohmann::json operator()(const std::uint64_t* u) const { return *u; }
    nlohmann::json operator()(const Eigen::Vector3d* v) const { return {(*v)[0], (*v)[1], (*v)[2]}; }
    nlohmann::json operator()(const std::vector<double>* v) const { return *v; }
    nlohmann::json operator()(const std::vector<Eigen::Vector2d>* v) const {
      nlohmann::json a = nlohmann::json::array();
      for (const auto& p : *v) a.push_back({p.x(), p.y()});
      return a;
    }
  };
  return std::visit(V{}, ref);
}

[[noreturn]] void fail(const std::string& source, const std::string& field, const std::string& what) {
  detail::fail_config_field(source, field, what);
}

std::string type_name(const nlohmann::json& j) { return j.type_name(); }

double read_number(const nlohmann::json& j, const std::string& source, const std::string& path) {
  if (!j.is_number()) fail(source, path, "expected a number, got " + type_name(j));
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail(source, path, "expected a finite number");
  return v;
}

void assign(const FieldRef& ref, const nlohmann::json& j, const std::string& source,
            const std::string& path) {
  struct V {
    const nlohmann::json& j;
    const std::string& source;
    const std::string& path;
    void operator()(double* d) const { *d = read_number(j, source, path); }
    void operator()(int* i) const {
      if (!j.is_number_integer()) fail(source, path, "expected an integer, got " + type_name(j));
      *i = j.get<int>();
    }
    void operator()(bool* b) const {
      if (!j.is_boolean()) fail(source, path, "expected true or false, got " + type_name(j));
      *b = j.get<bool>();
    }
    void operator()(std::string* s) const {
      if (!j.is_string()) fail(source, path, "expected a string, got " + type_name(j));
      *s = j.get<std::string>();
    }
    void operator()(std::uint64_t* u) const {
      if (!j.is_number_integer() || (j.is_number_integer() && !j.is_number_unsigned() && j.get<long long>() < 0))
        fail(source, path, "expected a non-negative integer, got " + j.dump());
      *u = j.get<std::uint64_t>();
    }
    void operator()(Eigen::Vector3d* v) const {
      if (!j.is_array() || j.size() != 3)
        fail(source, path, "expected an array of 3 numbers, got " + j.dump());
      for (int k = 0; k < 3; ++k) (*v)[k] = read_number(j[static_cast<std::size_t>(k)], source, path + fmt::format("[{}]", k));
    }
    void operator()(std::vector<double>* v) const {
      if (!j.is_array()) fail(source, path, "expected an array of numbers, got " + type_name(j));
      v->clear();
      for (std::size_t k = 0; k < j.size(); ++k)
        v->push_back(read_number(j[k], source, path + fmt::format("[{}]", k)));
    }
    void operator()(std::vector<Eigen::Vector2d>* v) const {
      if (!j.is_array()) fail(source, path, "expected an array of [x, y] pairs, got " + type_name(j));
      v->clear();
      for (std::size_t k = 0; k < j.size(); ++k) {
        const std::string p = path + fmt::format("[{}]", k);
        if (!j[k].is_array() || j[k].size() != 2) fail(source, p, "expected [x, y], got " + j[k].dump());
        v->emplace_back(read_number(j[k][0], source, p + "[0]"), read_number(j[k][1], source, p + "[1]"));
      }
    }
  };
  std::visit(V{j, source, path}, ref);
}

void walk(const nlohmann::json& j, const std::string& prefix, const std::map<std::string, FieldRef>& fields,
          const std::set<std::string>& sections, const std::string& source) {
  if (!j.is_object())
    fail(source, prefix.empty() ? "(top level)" : prefix, "expected an object, got " + type_name(j));
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string path = prefix.empty() ? it.key() : prefix + "." + it.key();
    if (path == "tissue.preset") continue;  // applied before the walk
    auto f = fields.find(path);
    if (f != fields.end()) {
      assign(f->second, it.value(), source, path);
    } else if (sections.count(path)) {
      walk(it.value(), path, fields, sections, source);
    } else {
      std::string known;
      for (const auto& [k, v] : fields) {
        (void)v;
        const bool under = prefix.empty() ? k.find('.') == std::string::npos
                                          : k.rfind(prefix + ".", 0) == 0 &&
                                                k.find('.', prefix.size() + 1) == std::string::npos;
        if (under) known += (known.empty() ? "" : ", ") + k.substr(prefix.empty() ? 0 : prefix.size() + 1);
      }
      for (const auto& s : sections) {
        const bool under = prefix.empty() ? s.find('.') == std::string::npos
                                          : s.rfind(prefix + ".", 0) == 0 &&
                                                s.find('.', prefix.size() + 1) == std::string::npos;
        if (under) known += (known.empty() ? "" : ", ") + s.substr(prefix.empty() ? 0 : prefix.size() + 1);
      }
      fail(source, path, "unknown key; known here: " + known);
    }
  }
}

}  // namespace

void apply_config_json(SimConfig& config, const nlohmann::json& json, const std::string& source) {
  if (!json.is_object()) fail(source, "(top level)", "expected a JSON object");
  if (json.contains("tissue") && json["tissue"].is_object() && json["tissue"].contains("preset")) {
    const auto& p = json["tissue"]["preset"];
    if (!p.is_string()) fail(source, "tissue.preset", "expected a string, got " + type_name(p));
    try {
      apply_tissue_preset(config.tissue, p.get<std::string>());
    } catch (const InputError& e) {
      fail(source, "tissue.preset", e.reason());
    }
  }
  if (json.contains("arm") && json["arm"].is_object() && json["arm"].contains("preset")) {
    const auto& p = json["arm"]["preset"];
    if (!p.is_string()) fail(source, "arm.preset", "expected a string, got " + type_name(p));
    try {
      apply_arm_preset(config, p.get<std::string>());
    } catch (const InputError& e) {
      fail(source, "arm.preset", e.reason());
    }
  }
  if (json.contains("friction") && json["friction"].is_object() && json["friction"].contains("preset")) {
    const auto& p = json["friction"]["preset"];
    if (!p.is_string()) fail(source, "friction.preset", "expected a string, got " + type_name(p));
    try {
      apply_friction_preset(config, p.get<std::string>());
    } catch (const InputError& e) {
      fail(source, "friction.preset", e.reason());
    }
  }
  std::map<std::string, FieldRef> fields;
  std::set<std::string> sections;
  for (auto& f : get_fields(config)) {
    fields.emplace(f.path, f.ref);
    for (std::size_t pos = f.path.find('.'); pos != std::string::npos; pos = f.path.find('.', pos + 1))
      sections.insert(f.path.substr(0, pos));
  }
  walk(json, "", fields, sections, source);
}

nlohmann::json config_to_json(const SimConfig& config) {
  SimConfig copy = config;
  nlohmann::json out = nlohmann::json::object();
  for (const auto& f : get_fields(copy)) {
    nlohmann::json* node = &out;
    std::size_t start = 0;
    for (std::size_t pos = f.path.find('.'); pos != std::string::npos; pos = f.path.find('.', start)) {
      node = &(*node)[f.path.substr(start, pos - start)];
      start = pos + 1;
    }
    (*node)[f.path.substr(start)] = value_to_json(f.ref);
  }
  return out;
}

void save_config(const std::filesystem::path& path, const SimConfig& config) {
  save_json_file(path, config_to_json(config));
}

SimConfig load_config(const std::filesystem::path& path) {
  SimConfig c = make_default_config();
  apply_config_json(c, load_json_file(path), path.string());
  validate_config(c, path.string());
  return c;
}

std::vector<ConfigFieldDoc> describe_config(const SimConfig& config) {
  SimConfig copy = config;
  std::vector<ConfigFieldDoc> out;
  for (const auto& f : get_fields(copy)) out.push_back({f.path, value_to_text(f.ref), f.help});
  return out;
}

}  // namespace rcm::sim
