#include "common.hpp"

#include <cmath>
#include <cstring>

namespace rcm::python {

InputLocation argument_location(const std::string& function, const std::string& argument) {
  return InputLocation::plain(function, argument);
}

namespace {

std::string shape_text(const py::array& a) {
  std::string out = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) out += (d ? ", " : "") + std::to_string(a.shape(d));
  return out + (a.ndim() == 1 ? ",)" : ")");
}

// numpy.asarray(object) as a C-contiguous float64 array, refusing every dtype
// whose values float64 cannot hold exactly.
py::array_t<double, py::array::c_style> as_float64(py::handle object, const InputLocation& where) {
  py::module_ np = py::module_::import("numpy");
  py::array a;
  try {
    a = np.attr("asarray")(object);
  } catch (py::error_already_set& e) {
    throw InputError(where, std::string("expected an array of numbers: ") + e.what());
  }
  const py::dtype dtype = a.dtype();
  const char kind = dtype.kind();
  const std::string name = py::str(static_cast<py::handle>(dtype)).cast<std::string>();
  if (kind == 'f') {
    if (dtype.itemsize() > 8)
      throw InputError(where, "dtype " + name + " would lose precision as float64; convert explicitly with .astype(numpy.float64)");
  } else if (kind == 'i' || kind == 'u') {
    // Integer positions (q = [0, 0, 0]) are common and exact as long as every
    // value fits float64's 53-bit mantissa.
    if (a.size() > 0) {
      constexpr double limit = 9007199254740992.0;  // 2^53
      const double hi = py::float_(a.attr("max")()).cast<double>();
      const double lo = py::float_(a.attr("min")()).cast<double>();
      if (hi > limit || lo < -limit)
        throw InputError(where, "dtype " + name + " holds values beyond 2^53 that float64 cannot represent exactly");
    }
  } else {
    throw InputError(where, "expected real numbers (float64), got dtype " + name);
  }
  return np.attr("ascontiguousarray")(a, py::arg("dtype") = np.attr("float64")).cast<py::array_t<double, py::array::c_style>>();
}

void check_finite(const double* data, py::ssize_t n, py::ssize_t columns, const InputLocation& where) {
  for (py::ssize_t i = 0; i < n; ++i)
    if (!std::isfinite(data[i])) {
      const std::string index =
          columns > 0 ? "[" + std::to_string(i / columns) + ", " + std::to_string(i % columns) + "]" : "[" + std::to_string(i) + "]";
      InputLocation at = where;
      at.field += index;
      throw InputError(at, "not a finite number");
    }
}

}  // namespace

Eigen::MatrixXd to_matrix(py::handle object, const InputLocation& where, Eigen::Index rows, Eigen::Index columns,
                          bool finite) {
  const auto a = as_float64(object, where);
  if (a.ndim() != 2)
    throw InputError(where, "expected a 2-D array (rows x columns), got " + std::to_string(a.ndim()) + "-D with shape " +
                                shape_text(a));
  if ((rows >= 0 && a.shape(0) != rows) || (columns >= 0 && a.shape(1) != columns))
    throw InputError(where, "expected shape (" + (rows >= 0 ? std::to_string(rows) : std::string("T")) + ", " +
                                (columns >= 0 ? std::to_string(columns) : std::string("N")) + "), got " + shape_text(a));
  if (finite) check_finite(a.data(), a.size(), a.shape(1), where);
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  return Eigen::Map<const RowMajor>(a.data(), a.shape(0), a.shape(1));
}

Eigen::VectorXd to_vector(py::handle object, const InputLocation& where, Eigen::Index size, bool finite) {
  const auto a = as_float64(object, where);
  if (a.ndim() != 1)
    throw InputError(where, "expected a 1-D array, got " + std::to_string(a.ndim()) + "-D with shape " + shape_text(a));
  if (size >= 0 && a.shape(0) != size)
    throw InputError(where, "expected " + std::to_string(size) + " values, got " + std::to_string(a.shape(0)));
  if (finite) check_finite(a.data(), a.size(), 0, where);
  return Eigen::Map<const Eigen::VectorXd>(a.data(), a.shape(0));
}

Eigen::Vector3d to_vector3(py::handle object, const InputLocation& where) { return to_vector(object, where, 3); }

double to_finite(double value, const InputLocation& where) {
  if (!std::isfinite(value)) throw InputError(where, "must be a finite number");
  return value;
}

namespace {
py::array make_readonly(py::array a) {
  a.attr("setflags")(py::arg("write") = false);
  return a;
}
}  // namespace

py::array readonly_view(const Eigen::MatrixXd& m, py::handle owner) {
  const std::vector<py::ssize_t> shape{m.rows(), m.cols()};
  if (m.size() == 0) return make_readonly(py::array_t<double>(shape));
  const std::vector<py::ssize_t> strides{static_cast<py::ssize_t>(sizeof(double)),
                                         static_cast<py::ssize_t>(sizeof(double) * m.rows())};
  return make_readonly(py::array(py::dtype::of<double>(), shape, strides, m.data(), owner));
}

py::array readonly_view(const Eigen::VectorXd& v, py::handle owner) {
  const std::vector<py::ssize_t> shape{v.size()};
  if (v.size() == 0) return make_readonly(py::array_t<double>(shape));
  return make_readonly(py::array(py::dtype::of<double>(), shape, {static_cast<py::ssize_t>(sizeof(double))}, v.data(), owner));
}

py::object to_python(const nlohmann::json& value) {
  return py::module_::import("json").attr("loads")(value.dump());
}

nlohmann::json to_json(py::handle value) {
  // allow_nan=False: JSON has no NaN, and a config value NaN is an error, not null.
  const std::string text = py::module_::import("json").attr("dumps")(value, py::arg("allow_nan") = false).cast<std::string>();
  return nlohmann::json::parse(text);
}

PsmModel resolve_robot(py::handle robot) {
  if (py::isinstance<PsmModel>(robot)) return robot.cast<PsmModel>();
  return load_robot_model(py::str(robot).cast<std::string>(), "robot");
}

}  // namespace rcm::python
