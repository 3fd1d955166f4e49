// The PSM model, the incision frame and the incision-port Jacobian J_D, and the
// Eq. 6 force at the incision.

#include <cmath>

#include "common.hpp"
#include "options.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/kinematics/incision.hpp"
#include "rcm/kinematics/psm_model.hpp"

namespace rcm::python {

namespace {

// Everything `rcm kinematics` prints, computed the same way.
struct IncisionKinematics {
  std::string robot;
  Eigen::Vector3d q = Eigen::Vector3d::Zero(), q0 = Eigen::Vector3d::Zero();
  double offset_m = 0.0;
  Eigen::Matrix4d X_base_3 = Eigen::Matrix4d::Identity();
  Eigen::Vector3d z3 = Eigen::Vector3d::Zero();
  double theta = 0.0;
  double shaft_distance_m = 0.0;  // inf when the shaft is parallel to the pad
  Eigen::Matrix3d J_inc_base = Eigen::Matrix3d::Zero();  // NaN when shaft_distance_m is not finite
  JacobianCondition condition;
};

InputLocation limit_location(const std::string& function, const std::string& argument) {
  InputLocation where;
  where.file = function;
  where.field = argument;
  where.kind = InputLocation::Kind::json_field;  // the joint index is appended: q[2]
  return where;
}

IncisionKinematics compute_incision_kinematics(py::handle q_in, py::handle q0_in, double offset, py::handle robot) {
  const std::string fn = "rcm.compute_incision_kinematics";
  IncisionKinematics k;
  const PsmModel model = resolve_robot(robot);
  k.robot = model.name();
  k.q = to_vector3(q_in, argument_location(fn, "q"));
  k.q0 = to_vector3(q0_in, argument_location(fn, "q0"));
  k.offset_m = to_finite(offset, argument_location(fn, "offset"));
  model.check_within_limits(k.q, limit_location(fn, "q"));
  model.check_within_limits(k.q0, limit_location(fn, "q0"));
  KinematicsData data;
  compute_forward_kinematics(model, data, k.q);
  k.X_base_3 = get_frame_pose(data, 3).matrix();
  const IncisionFrame incision = make_incision_frame(k.q0);
  k.theta = compute_pivot_angle(incision, k.q);
  k.shaft_distance_m = compute_shaft_distance(incision, k.q, k.offset_m);
  k.z3 = compute_z3_base(k.q);
  k.condition = compute_incision_jacobian_condition(k.q, k.shaft_distance_m);
  k.J_inc_base = std::isfinite(k.shaft_distance_m) ? compute_incision_jacobian(k.q, k.shaft_distance_m)
                                                   : Eigen::Matrix3d::Constant(NAN);
  return k;
}

py::list rows(const Eigen::MatrixXd& m) {
  py::list out;
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    py::list row;
    for (Eigen::Index j = 0; j < m.cols(); ++j) row.append(m(i, j));
    out.append(row);
  }
  return out;
}
py::list values(const Eigen::VectorXd& v) {
  py::list out;
  for (Eigen::Index i = 0; i < v.size(); ++i) out.append(v[i]);
  return out;
}

}  // namespace

