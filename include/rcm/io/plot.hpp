#pragma once
// Line and scatter plots through gnuplot: a self-contained script (data inline)
// is written next to the figures and run by the `gnuplot` program, so that a
// user can edit and re-run it. Throws std::runtime_error when gnuplot is missing
// or fails; library code never draws anything itself.

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace rcm {

enum class PlotStyle { lines, points, lines_points };

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;
  PlotStyle style = PlotStyle::lines_points;
  double line_width = 1.5;
};

struct PlotSpec {
  std::string title;
  std::string x_label, y_label;
  std::vector<PlotSeries> series;
  std::optional<std::pair<double, double>> x_range, y_range;
  std::string legend = "top left";  // gnuplot "set key" position; "off" hides it
  bool grid = true;
  int width_px = 900, height_px = 600;
};

struct PlotFiles {
  std::filesystem::path png, svg, script;
};

// True when `gnuplot` can be run.
bool is_gnuplot_available();

// Writes stem.gp, stem.png and stem.svg (e.g. stem = out/force_angle). Throws
// std::invalid_argument for a malformed spec (x and y of different lengths,
// non-finite values are skipped by gnuplot and therefore written as NaN).
PlotFiles save_plot(const PlotSpec& spec, const std::filesystem::path& stem);

}  // namespace rcm
