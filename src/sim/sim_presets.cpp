// The simulator's defaults (make_default_config: a Classic PSM on the phantom
// bench) and its friction and tissue presets (docs/simulator.md).

#include "rcm/common/error.hpp"
#include "rcm/sim/sim_config.hpp"

namespace rcm::sim {

namespace {

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
  // 0.85 kg on the insertion axis; yaw link COM 8 cm below the RCM. The
  // parallelogram is counterweighted against the insertion stage (its lumped COM
  // 2.9 cm below the RCM): the pitch's gravity torque is 0.2 N m per unit
  // sin(q2) at q3 = 0.12 m, and changes by 8.3 N m per metre of insertion, so
  // that over the real Classic PSM's recorded pitch range it spans a few tenths
  // of a N m, as there (docs/validation.md, "Real friction").
  c.arm.yaw_link = {1.0, Eigen::Vector3d(0.0, 0.0, -0.08), Eigen::Vector3d(0.010, 0.0076, 0.010)};
  c.arm.pitch_link = {2.2, Eigen::Vector3d(0.0, 0.0, 0.0294), Eigen::Vector3d(0.1156, 0.1696, 0.020)};
  c.arm.insertion_stage = {0.85, Eigen::Vector3d(0.0, 0.0, -0.22), Eigen::Vector3d(0.020, 0.020, 0.001)};
  c.arm.gravity_base_m_s2 = Eigen::Vector3d(0.0, 0.0, -9.81);
  c.arm.insertion_counterbalance_n = 7.0;
  // The elastic element along the real Classic PSM's insertion: rcm's fit
  // finds 1.6-2.0 N/m on its recordings.
  c.arm.insertion_stiffness_n_per_m = 1.8;
  apply_arm_preset(c, "rigid");
  apply_friction_preset(c, "real");
  apply_tissue_preset(c.tissue, "linear");
  return c;
}

std::vector<std::string> get_friction_preset_names() { return {"real", "hysteretic", "smooth"}; }

void apply_friction_preset(SimConfig& c, const std::string& name) {
  for (auto& f : c.friction) f = JointFrictionParams{};
  if (name == "real") {
    // Identified on real Classic PSM1 recordings by bench/real_friction_fit.py
    // (docs/validation.md, "Real friction"): Maxwell-slip elements whose
    // breakaway displacements spread from a fraction of a milliradian to tens of
    // them (tenths of a millimetre to millimetres on the insertion), so that the
    // friction builds over the travel after a reversal as the real arm's does and
    // a joint at rest keeps whatever its last motion left, plus the viscous
    // friction the fit found. No LuGre element. The offsets are the hysteretic
    // preset's (a constant torque the recordings cannot tell from gravity), the
    // damping while sticking its bristle damping (the recordings are too slow to
    // show it).
    c.friction[0].slip_elements = {{5.0e-5, 0.0233}, {5.87e-4, 0.0076}, {2.01e-3, 0.0082},
                                  {3.73e-3, 0.0079}, {6.90e-3, 0.0405}, {1.28e-2, 0.0135}};
    c.friction[0].viscous = 0.1425;
    c.friction[0].offset = 0.008;
    c.friction[0].slip_damping = 1.0;
    c.friction[1].slip_elements = {{5.0e-5, 0.0158},  {3.17e-4, 0.0093}, {5.87e-4, 0.0211}, {3.73e-3, 0.0419},
                                  {6.90e-3, 0.0469}, {2.36e-2, 0.0117}, {4.38e-2, 0.0037}, {8.10e-2, 0.0597}};
    c.friction[1].viscous = 0.1493;
    c.friction[1].offset = -0.012;
    c.friction[1].slip_damping = 2.0;
    c.friction[2].slip_elements = {{5.0e-6, 0.125},   {3.17e-5, 0.0354}, {5.87e-5, 0.0667}, {1.09e-4, 0.1008},
                                  {2.01e-4, 0.1132}, {3.73e-4, 0.0571}, {1.28e-3, 0.0446}};
    c.friction[2].viscous = 0.0;
    c.friction[2].slip_damping = 40.0;
    for (auto& f : c.friction) f.coulomb_pos = f.coulomb_neg = 0.0;
  } else if (name == "hysteretic") {
    // The real Classic PSM: friction that barely depends on speed and keeps what
    // the last motion left, so a joint at rest holds anywhere in a band of about
    // +-0.12 / +-0.24 N m / +-0.6 N. Coulomb levels at the band, a little viscous
    // friction, no Stribeck peak; the bristles take 2 mrad / 0.2 mm to reverse.
    c.friction[0] = {0.125, 0.115, 1.0, 0.02, 0.01, 60.0, 1.0, 0.008, {}, 0.0};
    c.friction[1] = {0.25, 0.23, 1.0, 0.02, 0.02, 120.0, 2.0, -0.012, {}, 0.0};
    c.friction[2] = {0.58, 0.62, 1.0, 0.004, 0.2, 3000.0, 40.0, 0.0, {}, 0.0};
  } else if (name == "smooth") {
    // Smaller Coulomb levels with a Stribeck peak and stiff bristles, and most of
    // the friction viscous: Coulomb ~0.050 / 0.067 N m and 0.45 / 0.58 N, viscous
    // 0.09 / 0.22 N m s/rad and 1.2 N s/m.
    c.friction[0] = {0.052, 0.048, 1.3, 0.02, 0.09, 500.0, 2.0, 0.008, {}, 0.0};
    c.friction[1] = {0.070, 0.064, 1.3, 0.02, 0.22, 600.0, 2.5, -0.012, {}, 0.0};
    c.friction[2] = {0.45, 0.58, 1.25, 0.004, 1.2, 2.5e4, 40.0, 0.0, {}, 0.0};
  } else {
    throw_unknown_preset("friction", name, get_friction_preset_names());
  }
  c.friction_preset = name;
}

std::vector<std::string> get_arm_preset_names() { return {"rigid", "cable"}; }

void apply_arm_preset(SimConfig& c, const std::string& name) {
  if (name == "cable") {
    // The Classic PSM's joints: brushed DC motors with encoders and current
    // sensing drive the links through gearheads and steel cables
    // (docs/simulator.md, "Cable transmission"). Rotors: a 40 mm motor and its
    // gearhead (about 1.4e-5 kg m^2) behind a total reduction of about 80:1 on
    // yaw and 65:1 on pitch reflect 0.09 and 0.06 kg m^2; 0.10 kg on the
    // insertion. Stiffness: the link against a motor held still rings at 6 Hz
    // on yaw and pitch and at 11.5 Hz on the insertion (4.5 Hz on yaw and pitch
    // with the bench's servo), the few-to-15 Hz of a cable-driven arm of this
    // size; damping 10 % of critical. Half the friction on each side of the cable.
    c.arm.transmission[0] = {0.09, 227.4, 1.206, 0.5};
    c.arm.transmission[1] = {0.06, 284.2, 1.508, 0.5};
    c.arm.transmission[2] = {0.10, 4438.0, 12.28, 0.5};
    // White effort noise and the published velocity's noise of the size seen
    // on the real Classic PSM1 recordings (second differences at 100 and 200 Hz):
    // the cables, not white noise, make the effort's high-frequency content.
    c.sensors.effort_noise = Eigen::Vector3d(0.009, 0.007, 0.05);
    c.sensors.velocity_noise = Eigen::Vector3d(0.010, 0.010, 0.002);
  } else if (name == "rigid") {
    // The links driven directly, in the model family of rcm's rigid-body fit.
    // With no cables to make it, the effort's high-frequency content is white
    // noise of the size measured on the real arm above 5 Hz, and the velocity
    // is the controller's filtered encoder difference.
    for (auto& t : c.arm.transmission) t = JointTransmissionParams{};
    c.sensors.effort_noise = Eigen::Vector3d(0.007, 0.007, 0.195);
    c.sensors.velocity_noise = Eigen::Vector3d::Zero();
  } else {
    throw_unknown_preset("arm", name, get_arm_preset_names());
  }
  c.arm.preset = name;
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

}  // namespace rcm::sim