void bind_kinematics(py::module_& m) {
  py::enum_<JointType>(m, "JointType").value("revolute", JointType::revolute).value("prismatic", JointType::prismatic);
  py::class_<DhJoint>(m, "DhJoint", "One row of the modified-DH table")
      .def_readonly("name", &DhJoint::name)
      .def_readonly("type", &DhJoint::type)
      .def_readonly("a", &DhJoint::a, "a(i-1), m")
      .def_readonly("alpha", &DhJoint::alpha, "alpha(i-1), rad")
      .def_readonly("d", &DhJoint::d, "constant part of d(i), m")
      .def_readonly("theta", &DhJoint::theta, "constant part of theta(i), rad")
      .def_readonly("q_min", &DhJoint::q_min)
      .def_readonly("q_max", &DhJoint::q_max)
      .def("__repr__", [](const DhJoint& j) { return "<rcm.DhJoint '" + j.name + "'>"; });

  py::class_<PsmModel>(m, "PsmModel",
                       "The robot description: a modified-DH chain (rcm-robot/1 JSON). Immutable; computations\n"
                       "take it together with a KinematicsData workspace.")
      .def_static("load", &PsmModel::load, py::arg("path"), "Read an rcm-robot/1 JSON file")
      .def_static("from_json_text", &PsmModel::from_json_text, py::arg("text"), py::arg("source") = "<text>")
      .def_property_readonly("name", &PsmModel::name)
      .def_property_readonly("joints", &PsmModel::joints, "list of DhJoint")
      .def_property_readonly("num_joints", &PsmModel::num_joints)
      .def_property_readonly("tool_offset", &PsmModel::tool_offset, "l_tool, m: insertion at which frame 3 is at the RCM")
      .def(
          "check_within_limits",
          [](const PsmModel& model, py::handle q, double tolerance) {
            const std::string fn = "rcm.PsmModel.check_within_limits";
            model.check_within_limits(to_vector3(q, argument_location(fn, "q")), limit_location(fn, "q"), tolerance);
          },
          py::arg("q"), py::arg("tolerance") = 1e-9,
          "Raise rcm.InputError if q (first three joints) is outside the limits by more than tolerance")
      .def("__repr__", [](const PsmModel& p) { return "<rcm.PsmModel '" + p.name() + "'>"; });
  m.def("get_builtin_robot_names", &get_builtin_robot_names, "Robots compiled into the library");
  m.def("load_robot_model", &load_robot_model, py::arg("name_or_path") = "dvrk-psm-classic",
        py::arg("context_for_errors") = "robot", "A built-in robot by name, or an rcm-robot/1 JSON file");

  py::class_<KinematicsData>(m, "KinematicsData", "Workspace of forward kinematics: poses of frames 0..3")
      .def(py::init<>());
  m.def(
      "compute_forward_kinematics",
      [](const PsmModel& model, KinematicsData& data, py::handle q) {
        compute_forward_kinematics(model, data, to_vector3(q, argument_location("rcm.compute_forward_kinematics", "q")));
      },
      py::arg("model"), py::arg("data"), py::arg("q"), "Fill data with the poses of frames 1..3 at q (rad, rad, m)");
  m.def(
      "get_frame_pose",
      [](const KinematicsData& data, int frame) -> Eigen::Matrix4d {
        if (frame < 0 || frame > 3)
          throw InputError(argument_location("rcm.get_frame_pose", "frame"), "expected 0..3, got " + std::to_string(frame));
        return get_frame_pose(data, frame).matrix();
      },
      py::arg("data"), py::arg("frame"), "X_base_frame as a 4x4 homogeneous matrix (numpy)");
  m.def("compute_dh_transform", [](double a, double alpha, double d, double theta) -> Eigen::Matrix4d {
    return compute_dh_transform(a, alpha, d, theta).matrix();
  }, py::arg("a"), py::arg("alpha"), py::arg("d"), py::arg("theta"), "Modified-DH link transform X_{i-1,i} (4x4)");
  auto closed_form = [&m](const char* name, Eigen::Vector3d (*f)(const Eigen::Vector3d&), const char* doc) {
    const std::string fn = std::string("rcm.") + name;
    m.def(name, [f, fn](py::handle q) { return f(to_vector3(q, argument_location(fn, "q"))); }, py::arg("q"), doc);
  };
  closed_form("compute_z3_base", &compute_z3_base, "Insertion axis z3(q) in the base frame (contract closed form)");
  closed_form("compute_x3_base", &compute_x3_base, "x3(q) in the base frame");
  closed_form("compute_y3_base", &compute_y3_base, "y3(q) in the base frame");
  py::class_<ShaftDirections>(m, "ShaftDirections",
                              "The shaft's axes at q in the base frame and the derivatives of its axis z3")
      .def_readonly("x3", &ShaftDirections::x3)
      .def_readonly("y3", &ShaftDirections::y3)
      .def_readonly("z3", &ShaftDirections::z3)
      .def_readonly("dz3_dq1", &ShaftDirections::dz3_dq1, "yaw axis x z3, norm |cos q2|")
      .def_property_readonly("dz3_dq2", &ShaftDirections::get_dz3_dq2, "= x3")
      .def_readonly("cos_q2", &ShaftDirections::cos_q2);
  m.def("compute_shaft_directions", [](py::handle q) {
    return compute_shaft_directions(to_vector3(q, argument_location("rcm.compute_shaft_directions", "q")));
  }, py::arg("q"), "x3, y3, z3 and dz3/dq1, dz3/dq2 at q: the closed forms J_D and the estimators use");
  m.def("compute_R_base_3", [](py::handle q) {
    return compute_R_base_3(to_vector3(q, argument_location("rcm.compute_R_base_3", "q")));
  }, py::arg("q"), "Rotation of DH frame 3 in the base frame, columns [x3 y3 z3]");

  py::class_<IncisionFrame>(m, "IncisionFrame",
                            "Incision frame I: orientation of DH frame 3 at the docking configuration q0, origin at the RCM")
      .def(py::init([](py::handle q0) { return make_incision_frame(to_vector3(q0, argument_location("rcm.IncisionFrame", "q0"))); }),
           py::arg("q0"))
      .def_readonly("q0", &IncisionFrame::q0)
      .def_readonly("R_base_inc", &IncisionFrame::R_base_inc, "columns x3(q0), y3(q0), z3(q0)")
      .def_property_readonly("z_inc_base", &IncisionFrame::z_inc_base);
  m.def("make_incision_frame", [](py::handle q0) {
    return make_incision_frame(to_vector3(q0, argument_location("rcm.make_incision_frame", "q0")));
  }, py::arg("q0"), "The incision frame at q0");
  m.def("compute_pivot_angle", [](const IncisionFrame& inc, py::handle q) {
    return compute_pivot_angle(inc, to_vector3(q, argument_location("rcm.compute_pivot_angle", "q")));
  }, py::arg("incision"), py::arg("q"), "theta(q0, q), rad in [0, pi] (Eq. 9)");
  m.def("compute_shaft_distance", [](const IncisionFrame& inc, py::handle q, double D) {
    return compute_shaft_distance(inc, to_vector3(q, argument_location("rcm.compute_shaft_distance", "q")), D);
  }, py::arg("incision"), py::arg("q"), py::arg("D"), "s = D sec(theta), m (inf when the shaft is parallel to the pad)");
  m.def("compute_incision_jacobian", [](py::handle q, double s) {
    return compute_incision_jacobian(to_vector3(q, argument_location("rcm.compute_incision_jacobian", "q")), s);
  }, py::arg("q"), py::arg("shaft_distance"), "J_D in the base frame (3x3), columns s dz3/dq1, s dz3/dq2, z3");
  m.def("compute_incision_jacobian_dh", [](const PsmModel& model, KinematicsData& data, py::handle q, double s) {
    return compute_incision_jacobian_dh(model, data, to_vector3(q, argument_location("rcm.compute_incision_jacobian_dh", "q")), s);
  }, py::arg("model"), py::arg("data"), py::arg("q"), py::arg("shaft_distance"),
        "The same J_D from the DH chain with the 'inc' row of paper Table I (a cross-check)");

  py::enum_<JacobianStatus>(m, "JacobianStatus")
      .value("ok", JacobianStatus::ok)
      .value("ill_conditioned", JacobianStatus::ill_conditioned)
      .value("singular", JacobianStatus::singular);
  def_options<JacobianCheckOptions>(m, "JacobianCheckOptions", "When J_D counts as ill-conditioned or singular");
  py::class_<JacobianCondition>(m, "JacobianCondition")
      .def_readonly("condition", &JacobianCondition::condition, "sigma_max / sigma_min, inf when singular")
      .def_readonly("status", &JacobianCondition::status)
      .def("__repr__", [](const JacobianCondition& c) {
        return "<rcm.JacobianCondition " + std::to_string(c.condition) + " " + to_string(c.status) + ">";
      });
  m.def("compute_incision_jacobian_condition", [](py::handle q, double s, const JacobianCheckOptions& o) {
    return compute_incision_jacobian_condition(
        to_vector3(q, argument_location("rcm.compute_incision_jacobian_condition", "q")), s, o);
  }, py::arg("q"), py::arg("shaft_distance"), py::arg("options") = JacobianCheckOptions{}, "Condition of J_D at (q, s)");

  py::class_<IncisionKinematics>(m, "IncisionKinematics", "What `rcm kinematics` reports for one configuration")
      .def_readonly("robot", &IncisionKinematics::robot)
      .def_readonly("q", &IncisionKinematics::q)
      .def_readonly("q0", &IncisionKinematics::q0)
      .def_readonly("offset_m", &IncisionKinematics::offset_m, "coaxial offset D, m")
      .def_readonly("X_base_3", &IncisionKinematics::X_base_3, "pose of DH frame 3 in the base frame (4x4)")
      .def_readonly("z3", &IncisionKinematics::z3, "insertion axis in the base frame")
      .def_readonly("theta", &IncisionKinematics::theta, "pivot angle from z3(q0), rad")
      .def_readonly("shaft_distance_m", &IncisionKinematics::shaft_distance_m, "D sec(theta), m; inf when parallel")
      .def_readonly("J_inc_base", &IncisionKinematics::J_inc_base, "J_D (3x3, base frame); NaN when s is not finite")
      .def_property_readonly("condition", [](const IncisionKinematics& k) { return k.condition.condition; })
      .def_property_readonly("status", [](const IncisionKinematics& k) { return k.condition.status; })
      .def("to_dict", [](const IncisionKinematics& k) {
        // The shape of `rcm kinematics --json` (non-finite numbers as None, like its null).
        auto finite_or_none = [](double v) { return std::isfinite(v) ? py::object(py::float_(v)) : py::none(); };
        py::dict d;
        d["robot"] = k.robot;
        d["q"] = values(k.q);
        d["q0"] = values(k.q0);
        d["offset_m"] = k.offset_m;
        d["z3"] = values(k.z3);
        d["theta"] = k.theta;
        d["shaft_distance_m"] = finite_or_none(k.shaft_distance_m);
        py::dict frame3;
        frame3["position_m"] = values(k.X_base_3.block<3, 1>(0, 3));
        frame3["rotation_rows"] = rows(k.X_base_3.block<3, 3>(0, 0));
        d["frame3"] = frame3;
        d["J_inc_base"] = std::isfinite(k.shaft_distance_m) ? py::object(rows(k.J_inc_base)) : py::none();
        d["condition"] = finite_or_none(k.condition.condition);
        d["status"] = to_string(k.condition.status);
        return d;
      }, "The fields of `rcm kinematics --json` as a dict");
  m.def("compute_incision_kinematics", &compute_incision_kinematics, py::arg("q"),
        py::arg("q0") = std::vector<double>{0.0, 0.0, 0.12}, py::arg("offset") = 0.0,
        py::arg("robot") = "dvrk-psm-classic",
        "Frame 3, z3, theta, s = D sec(theta), J_D and its condition at q for docking configuration q0 and\n"
        "coaxial offset D (m), exactly as `rcm kinematics`. q and q0 must lie within the robot's limits\n"
        "(rcm.InputError otherwise). robot: a built-in name, an rcm-robot/1 file or a PsmModel.");
}

