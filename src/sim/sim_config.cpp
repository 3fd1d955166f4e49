#include "rcm/sim/sim_config.hpp"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm::sim {

namespace {

using FieldRef = std::variant<double*, int*, bool*, std::string*, std::uint64_t*, Eigen::Vector3d*,
                              std::vector<double>*, std::vector<Eigen::Vector2d>*>;

struct Field {
  std::string path;
  FieldRef ref;
  std::string help;
};

const char* kJointKeys[3] = {"yaw", "pitch", "insertion"};

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
  add("friction.preset", &c.friction_preset, "hysteretic | smooth (applied first)");
  for (int j = 0; j < 3; ++j) {
    JointFrictionParams& p = c.friction[static_cast<std::size_t>(j)];
    const std::string k = std::string("friction.") + kJointKeys[j];
    const std::string u = j == 2 ? "N" : "N m";
    const std::string v = j == 2 ? "m/s" : "rad/s";
    const std::string x = j == 2 ? "m" : "rad";
    add(k + ".coulomb_pos", &p.coulomb_pos, "Coulomb level moving in +q, " + u);
    add(k + ".coulomb_neg", &p.coulomb_neg, "Coulomb level moving in -q, " + u);
    add(k + ".stiction_ratio", &p.stiction_ratio, "stiction / Coulomb (Stribeck peak), -");
    add(k + ".stribeck_velocity", &p.stribeck_velocity, "Stribeck velocity, " + v);
    add(k + ".viscous", &p.viscous, "viscous coefficient, " + u + " per " + v);
    add(k + ".bristle_stiffness", &p.bristle_stiffness, "LuGre sigma_0, " + u + "/" + x);
    add(k + ".bristle_damping", &p.bristle_damping, "LuGre sigma_1, " + u + " per " + v);
    add(k + ".offset", &p.offset, "constant bias (cable preload), " + u);
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
  add("trajectory.free_space_path", &T.free_space_path, "free-space recording: teleoperation | excitation");
  add("trajectory.excitation_period_s", &T.excitation_period_s, "excitation: fundamental period, s");
  add("trajectory.excitation_harmonics", &T.excitation_harmonics, "excitation: harmonics of the fundamental");
  add("trajectory.excitation_ramp_s", &T.excitation_ramp_s, "excitation: fade-in from rest at q0, s");
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
  InputLocation loc;
  loc.file = source;
  loc.field = field;
  loc.kind = InputLocation::Kind::json_field;
  throw InputError(loc, what);
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

[[noreturn]] void throw_unknown_preset(const std::string& section, const std::string& name,
                                      const std::vector<std::string>& known_names) {
  std::string known;
  for (const auto& n : known_names) known += (known.empty() ? "" : ", ") + n;
  InputLocation loc;
  loc.field = section + ".preset";
  loc.kind = InputLocation::Kind::json_field;
  throw InputError(loc, "unknown " + section + " '" + name + "'; known: " + known);
}

}  // namespace

SimConfig make_default_config() {
  SimConfig c;
  // Mass model: effective inertia ~0.16 (yaw) and ~0.20 kg m^2 (pitch) at q0 and
  // 0.85 kg on the insertion axis; counterweighted parallelogram (COM 11 cm above the RCM),
  // yaw link COM 8 cm below it.
  c.arm.yaw_link = {1.0, Eigen::Vector3d(0.0, 0.0, -0.08), Eigen::Vector3d(0.010, 0.0076, 0.010)};
  c.arm.pitch_link = {2.2, Eigen::Vector3d(0.0, 0.0, -0.11), Eigen::Vector3d(0.0909, 0.1449, 0.020)};
  c.arm.insertion_stage = {0.85, Eigen::Vector3d(0.0, 0.0, -0.22), Eigen::Vector3d(0.020, 0.020, 0.001)};
  c.arm.gravity_base_m_s2 = Eigen::Vector3d(0.0, 0.0, -9.81);
  c.arm.insertion_counterbalance_n = 7.0;
  apply_friction_preset(c, "hysteretic");
  apply_tissue_preset(c.tissue, "linear");
  return c;
}

std::vector<std::string> get_friction_preset_names() { return {"hysteretic", "smooth"}; }

void apply_friction_preset(SimConfig& c, const std::string& name) {
  if (name == "hysteretic") {
    // The real Classic PSM: friction that barely depends on speed and keeps what
    // the last motion left, so a joint at rest holds anywhere in a band of about
    // +-0.12 / +-0.24 N m / +-0.6 N. Coulomb levels at the band, a little viscous
    // friction, no Stribeck peak; the bristles take 2 mrad / 0.2 mm to reverse.
    c.friction[0] = {0.125, 0.115, 1.0, 0.02, 0.01, 60.0, 1.0, 0.008};
    c.friction[1] = {0.25, 0.23, 1.0, 0.02, 0.02, 120.0, 2.0, -0.012};
    c.friction[2] = {0.58, 0.62, 1.0, 0.004, 0.2, 3000.0, 40.0, 0.0};
  } else if (name == "smooth") {
    // Smaller Coulomb levels with a Stribeck peak and stiff bristles, and most of
    // the friction viscous: Coulomb ~0.050 / 0.067 N m and 0.45 / 0.58 N, viscous
    // 0.09 / 0.22 N m s/rad and 1.2 N s/m.
    c.friction[0] = {0.052, 0.048, 1.3, 0.02, 0.09, 500.0, 2.0, 0.008};
    c.friction[1] = {0.070, 0.064, 1.3, 0.02, 0.22, 600.0, 2.5, -0.012};
    c.friction[2] = {0.45, 0.58, 1.25, 0.004, 1.2, 2.5e4, 40.0, 0.0};
  } else {
    throw_unknown_preset("friction", name, get_friction_preset_names());
  }
  c.friction_preset = name;
}

std::vector<std::string> get_tissue_preset_names() {
  return {"linear", "stiffening", "viscoelastic", "sliding"};
}

void apply_tissue_preset(TissueParams& t, const std::string& name) {
  const TissueParams defaults;
  const double min_cos = t.min_pad_cosine;
  t = defaults;
  t.min_pad_cosine = min_cos;
  t.preset = name;
  if (name == "linear") {
    // 875 N/m: 35.0 N at D = 40 mm, 45 deg (Fig. 3); inside the paper's 651-972 N/m band.
    t.stiffness_n_per_m = 875.0;
  } else if (name == "stiffening") {
    // k1 x + k3 x^3 through (20 mm, 12 N) and (40 mm, 35 N): Fig. 3 read literally.
    t.stiffness_n_per_m = 508.33;
    t.cubic_n_per_m3 = 2.2917e5;
  } else if (name == "viscoelastic") {
    t.stiffness_n_per_m = 875.0;
    t.damping_n_s_per_m = 40.0;
  } else if (name == "sliding") {
    t.stiffness_n_per_m = 875.0;
    t.axial_friction_n = 1.5;
  } else {
    throw_unknown_preset("tissue", name, get_tissue_preset_names());
  }
}

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

void validate_config(const SimConfig& c, const std::string& source) {
  auto require = [&](bool ok, const std::string& field, const std::string& what) {
    if (!ok) fail(source, field, what);
  };
  auto positive3 = [&](const Eigen::Vector3d& v, const std::string& field, bool allow_zero) {
    for (int j = 0; j < 3; ++j)
      require(std::isfinite(v[j]) && (allow_zero ? v[j] >= 0 : v[j] > 0),
              field + fmt::format("[{}]", j), allow_zero ? "expected >= 0" : "expected > 0");
  };
  require(c.threads >= 1 && c.threads <= 64, "threads", "expected 1..64");
  const std::pair<const RigidBodyParams*, const char*> bodies[] = {
      {&c.arm.yaw_link, "arm.yaw_link"}, {&c.arm.pitch_link, "arm.pitch_link"},
      {&c.arm.insertion_stage, "arm.insertion_stage"}};
  for (const auto& [b, name] : bodies) {
    require(b->mass_kg >= 0, std::string(name) + ".mass_kg", "expected >= 0");
    positive3(b->inertia_diag_kg_m2, std::string(name) + ".inertia_diag_kg_m2", true);
  }
  require(c.arm.insertion_stage.mass_kg > 0, "arm.insertion_stage.mass_kg",
          "expected > 0 (the insertion axis needs inertia)");
  for (int j = 0; j < 3; ++j) {
    const auto& p = c.friction[static_cast<std::size_t>(j)];
    const std::string k = std::string("friction.") + kJointKeys[j];
    require(p.coulomb_pos > 0, k + ".coulomb_pos", "expected > 0");
    require(p.coulomb_neg > 0, k + ".coulomb_neg", "expected > 0");
    require(p.stiction_ratio >= 1.0, k + ".stiction_ratio", "expected >= 1");
    require(p.stribeck_velocity > 0, k + ".stribeck_velocity", "expected > 0");
    require(p.viscous >= 0, k + ".viscous", "expected >= 0");
    require(p.bristle_stiffness > 0, k + ".bristle_stiffness", "expected > 0");
    require(p.bristle_damping >= 0, k + ".bristle_damping", "expected >= 0");
  }
  const auto& C = c.controller;
  require(C.physics_rate_hz >= 200 && C.physics_rate_hz <= 1e5, "controller.physics_rate_hz",
          "expected 200..100000 Hz");
  positive3(C.kp, "controller.kp", false);
  positive3(C.kd, "controller.kd", true);
  require(C.velocity_filter_hz > 0, "controller.velocity_filter_hz", "expected > 0");
  require(C.settle_s >= 0, "controller.settle_s", "expected >= 0");
  const auto& S = c.sensors;
  require(S.log_rate_hz > 0 && S.log_rate_hz <= C.physics_rate_hz, "sensors.log_rate_hz",
          "expected > 0 and <= controller.physics_rate_hz");
  const double ratio = C.physics_rate_hz / S.log_rate_hz;
  require(std::abs(ratio - std::round(ratio)) < 1e-9, "sensors.log_rate_hz",
          fmt::format("must divide controller.physics_rate_hz ({} / {} is not an integer)",
                      C.physics_rate_hz, S.log_rate_hz));
  positive3(S.effort_noise, "sensors.effort_noise", true);
  positive3(S.position_quantum, "sensors.position_quantum", true);
  require(S.force_noise_n >= 0, "sensors.force_noise_n", "expected >= 0");
  require(S.repeat_row_probability >= 0 && S.repeat_row_probability < 1,
          "sensors.repeat_row_probability", "expected 0 <= p < 1");
  const auto& T = c.trajectory;
  positive3(T.amplitude, "trajectory.amplitude", true);
  require(T.min_frequency_hz > 0, "trajectory.min_frequency_hz", "expected > 0");
  require(T.max_frequency_hz >= T.min_frequency_hz && T.max_frequency_hz <= 5.0,
          "trajectory.max_frequency_hz", "expected min_frequency_hz..5 Hz");
  require(T.harmonics >= 1 && T.harmonics <= 64, "trajectory.harmonics", "expected 1..64");
  require(T.segment_s >= 5.0, "trajectory.segment_s", "expected >= 5 s");
  require(T.blend_s > 0.0 && T.blend_s <= 0.5 * T.segment_s, "trajectory.blend_s", "expected 0 < blend_s <= segment_s / 2");
  require(T.pause_fraction >= 0 && T.pause_fraction <= 0.8, "trajectory.pause_fraction", "expected 0..0.8");
  require(T.pause_min_s > 0 && T.pause_max_s >= T.pause_min_s, "trajectory.pause_max_s",
          "expected 0 < pause_min_s <= pause_max_s");
  require(T.max_theta_rad > 0 && T.max_theta_rad < 1.3, "trajectory.max_theta_rad", "expected 0..1.3 rad");
  require(T.free_space_path == "teleoperation" || T.free_space_path == "excitation", "trajectory.free_space_path",
          "expected teleoperation or excitation, got '" + T.free_space_path + "'");
  require(T.excitation_period_s > 0, "trajectory.excitation_period_s", "expected > 0");
  require(T.excitation_harmonics >= 1 && T.excitation_harmonics <= 50, "trajectory.excitation_harmonics",
          "expected 1..50");
  require(T.excitation_ramp_s > 0, "trajectory.excitation_ramp_s", "expected > 0");
  const auto& X = c.tissue;
  require(X.stiffness_n_per_m >= 0, "tissue.stiffness_n_per_m", "expected >= 0");
  require(X.cubic_n_per_m3 >= 0, "tissue.cubic_n_per_m3", "expected >= 0");
  require(X.damping_n_s_per_m >= 0, "tissue.damping_n_s_per_m", "expected >= 0");
  require(X.axial_friction_n >= 0, "tissue.axial_friction_n", "expected >= 0");
  require(X.axial_bristle_n_per_m > 0, "tissue.axial_bristle_n_per_m", "expected > 0");
  require(X.axial_bristle_damping_n_s_per_m >= 0, "tissue.axial_bristle_damping_n_s_per_m", "expected >= 0");
  require(X.min_pad_cosine > 0 && X.min_pad_cosine < 1, "tissue.min_pad_cosine", "expected 0..1");

  const auto& P = c.protocol;
  // Joint limits come from the robot description, never from this file.
  const PsmModel robot = load_robot_model(c.robot, source + ": field robot");
  {
    InputLocation where;
    where.file = source;
    where.field = "protocol.q0";
    where.kind = InputLocation::Kind::json_field;
    robot.check_within_limits(P.q0, where);
  }
  for (int j = 0; j < 3; ++j) {
    const auto& lim = robot.joints()[static_cast<std::size_t>(j)];
    const std::string field = fmt::format("trajectory.amplitude[{}]", j);
    require(P.q0[j] - T.amplitude[j] >= lim.q_min && P.q0[j] + T.amplitude[j] <= lim.q_max, field,
            fmt::format("q0 +- amplitude leaves the joint range [{}, {}] of {}", lim.q_min, lim.q_max,
                        lim.name));
    const double b = P.baseline_start_offset[j];
    require(P.q0[j] + b >= lim.q_min && P.q0[j] + b <= lim.q_max,
            fmt::format("protocol.baseline_start_offset[{}]", j), "start pose outside the joint range");
  }
  // The largest pivot angle of the teleoperation box is at one of its corners.
  const auto z3 = [](double q1, double q2) {
    return Eigen::Vector3d(std::sin(q1) * std::cos(q2), -std::sin(q2), -std::cos(q1) * std::cos(q2));
  };
  const Eigen::Vector3d n = z3(P.q0[0], P.q0[1]);
  double min_cos = 1.0;
  for (int a = -1; a <= 1; a += 2)
    for (int b = -1; b <= 1; b += 2)
      min_cos = std::min(min_cos, n.dot(z3(P.q0[0] + a * T.amplitude[0], P.q0[1] + b * T.amplitude[1])));
  require(std::acos(std::clamp(min_cos, -1.0, 1.0)) <= T.max_theta_rad, "trajectory.amplitude",
          fmt::format("the ranges reach a pivot angle of {:.1f} deg, above trajectory.max_theta_rad ({:.1f} deg)",
                      std::acos(std::clamp(min_cos, -1.0, 1.0)) * 180 / M_PI, T.max_theta_rad * 180 / M_PI));
  require(min_cos >= X.min_pad_cosine, "trajectory.amplitude",
          "the ranges bring the shaft flatter to the pad than tissue.min_pad_cosine");
  require(P.free_space_s > 0, "protocol.free_space_s", "expected > 0");
  require(P.free_space_files >= 1 && P.free_space_files <= 100, "protocol.free_space_files", "expected 1..100");
  require(P.baseline_approach_s > 0, "protocol.baseline_approach_s", "expected > 0");
  require(P.baseline_hold_s > 0, "protocol.baseline_hold_s", "expected > 0");
  require(P.calibration_s > 0, "protocol.calibration_s", "expected > 0");
  require(P.trial_s > 0, "protocol.trial_s", "expected > 0");
  require(P.static_return_s > 0, "protocol.static_return_s", "expected > 0");
  require(P.static_hold_s > 0, "protocol.static_hold_s", "expected > 0");
  require(P.static_approaches >= 1 && P.static_approaches <= 8, "protocol.static_approaches", "expected 1..8");
  positive3(P.static_approach_offset, "protocol.static_approach_offset", false);
  auto check_offset = [&](double D, const std::string& field) {
    require(D >= -0.02 && D <= 0.07, field, "expected a coaxial offset in [-0.02, 0.07] m");
    // The shaft must reach the pad: the tip is at about q3 along z3.
    require(std::abs(D) / std::max(min_cos, 1e-6) < P.q0[2] - T.amplitude[2], field,
            fmt::format("the pad (up to {:.3f} m along the shaft) lies beyond the shallowest insertion {:.3f} m",
                        std::abs(D) / std::max(min_cos, 1e-6), P.q0[2] - T.amplitude[2]));
  };
  check_offset(P.calibration_offset_m, "protocol.calibration_offset_m");
  for (std::size_t i = 0; i < P.coaxial_offsets_m.size(); ++i)
    check_offset(P.coaxial_offsets_m[i], fmt::format("protocol.coaxial_offsets_m[{}]", i));
  for (std::size_t i = 0; i < P.radial_offsets_m.size(); ++i)
    require(P.radial_offsets_m[i].norm() <= 0.045, fmt::format("protocol.radial_offsets_m[{}]", i),
            "expected a radial offset within the 9 x 9 cm pad (|r| <= 0.045 m)");
  const auto& F = c.force_angle;
  require(F.pivot_joint == 1 || F.pivot_joint == 2, "force_angle.pivot_joint", "expected 1 or 2");
  require(F.move_s > 0 && F.hold_s > 0, "force_angle.hold_s", "expected move_s, hold_s > 0");
  require(F.average_s > 0 && F.average_s <= F.hold_s, "force_angle.average_s", "expected 0 < average_s <= hold_s");
  require(!F.offsets_m.empty() && !F.angles_deg.empty(), "force_angle.offsets_m", "expected at least one offset and angle");
  for (std::size_t i = 0; i < F.angles_deg.size(); ++i) {
    const double a = F.angles_deg[i] * M_PI / 180.0;
    const auto& lim = robot.joints()[static_cast<std::size_t>(F.pivot_joint - 1)];
    require(P.q0[F.pivot_joint - 1] + a >= lim.q_min && P.q0[F.pivot_joint - 1] + a <= lim.q_max &&
                std::cos(a) >= X.min_pad_cosine && std::abs(a) <= T.max_theta_rad + 1e-12,
            fmt::format("force_angle.angles_deg[{}]", i),
            "angle outside the joint range or beyond trajectory.max_theta_rad");
  }
  for (std::size_t i = 0; i < F.offsets_m.size(); ++i)
    require(F.offsets_m[i] >= -0.02 && F.offsets_m[i] <= 0.07 &&
                std::abs(F.offsets_m[i]) / 0.5 < P.q0[2],  // cos(60 deg) = 0.5
            fmt::format("force_angle.offsets_m[{}]", i), "expected [-0.02, 0.07] m, within the insertion depth");
}

}  // namespace rcm::sim
