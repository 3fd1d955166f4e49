#pragma once
// Shared by the translation units of the Python module: array conversion with
// located errors, read-only views of Eigen data, JSON <-> Python.
//
// Conversion rule (docs/python.md, "Arrays"): every array argument goes through
// numpy.asarray, then must have exactly the expected number of dimensions (a
// 1-D array is never reshaped into a T x 1 matrix) and a dtype whose values
// float64 holds exactly: floating point up to 64 bits, or integers that are all
// within +-2^53. Anything else (bool, complex, object, long double, a huge
// integer) is an rcm.InputError naming the argument, never a silent cast.

#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>
#include <pybind11/stl_bind.h>

#include <Eigen/Core>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/estimation/joint.hpp"
#include "rcm/kinematics/psm_model.hpp"

// The joint estimator's samples stay a C++ vector on the Python side (an opaque
// list-like object): they are thousands of small structs that only the C++ code reads.
PYBIND11_MAKE_OPAQUE(std::vector<rcm::JointSample>)

namespace rcm::python {

namespace py = pybind11;

// Where a Python argument came from, for InputError: "rcm.Recording: position: ...".
InputLocation argument_location(const std::string& function, const std::string& argument);

// See the file comment. `columns` / `rows` / `size` < 0: any. `finite`: also
// reject NaN and inf (recordings leave that check to validate_recording, whose
// message names the sample).
Eigen::MatrixXd to_matrix(py::handle object, const InputLocation& where, Eigen::Index rows = -1,
                          Eigen::Index columns = -1, bool finite = true);
Eigen::VectorXd to_vector(py::handle object, const InputLocation& where, Eigen::Index size = -1,
                          bool finite = true);
Eigen::Vector3d to_vector3(py::handle object, const InputLocation& where);
double to_finite(double value, const InputLocation& where);

// Read-only numpy views of Eigen storage kept alive by `owner` (the Python object
// that holds the C++ value). Read-only because the owners are validated,
// immutable models; a caller who wants to edit takes .copy().
py::array readonly_view(const Eigen::MatrixXd& matrix, py::handle owner);
py::array readonly_view(const Eigen::VectorXd& vector, py::handle owner);

// nlohmann::json <-> plain Python objects (dict, list, float, ...), through the
// json module so that both sides agree on every corner case.
py::object to_python(const nlohmann::json& value);
nlohmann::json to_json(py::handle value);

// A robot argument: an rcm.PsmModel, or a built-in name or rcm-robot/1 file
// (load_robot_model; rcm.InputError otherwise).
PsmModel resolve_robot(py::handle robot);

// Area bindings, called in this order from module.cpp.
void bind_io(py::module_& m);
void bind_kinematics(py::module_& m);
void bind_dynamics(py::module_& m, py::module_& dynamics);
void bind_force(py::module_& m);
void bind_tissue(py::module_& m);
void bind_estimation(py::module_& m);
void bind_online(py::module_& m);
void bind_study(py::module_& m);
void bind_sim(py::module_& m, py::module_& sim);
void bind_plot(py::module_& m);

}  // namespace rcm::python
