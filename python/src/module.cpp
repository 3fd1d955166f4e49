// The compiled half of the Python package `rcm`: rcm::core (no LibTorch) for
// Python, as the extension `rcm._core`, whose every public name the package
// (python/rcm/__init__.py) re-exports. See docs/howto-python.md.

#include "common.hpp"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() =
      "Sensorless RCM misalignment estimation for the dVRK PSM (the rcm C++ library).\n\n"
      "SI units throughout (m, rad, s, N, N m). Arrays are numpy float64; T x N arrays have one row per\n"
      "sample. Bad input raises rcm.InputError (a ValueError) naming the file, line and column or field.\n"
      "Submodules: rcm.dynamics (free-space torque models), rcm.sim (the simulated bench), rcm.batch (many\n"
      "sessions or seeds side by side on Dask; docs/howto-batch.md).";
  m.attr("__version__") = RCM_VERSION;

  // rcm.InputError: the C++ InputError with its location kept as attributes, so
  // that a caller can point at the file without parsing the message.
  static py::exception<rcm::InputError> input_error(m, "InputError", PyExc_ValueError);
  input_error.doc() =
      "Bad user input (malformed file, missing column, NaN, non-increasing time, wrong array shape...).\n"
      "str(e) is the full located message, e.g. 'free_space.csv:1204: column effort_2: expected a number,\n"
      "got 'nan''. Attributes: file (str or None), line (int or None, 1-based), column (int or None),\n"
      "field (str or None: CSV column, JSON field path or argument name), reason (the message without the place).";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const rcm::InputError& e) {
      const rcm::InputLocation& w = e.where();
      py::object error = py::reinterpret_borrow<py::object>(input_error.ptr())(e.what());
      error.attr("file") = w.file.empty() ? py::none() : py::object(py::str(w.file));
      error.attr("line") = w.line == 0 ? py::none() : py::object(py::int_(w.line));
      error.attr("column") = w.column == 0 ? py::none() : py::object(py::int_(w.column));
      error.attr("field") = w.field.empty() ? py::none() : py::object(py::str(w.field));
      error.attr("reason") = py::str(e.reason());
      PyErr_SetObject(input_error.ptr(), error.ptr());
    }
  });

  py::module_ dynamics = m.def_submodule("dynamics", "Free-space joint torque models tau_fs = f(q, qdot, history)");
  py::module_ sim = m.def_submodule("sim", "The simulated phantom bench (docs/simulator.md)");
  // So that `import rcm.dynamics` works as well as `rcm.dynamics` after `import rcm`.
  py::module_::import("sys").attr("modules")["rcm.dynamics"] = dynamics;
  py::module_::import("sys").attr("modules")["rcm.sim"] = sim;
  rcm::python::bind_io(m);
  rcm::python::bind_kinematics(m);
  rcm::python::bind_dynamics(m, dynamics);
  rcm::python::bind_force(m);
  rcm::python::bind_tissue(m);
  rcm::python::bind_estimation(m);
  rcm::python::bind_online(m);
  rcm::python::bind_study(m);
  rcm::python::bind_sim(m, sim);
  rcm::python::bind_plot(m);
}
