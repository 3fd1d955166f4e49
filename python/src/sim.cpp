// rcm.sim: the simulated phantom bench (docs/simulator.md). The configuration
// crosses into Python as a dict in the JSON layout of `rcm simulate --config`,
// so that one table of fields (src/sim/sim_config.cpp) keeps load, save and Python in step.

#include "common.hpp"
#include "rcm/sim/bench.hpp"
#include "rcm/sim/sim_config.hpp"

namespace rcm::python {

namespace {

void update_config(sim::SimConfig& config, py::handle values, const std::string& source) {
  nlohmann::json j;
  try {
    j = to_json(values);
  } catch (py::error_already_set& e) {
    throw InputError(argument_location(source, "values"), std::string("not JSON-serializable: ") + e.what());
  }
  sim::apply_config_json(config, j, source);
}

}  // namespace

void bind_sim(py::module_& m, py::module_& s) {
  (void)m;
  using namespace rcm::sim;
  py::class_<SimConfig>(s, "SimConfig",
                        "Every number of the simulated bench, with the defaults of docs/simulator.md. Read and change\n"
                        "it as a dict in the layout of `rcm simulate --config` (to_dict / update).")
      .def(py::init(&make_default_config), "The defaults")
      .def_readwrite("seed", &SimConfig::seed)
      .def_readwrite("robot", &SimConfig::robot)
      .def_readwrite("threads", &SimConfig::threads, "recordings are independent; results do not depend on it")
      .def("to_dict", [](const SimConfig& c) { return to_python(config_to_json(c)); }, "The resolved configuration")
      .def("update", [](SimConfig& c, py::handle values, const std::string& source) { update_config(c, values, source); },
           py::arg("values"), py::arg("source") = "<dict>",
           "Override fields from a (nested, partial) dict; unknown keys and wrong types raise rcm.InputError\n"
           "naming the path. tissue.preset, when present, is applied before explicit tissue fields.")
      .def("validate", [](const SimConfig& c, const std::string& source) { validate_config(c, source); },
           py::arg("source") = "config", "rcm.InputError naming the field of any inconsistent value")
      .def("__repr__", [](const SimConfig& c) {
        return "<rcm.sim.SimConfig seed " + std::to_string(c.seed) + ", tissue " + c.tissue.preset + ">";
      });
  s.def("make_default_config", &make_default_config);
  s.def("load_config", &load_config, py::arg("path"), "Defaults + a JSON file, validated");
  s.def("save_config", &save_config, py::arg("path"), py::arg("config"));
  s.def("get_tissue_preset_names", &get_tissue_preset_names);
  s.def("apply_tissue_preset", [](SimConfig& c, const std::string& name) { apply_tissue_preset(c.tissue, name); },
        py::arg("config"), py::arg("name"), "Set every tissue field of config to the named preset");
  // `rcm simulate --quick` (apps/rcm/cmd_simulate.cpp): config.update(rcm.sim.QUICK_PROTOCOL).
  s.attr("QUICK_PROTOCOL") = to_python(nlohmann::json{
      {"protocol", {{"free_space_s", 120.0}, {"calibration_s", 30.0}, {"trial_s", 30.0}, {"static_hold_s", 5.0}}}});

  py::class_<SimTruth>(s, "SimTruth", "Ground truth per logged sample (T rows)")
      .def_readonly("q", &SimTruth::q, "(T, 3) true joint positions")
      .def_readonly("qd", &SimTruth::qd)
      .def_readonly("qdd", &SimTruth::qdd)
      .def_readonly("tau", &SimTruth::tau, "(T, 3) actuator effort without sensor noise")
      .def_readonly("tau_fs", &SimTruth::tau_fs, "(T, 3) what a perfect free-space model predicts")
      .def_readonly("friction", &SimTruth::friction)
      .def_readonly("force", &SimTruth::force, "(T, 3) tissue force on the tissue, base frame")
      .def_readonly("theta", &SimTruth::theta)
      .def_readonly("shaft_distance", &SimTruth::shaft_distance);
  py::class_<SimulatedRecording>(s, "SimulatedRecording")
      .def_readonly("name", &SimulatedRecording::name)
      .def_readonly("recording", &SimulatedRecording::recording, "the rcm.Recording the sensors logged")
      .def_readonly("truth", &SimulatedRecording::truth)
      .def_readonly("tissue_engaged", &SimulatedRecording::tissue_engaged)
      .def_readonly("misalignment_m", &SimulatedRecording::misalignment_m);
  py::class_<SimulatedTrial>(s, "SimulatedTrial")
      .def_readonly("name", &SimulatedTrial::name)
      .def_readonly("misalignment_m", &SimulatedTrial::misalignment_m)
      .def_readonly("recording", &SimulatedTrial::recording, "teleoperation (SimulatedRecording)")
      .def_readonly("static_recording", &SimulatedTrial::static_recording, "return to q0 and hold");
  auto released = [](auto f) {
    return [f](const SimConfig& c) {
      py::gil_scoped_release release;
      return f(c);
    };
  };
  s.def("simulate_free_space", [](const SimConfig& c, int index) {
    py::gil_scoped_release release;
    return simulate_free_space(c, index);
  }, py::arg("config"), py::arg("index") = 0, "One free-space recording of the session's protocol");
  s.def("simulate_baseline", released([](const SimConfig& c) { return simulate_baseline(c); }), py::arg("config"));
  s.def("simulate_calibration", released([](const SimConfig& c) { return simulate_calibration(c); }), py::arg("config"));
  s.def("simulate_trial", [](const SimConfig& c, py::handle misalignment) {
    const Eigen::Vector3d p = to_vector3(misalignment, argument_location("rcm.sim.simulate_trial", "misalignment_m"));
    py::gil_scoped_release release;
    return simulate_trial(c, p);
  }, py::arg("config"), py::arg("misalignment_m"), "Teleoperation and static hold under [dr_x, dr_y, D] (m)");
  s.def("get_trial_name", [](py::handle p) {
    return get_trial_name(to_vector3(p, argument_location("rcm.sim.get_trial_name", "misalignment_m")));
  }, py::arg("misalignment_m"), "'D30_r10_15' for [0.010, 0.015, 0.030]");
  s.def("save_truth_csv", &save_truth_csv, py::arg("path"), py::arg("recording"));

  py::class_<RecordingFileInfo>(s, "RecordingFileInfo")
      .def_readonly("name", &RecordingFileInfo::name)
      .def_readonly("file", &RecordingFileInfo::file)
      .def_readonly("truth_file", &RecordingFileInfo::truth_file)
      .def_readonly("samples", &RecordingFileInfo::samples)
      .def_readonly("duration_s", &RecordingFileInfo::duration_s)
      .def_readonly("force_max_n", &RecordingFileInfo::force_max_n)
      .def_readonly("theta_max_rad", &RecordingFileInfo::theta_max_rad);
  py::class_<SessionWriteSummary>(s, "SessionWriteSummary")
      .def_readonly("manifest", &SessionWriteSummary::manifest, "path of session.json")
      .def_readonly("recordings", &SessionWriteSummary::recordings)
      .def_readonly("elapsed_s", &SessionWriteSummary::elapsed_s);
  s.def("simulate_session", [](const SimConfig& c, const std::filesystem::path& out_dir, py::object progress) {
    std::function<void(const std::string&)> report;
    // A bare handle: the callback may run on the simulator's worker threads, where
    // only code holding the GIL may touch reference counts.
    const py::handle callback = progress;
    if (!progress.is_none())
      report = [callback](const std::string& message) {
        py::gil_scoped_acquire gil;
        callback(message);
      };
    py::gil_scoped_release release;
    return simulate_session(c, out_dir, report);
  }, py::arg("config"), py::arg("out_dir"), py::arg("progress") = py::none(),
        "Write a whole rcm-session/1 session (recordings, *_truth.csv, sim_config.json, session.json) under\n"
        "out_dir, as `rcm simulate`; files do not depend on config.threads. progress(str) is called per file.");

  py::class_<ForceAnglePoint>(s, "ForceAnglePoint")
      .def_readonly("offset_m", &ForceAnglePoint::offset_m)
      .def_readonly("theta_rad", &ForceAnglePoint::theta_rad)
      .def_readonly("theta_true_rad", &ForceAnglePoint::theta_true_rad)
      .def_readonly("force_n", &ForceAnglePoint::force_n)
      .def_readonly("force_std_n", &ForceAnglePoint::force_std_n)
      .def_readonly("force_true_n", &ForceAnglePoint::force_true_n)
      .def_readonly("force_law_n", &ForceAnglePoint::force_law_n);
  py::class_<ForceAngleResult>(s, "ForceAngleResult").def_readonly("points", &ForceAngleResult::points);
  s.def("run_force_angle_experiment", released([](const SimConfig& c) { return run_force_angle_experiment(c); }),
        py::arg("config"), "Fig. 3: static |f| at the incision vs pivot angle for several offsets");
  s.def("save_force_angle_csv", &save_force_angle_csv, py::arg("path"), py::arg("result"));
}

}  // namespace rcm::python
