// The tissue law g: x = D tan(theta) [m] -> |f_inc| [N] (paper Eq. 11): its
// calibration pairs, the symbolic-regression fit and the identified law.

#include "common.hpp"
#include "options.hpp"
#include "rcm/tissue/expression.hpp"
#include "rcm/tissue/tissue_fit.hpp"
#include "rcm/tissue/tissue_law.hpp"
#include "rcm/tissue/tissue_pairs.hpp"

namespace rcm::python {

namespace {

TissuePairs make_pairs(py::handle x, py::handle y, const std::string& source) {
  const std::string fn = "rcm.TissuePairs";
  TissuePairs p;
  p.source = source;
  p.x = to_vector(x, argument_location(fn, "x"), -1, false);
  p.y = to_vector(y, argument_location(fn, "y"), p.x.size(), false);
  for (Eigen::Index i = 0; i < p.x.size(); ++i) p.origin.push_back(static_cast<std::size_t>(i));
  validate_tissue_pairs(p);
  return p;
}

}  // namespace

void bind_tissue(py::module_& m) {
  py::enum_<TissueTermKind>(m, "TissueTermKind", "Library terms of g: x, x^2, x^3, sin, cos, exp, and scaled sin(b x)...")
      .value("x", TissueTermKind::x)
      .value("square", TissueTermKind::square)
      .value("cube", TissueTermKind::cube)
      .value("sin", TissueTermKind::sin)
      .value("cos", TissueTermKind::cos)
      .value("exp", TissueTermKind::exp)
      .value("sin_scaled", TissueTermKind::sin_scaled)
      .value("cos_scaled", TissueTermKind::cos_scaled)
      .value("exp_scaled", TissueTermKind::exp_scaled);
  py::class_<TissueTerm>(m, "TissueTerm", "coefficient * phi(scale * x)")
      .def(py::init([](TissueTermKind kind, double coefficient, double scale) { return TissueTerm{kind, coefficient, scale}; }),
           py::arg("kind"), py::arg("coefficient"), py::arg("scale") = 1.0)
      .def_readonly("kind", &TissueTerm::kind)
      .def_readonly("coefficient", &TissueTerm::coefficient)
      .def_readonly("scale", &TissueTerm::scale);
  py::enum_<ExpressionFormat>(m, "ExpressionFormat")
      .value("plain", ExpressionFormat::plain)
      .value("sympy", ExpressionFormat::sympy)
      .value("latex", ExpressionFormat::latex);
  py::class_<TissueExpression>(m, "TissueExpression", "One candidate g: [intercept] + sum of terms, in canonical order")
      .def(py::init([](const std::vector<TissueTerm>& terms, std::optional<double> intercept) {
             TissueExpression e;
             e.terms = terms;
             e.has_intercept = intercept.has_value();
             e.intercept = intercept.value_or(0.0);
             if (!e.is_canonical())
               throw InputError(argument_location("rcm.TissueExpression", "terms"),
                                "terms must be in canonical order (TissueTermKind order), each kind at most once");
             return e;
           }),
           py::arg("terms"), py::arg("intercept") = py::none())
      .def_readonly("has_intercept", &TissueExpression::has_intercept)
      .def_readonly("intercept", &TissueExpression::intercept)
      .def_readonly("terms", &TissueExpression::terms)
      .def_property_readonly("complexity", &TissueExpression::complexity, "PySR node count")
      .def("evaluate", &TissueExpression::evaluate, py::arg("x"))
      .def("derivative", &TissueExpression::derivative, py::arg("x"))
      .def("get_skeleton", &TissueExpression::get_skeleton)
      .def("get_leading_coefficient", &TissueExpression::get_leading_coefficient)
      .def("to_string", [](const TissueExpression& e, ExpressionFormat f, int digits) { return format_expression(e, f, digits); },
           py::arg("format") = ExpressionFormat::sympy, py::arg("significant_digits") = 0)
      .def("__repr__", [](const TissueExpression& e) { return "<rcm.TissueExpression " + format_expression(e, ExpressionFormat::plain, 6) + ">"; });

  py::enum_<Monotonicity>(m, "Monotonicity")
      .value("increasing", Monotonicity::increasing)
      .value("decreasing", Monotonicity::decreasing)
      .value("not_monotone", Monotonicity::not_monotone);
  py::enum_<TissueInverseStatus>(m, "TissueInverseStatus")
      .value("ok", TissueInverseStatus::ok)
      .value("not_monotone", TissueInverseStatus::not_monotone)
      .value("out_of_range", TissueInverseStatus::out_of_range)
      .value("not_converged", TissueInverseStatus::not_converged);
  py::class_<TissueInverseResult>(m, "TissueInverseResult")
      .def_readonly("x", &TissueInverseResult::x, "NaN unless status == ok")
      .def_readonly("status", &TissueInverseResult::status)
      .def_readonly("iterations", &TissueInverseResult::iterations)
      .def_readonly("message", &TissueInverseResult::message);
  py::class_<TissueLaw>(m, "TissueLaw", "The identified g on its fitted range [x_min, x_max] (immutable)")
      .def(py::init<TissueExpression, double, double, int>(), py::arg("expression"), py::arg("x_min"), py::arg("x_max"),
           py::arg("monotonicity_samples") = 2048)
      .def_property_readonly("expression", &TissueLaw::expression)
      .def_property_readonly("x_min", &TissueLaw::x_min)
      .def_property_readonly("x_max", &TissueLaw::x_max)
      .def_property_readonly("complexity", &TissueLaw::complexity)
      .def_property_readonly("monotonicity", &TissueLaw::monotonicity)
      .def("evaluate", &TissueLaw::evaluate, py::arg("x"), "g(x), N")
      .def("derivative", &TissueLaw::derivative, py::arg("x"))
      .def("compute_inverse", &TissueLaw::compute_inverse, py::arg("y"), "g^-1(y) with a status (never raises)")
      .def("to_string", &TissueLaw::to_string, py::arg("format") = ExpressionFormat::sympy, py::arg("significant_digits") = 0)
      .def("to_json", [](const TissueLaw& g) { return to_python(to_json(g)); }, "rcm-tissue-law/1 as a dict")
      .def("__repr__", [](const TissueLaw& g) { return "<rcm.TissueLaw " + g.to_string(ExpressionFormat::plain, 6) + ">"; });
  m.def("load_tissue_law", &load_tissue_law, py::arg("path"));
  m.def("save_tissue_law", &save_tissue_law, py::arg("path"), py::arg("law"));

  py::class_<TissuePairs>(m, "TissuePairs", "Calibration pairs x = D* tan(theta) (m), y = |f_inc| (N)")
      .def(py::init(&make_pairs), py::arg("x"), py::arg("y"), py::arg("source") = "<numpy>",
           "From arrays; validated (finite, same size, >= 4 pairs, not all x equal)")
      .def_readonly("source", &TissuePairs::source)
      .def_readonly("x", &TissuePairs::x)
      .def_readonly("y", &TissuePairs::y)
      .def_readonly("origin", &TissuePairs::origin, "CSV line or source sample of each pair")
      .def("__len__", &TissuePairs::size);
  m.def("load_tissue_pairs", &load_tissue_pairs, py::arg("path"), "Pairs CSV with columns x, y");
  m.def("save_tissue_pairs", &save_tissue_pairs, py::arg("path"), py::arg("pairs"));
  m.def("compute_binned_pairs", &compute_binned_pairs, py::arg("pairs"), py::arg("bins"));

  def_options<TissuePairOptions, JacobianCheckOptions>(m, "TissuePairOptions", "Which calibration samples make pairs");
  py::class_<TissuePairsReport>(m, "TissuePairsReport", "Samples kept and dropped (never silently)")
      .def_readonly("samples", &TissuePairsReport::samples)
      .def_readonly("kept", &TissuePairsReport::kept)
      .def_readonly("dropped_small_theta", &TissuePairsReport::dropped_small_theta)
      .def_readonly("dropped_singular", &TissuePairsReport::dropped_singular)
      .def_readonly("dropped_ill_conditioned", &TissuePairsReport::dropped_ill_conditioned)
      .def_readonly("dropped_non_finite", &TissuePairsReport::dropped_non_finite);
  py::class_<TissuePairsResult>(m, "TissuePairsResult")
      .def_readonly("pairs", &TissuePairsResult::pairs)
      .def_readonly("report", &TissuePairsResult::report);
  m.def("compute_tissue_pairs", [](const Recording& rec, py::handle tau_fs, py::handle q0, double D_star,
                                   const TissuePairOptions& o) {
    const std::string fn = "rcm.compute_tissue_pairs";
    const Eigen::MatrixXd tau = to_matrix(tau_fs, argument_location(fn, "tau_fs"));
    const Eigen::Vector3d q = to_vector3(q0, argument_location(fn, "q0"));
    py::gil_scoped_release release;
    return compute_tissue_pairs(rec, tau, q, D_star, o);
  }, py::arg("recording"), py::arg("tau_fs"), py::arg("q0"), py::arg("D_star"), py::arg("options") = TissuePairOptions{},
        "Pairs from a calibration under the known pure coaxial offset D_star (m): x = D* tan(theta),\n"
        "y = |J_D*^-T (tau - tau_fs)|");
  m.def("compute_tissue_pairs_from_measured_force", [](const Recording& rec, py::handle q0, double D_star,
                                                       const TissuePairOptions& o) {
    return compute_tissue_pairs_from_measured_force(
        rec, to_vector3(q0, argument_location("rcm.compute_tissue_pairs_from_measured_force", "q0")), D_star, o);
  }, py::arg("recording"), py::arg("q0"), py::arg("D_star"), py::arg("options") = TissuePairOptions{},
        "Same pairs with y = |force| of the recording's force columns (a sensor, for reference)");

  def_options<TissueFitOptions, std::vector<TissueTermKind>>(m, "TissueFitOptions",
                                                             "Symbolic regression options (docs/methods.md)")
      .def("check", &TissueFitOptions::check);
  py::class_<TissueFrontEntry>(m, "TissueFrontEntry")
      .def_readonly("expression", &TissueFrontEntry::expression)
      .def_readonly("complexity", &TissueFrontEntry::complexity)
      .def_readonly("loss", &TissueFrontEntry::loss, "MSE, N^2")
      .def_readonly("score", &TissueFrontEntry::score)
      .def_readonly("bic", &TissueFrontEntry::bic)
      .def("__repr__", [](const TissueFrontEntry& e) {
        return "<rcm.TissueFrontEntry c=" + std::to_string(e.complexity) + " loss=" + std::to_string(e.loss) + " " +
               format_expression(e.expression, ExpressionFormat::plain, 6) + ">";
      });
  py::class_<TissueFitSummary>(m, "TissueFitSummary")
      .def_readonly("num_pairs", &TissueFitSummary::num_pairs)
      .def_readonly("num_candidates", &TissueFitSummary::num_candidates)
      .def_readonly("x_min", &TissueFitSummary::x_min)
      .def_readonly("x_max", &TissueFitSummary::x_max)
      .def("brief_report", &TissueFitSummary::brief_report);
  py::class_<TissueFitResult>(m, "TissueFitResult")
      .def_readonly("hall_of_fame", &TissueFitResult::hall_of_fame, "best per complexity")
      .def_readonly("front", &TissueFitResult::front, "Pareto front, ascending complexity")
      .def_readonly("best_index", &TissueFitResult::best_index)
      .def_readonly("law", &TissueFitResult::law, "the chosen TissueLaw, or None when unusable")
      .def_readonly("summary", &TissueFitResult::summary)
      .def_property_readonly("best", &TissueFitResult::best);
  m.def("fit_tissue_law", [](const TissuePairs& pairs, const TissueFitOptions& o) {
    py::gil_scoped_release release;
    return fit_tissue_law(pairs, o);
  }, py::arg("pairs"), py::arg("options") = TissueFitOptions{},
        "Symbolic regression of g over {1, x, x^2, x^3, sin, cos, exp} with PySR's selection (rcm tissue fit)");
}

}  // namespace rcm::python
