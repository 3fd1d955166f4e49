#include "rcm/io/plot.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace rcm {

namespace {

// gnuplot string literal in single quotes: only ' needs doubling.
std::string gp_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') out += "''";
    else if (c == '\n') out += ' ';
    else out += c;
  }
  return out + "'";
}

// POSIX shell single-quoted argument.
std::string sh_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') out += "'\\''";
    else out += c;
  }
  return out + "'";
}

const char* style_text(PlotStyle s) {
  switch (s) {
    case PlotStyle::lines: return "lines";
    case PlotStyle::points: return "points";
    default: return "linespoints";
  }
}

std::string format_number(double v) {
  if (!std::isfinite(v)) return "NaN";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

}  // namespace

bool is_gnuplot_available() {
  return std::system("gnuplot --version >/dev/null 2>&1") == 0;
}

PlotFiles save_plot(const PlotSpec& spec, const std::filesystem::path& stem) {
  for (const auto& s : spec.series)
    if (s.x.size() != s.y.size())
      throw std::invalid_argument("plot series '" + s.label + "': x has " +
                                  std::to_string(s.x.size()) + " values, y has " +
                                  std::to_string(s.y.size()));
  if (!is_gnuplot_available())
    throw std::runtime_error("cannot draw " + stem.string() +
                             ": the gnuplot program was not found (Debian: apt-get install gnuplot-nox)");
  PlotFiles files;
  files.png = stem;
  files.png += ".png";
  files.svg = stem;
  files.svg += ".svg";
  files.script = stem;
  files.script += ".gp";
  if (stem.has_parent_path()) std::filesystem::create_directories(stem.parent_path());

  std::ostringstream gp;
  gp << "# Written by rcm; run `gnuplot " << files.script.filename().string()
     << "` to redraw.\n";
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    gp << "$series" << i << " << EOD\n";
    const auto& s = spec.series[i];
    for (std::size_t k = 0; k < s.x.size(); ++k)
      gp << format_number(s.x[k]) << ' ' << format_number(s.y[k]) << '\n';
    gp << "EOD\n";
  }
  gp << "set title " << gp_quote(spec.title) << "\n";
  gp << "set xlabel " << gp_quote(spec.x_label) << "\n";
  gp << "set ylabel " << gp_quote(spec.y_label) << "\n";
  if (spec.grid) gp << "set grid\n";
  if (spec.legend == "off") gp << "unset key\n";
  else gp << "set key " << spec.legend << "\n";
  if (spec.x_range)
    gp << "set xrange [" << format_number(spec.x_range->first) << ":"
       << format_number(spec.x_range->second) << "]\n";
  if (spec.y_range)
    gp << "set yrange [" << format_number(spec.y_range->first) << ":"
       << format_number(spec.y_range->second) << "]\n";
  std::ostringstream plot;
  plot << "plot ";
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    const auto& s = spec.series[i];
    if (i) plot << ", \\\n     ";
    plot << "$series" << i << " using 1:2 with " << style_text(s.style) << " lw "
         << format_number(s.line_width) << " pt 7 ps 0.8 title " << gp_quote(s.label);
  }
  plot << "\n";
  const std::string size = std::to_string(spec.width_px) + "," + std::to_string(spec.height_px);
  gp << "set terminal pngcairo size " << size << " enhanced font 'sans,11'\n";
  gp << "set output " << gp_quote(files.png.filename().string()) << "\n" << plot.str();
  gp << "set terminal svg size " << size << " enhanced font 'sans,11' background '#ffffff'\n";
  gp << "set output " << gp_quote(files.svg.filename().string()) << "\n" << plot.str();
  gp << "unset output\n";
  {
    std::ofstream out(files.script);
    if (!out) throw std::runtime_error("cannot write " + files.script.string());
    out << gp.str();
  }
  // Run in the script's directory so that the output names inside it are relative.
  const std::filesystem::path dir =
      files.script.has_parent_path() ? files.script.parent_path() : std::filesystem::path(".");
  const std::string cmd = "cd " + sh_quote(dir.string()) + " && gnuplot " +
                          sh_quote(files.script.filename().string()) + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) throw std::runtime_error("cannot start gnuplot for " + files.script.string());
  std::string messages;
  char buf[512];
  while (std::fgets(buf, sizeof buf, pipe)) messages += buf;
  const int status = pclose(pipe);
  if (status != 0)
    throw std::runtime_error("gnuplot failed on " + files.script.string() + ": " + messages);
  return files;
}

}  // namespace rcm