void bind_force(py::module_& m) {
  py::class_<IncisionForceSample>(m, "IncisionForceSample")
      .def_readonly("f_inc_base", &IncisionForceSample::f_inc_base, "force on the tissue, base frame, N (NaN if singular)")
      .def_readonly("theta", &IncisionForceSample::theta)
      .def_readonly("shaft_distance", &IncisionForceSample::shaft_distance)
      .def_readonly("condition", &IncisionForceSample::condition);
  m.def("compute_incision_force", [](const IncisionFrame& inc, py::handle q, double D, py::handle dtau,
                                     const JacobianCheckOptions& o) {
    const std::string fn = "rcm.compute_incision_force";
    return compute_incision_force(inc, to_vector3(q, argument_location(fn, "q")), to_finite(D, argument_location(fn, "D")),
                                  to_vector3(dtau, argument_location(fn, "dtau")), o);
  }, py::arg("incision"), py::arg("q"), py::arg("D"), py::arg("dtau"), py::arg("options") = JacobianCheckOptions{},
        "Eq. 6 for one sample: f_inc_base = J_D^-T dtau, dtau = tau - tau_fs of joints 1-3 (N m, N m, N).\n"
        "A singular J_D gives NaN with status singular, never a huge number.");

  py::class_<IncisionForceSeries>(m, "IncisionForceSeries")
      .def_readonly("f_inc_base", &IncisionForceSeries::f_inc_base, "(T, 3) N, base frame; NaN rows where singular")
      .def_readonly("theta", &IncisionForceSeries::theta, "(T,) rad")
      .def_readonly("condition", &IncisionForceSeries::condition, "(T,) condition number of J_D")
      .def_readonly("status", &IncisionForceSeries::status, "list of JacobianStatus, one per sample")
      .def_readonly("num_ill_conditioned", &IncisionForceSeries::num_ill_conditioned)
      .def_readonly("num_singular", &IncisionForceSeries::num_singular);
  m.def("compute_incision_force_series", [](const IncisionFrame& inc, const Recording& rec, py::handle tau_fs, double D,
                                            const JacobianCheckOptions& o) {
    const std::string fn = "rcm.compute_incision_force_series";
    const Eigen::MatrixXd tau = to_matrix(tau_fs, argument_location(fn, "tau_fs"), -1, -1, true);
    const double offset = to_finite(D, argument_location(fn, "D"));
    py::gil_scoped_release release;
    return compute_incision_force_series(inc, rec, tau, offset, o);
  }, py::arg("incision"), py::arg("recording"), py::arg("tau_fs"), py::arg("D"),
        py::arg("options") = JacobianCheckOptions{},
        "Eq. 6 over a recording: tau_fs (T, >= 3) is the free-space prediction (rcm.dynamics.predict_torque).\n"
        "What `rcm force` computes; f_inc_base rows are NaN where J_D is singular.");
}

}  // namespace rcm::python
