#pragma once
// The Python classes of the options structs, made from their field tables
// (rcm/common/options.hpp): one attribute per field (read and write, as the C++
// member, with the field's help, unit and limits as its doc), a constructor
// taking any fields as keyword arguments (checked against the table: an unknown
// name is a TypeError, a value outside its limits an rcm.InputError naming the
// field), and to_dict() / from_dict() through the table's JSON.
//
//   def_options<JointEstimatorOptions>(m, "JointEstimatorOptions", "...").def("check", ...);

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "common.hpp"
#include "rcm/common/options.hpp"

namespace rcm::python {

namespace detail {

// The member types the tables hold; a field of another type is a bug found at import.
template <class T, class M>
bool bind_member(py::class_<T>& cls, const OptionField<T>& f, const std::string& doc) {
  if (const auto* member = std::any_cast<M T::*>(&f.member)) {
    cls.def_readwrite(f.name.c_str(), *member, doc.c_str());
    return true;
  }
  return false;
}

template <class T, class... Members>
bool bind_member_of(py::class_<T>& cls, const OptionField<T>& f, const std::string& doc) {
  return (bind_member<T, Members>(cls, f, doc) || ...);
}

// "help (unit; limits) [type, default value]" for an attribute's doc.
inline std::string field_doc(const OptionDoc& d) {
  std::string detail = d.unit;
  if (!d.limits.empty()) detail += (detail.empty() ? "" : "; ") + d.limits;
  return d.help + (detail.empty() ? "" : " (" + detail + ")") + " [" + d.type + ", default " + d.value + "]";
}

}  // namespace detail

// Every field of T's table as an attribute of `cls`. `Extra`: the enums and
// nested options structs T holds (each already bound to Python).
template <class T, class... Extra>
void def_option_fields(py::class_<T>& cls) {
  const std::vector<OptionDoc> docs = describe_options<T>();
  for (const OptionField<T>& f : get_option_table<T>().fields()) {
    std::string doc = f.help;
    for (const OptionDoc& d : docs)
      if (d.path == f.name) doc = detail::field_doc(d);
    const bool bound =
        detail::bind_member_of<T, bool, int, unsigned, std::size_t, double, std::string, std::optional<double>,
                               std::optional<std::filesystem::path>, std::vector<double>,
                               std::optional<std::vector<double>>, Eigen::Vector3d, Extra...>(cls, f, doc);
    if (!bound)
      throw std::logic_error("rcm." + get_option_table<T>().name() + "." + f.name +
                             ": its type is not in the binding's list");
  }
}

// The class rcm.<name> of options struct T: constructor with keyword
// arguments, the fields, to_dict() and from_dict().
template <class T, class... Extra>
py::class_<T> def_options(py::module_& m, const char* name, const char* doc) {
  py::class_<T> cls(m, name, doc);
  const std::string where = std::string("rcm.") + name;
  cls.def(py::init([where](const py::kwargs& kwargs) {
            T options;
            py::object self = py::cast(&options, py::return_value_policy::reference);
            for (const auto& [key, value] : kwargs) {
              const std::string field = py::str(key);
              if (!get_option_table<T>().find(field)) {
                std::string known;
                for (const auto& f : get_option_table<T>().fields()) known += (known.empty() ? "" : ", ") + f.name;
                throw py::type_error(where + "() got an unexpected keyword argument '" + field + "'; fields: " + known);
              }
              self.attr(field.c_str()) = value;
            }
            check_options(options, where);
            return options;
          }),
          ("Defaults, with any field given as a keyword argument (rcm.InputError when a value is out of its "
           "range). Fields: " +
           [] {
             std::string names;
             for (const auto& f : get_option_table<T>().fields()) names += (names.empty() ? "" : ", ") + f.name;
             return names;
           }())
              .c_str());
  def_option_fields<T, Extra...>(cls);
  cls.def("to_dict", [](const T& o) { return to_python(options_to_json(o)); },
          "The options as a dict (the JSON of an options file)");
  cls.def_static("from_dict", [where](py::handle d) { return options_from_json<T>(to_json(d), where); }, py::arg("d"),
                 "The defaults with the dict's fields; rcm.InputError naming an unknown key, a wrong type or a value "
                 "out of range");
  cls.def("validate", [where](const T& o) { check_options(o, where); },
          "rcm.InputError naming the first field out of its range (and the checks across fields)");
  return cls;
}

}  // namespace rcm::python
