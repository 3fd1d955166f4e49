// Figures through gnuplot (rcm/io/plot.hpp), so that Python callers draw theirs
// as the library draws its own: a script with the data inline, a PNG and an SVG.

#include "common.hpp"
#include "rcm/io/plot.hpp"

namespace rcm::python {

void bind_plot(py::module_& m) {
  py::enum_<PlotStyle>(m, "PlotStyle")
      .value("lines", PlotStyle::lines)
      .value("points", PlotStyle::points)
      .value("lines_points", PlotStyle::lines_points);
  py::class_<PlotSeries>(m, "PlotSeries", "One curve: label, x, y (equal lengths), style, line_width")
      .def(py::init([](std::string label, py::handle x, py::handle y, PlotStyle style, double line_width) {
             PlotSeries s;
             s.label = std::move(label);
             // NaN is allowed: gnuplot leaves a gap (a sample without a value).
             const Eigen::VectorXd vx = to_vector(x, argument_location("rcm.PlotSeries", "x"), -1, false);
             const Eigen::VectorXd vy = to_vector(y, argument_location("rcm.PlotSeries", "y"), vx.size(), false);
             s.x.assign(vx.data(), vx.data() + vx.size());
             s.y.assign(vy.data(), vy.data() + vy.size());
             s.style = style;
             s.line_width = line_width;
             return s;
           }),
           py::arg("label"), py::arg("x"), py::arg("y"), py::arg("style") = PlotStyle::lines_points,
           py::arg("line_width") = 1.5)
      .def_readonly("label", &PlotSeries::label)
      .def_readonly("x", &PlotSeries::x)
      .def_readonly("y", &PlotSeries::y);
  m.def("is_gnuplot_available", &is_gnuplot_available, "True when the gnuplot program can be run");
  m.def(
      "save_plot",
      [](const std::filesystem::path& stem, const std::vector<PlotSeries>& series, const std::string& title,
         const std::string& x_label, const std::string& y_label, const std::string& legend,
         std::optional<std::pair<double, double>> x_range, std::optional<std::pair<double, double>> y_range) {
        PlotSpec spec;
        spec.title = title;
        spec.x_label = x_label;
        spec.y_label = y_label;
        spec.series = series;
        spec.legend = legend;
        spec.x_range = x_range;
        spec.y_range = y_range;
        PlotFiles files;
        {
          py::gil_scoped_release release;
          files = save_plot(spec, stem);
        }
        py::dict out;
        out["png"] = files.png;
        out["svg"] = files.svg;
        out["script"] = files.script;
        return out;
      },
      py::arg("stem"), py::arg("series"), py::arg("title") = "", py::arg("x_label") = "", py::arg("y_label") = "",
      py::arg("legend") = "top left", py::arg("x_range") = py::none(), py::arg("y_range") = py::none(),
      "Writes stem.gp, stem.png and stem.svg as the library's own figures (gnuplot; RuntimeError without it).\n"
      "legend: gnuplot's `set key` position ('off' hides it); x_range, y_range: (low, high) or None (automatic).\n"
      "Returns {'png', 'svg', 'script'} paths.");
}

}  // namespace rcm::python
