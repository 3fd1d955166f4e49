#include "rcm/io/plot.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "rcm/io/atomic_file.hpp"

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

bool is_png_whole(const std::string& bytes) {
  static const std::string signature("\x89PNG\r\n\x1a\n", 8);
  // The last chunk: length 0, type IEND, its CRC.
  return bytes.size() >= signature.size() + 12 && bytes.compare(0, signature.size(), signature) == 0 &&
         bytes.compare(bytes.size() - 8, 4, "IEND") == 0;
}

bool is_svg_whole(const std::string& bytes) {
  const std::size_t end = bytes.find_last_not_of(" \t\r\n");
  return end != std::string::npos && end + 1 >= 6 && bytes.compare(end + 1 - 6, 6, "</svg>") == 0;
}

void check_figure_whole(const std::filesystem::path& temp, const std::filesystem::path& path,
                        bool (*is_whole)(const std::string&), const std::string& messages) {
  std::ifstream in(temp, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (!is_whole(bytes.str())) {
    InputLocation where;
    where.file = path.string();
    throw InputError(where, "cannot be written: gnuplot left it incomplete" +
                                (messages.empty() ? std::string() : " (" + messages.substr(0, 200) + ")"));
  }
}

}  // namespace

bool is_gnuplot_available() {
  // popen, not std::system: system() ignores SIGINT while it waits, which
  // would swallow a Ctrl-C meant for rcm (rcm/common/interrupt.hpp).
  static const bool available = [] {
    FILE* pipe = popen("gnuplot --version 2>&1", "r");
    if (!pipe) return false;
    char buf[256];
    while (std::fgets(buf, sizeof buf, pipe)) {
    }
    return pclose(pipe) == 0;
  }();
  return available;
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
     << "` to redraw (png_out and svg_out, when defined, name other outputs).\n";
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    gp << "$series" << i << " << EOD\n";
    const auto& s = spec.series[i];
    for (std::size_t k = 0; k < s.x.size(); ++k)
      gp << format_number(s.x[k]) << ' ' << format_number(s.y[k]) << '\n';
    gp << "EOD\n";
  }
  // Text is printed as written: enhanced mode would take the '_' of names
  // such as D30_r0_0 or large_step for subscripts.
  gp << "set title " << gp_quote(spec.title) << " noenhanced\n";
  gp << "set xlabel " << gp_quote(spec.x_label) << " noenhanced\n";
  gp << "set ylabel " << gp_quote(spec.y_label) << " noenhanced\n";
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
         << format_number(s.line_width) << " pt 7 ps 0.8 title " << gp_quote(s.label) << " noenhanced";
  }
  plot << "\n";
  // gnuplot draws to temporaries, renamed once both figures are whole; run as
  // a user runs it, the same script writes the final names.
  AtomicFile png(files.png), svg(files.svg);
  const std::string size = std::to_string(spec.width_px) + "," + std::to_string(spec.height_px);
  gp << "set terminal pngcairo size " << size << " enhanced font 'sans,11'\n";
  gp << "set output (exists('png_out') ? png_out : " << gp_quote(files.png.filename().string()) << ")\n" << plot.str();
  gp << "set terminal svg size " << size << " enhanced font 'sans,11' background '#ffffff'\n";
  gp << "set output (exists('svg_out') ? svg_out : " << gp_quote(files.svg.filename().string()) << ")\n" << plot.str();
  gp << "unset output\n";
  write_file_atomic(files.script, gp.str());
  // Run in the script's directory so that the output names inside it are relative.
  const std::filesystem::path dir =
      files.script.has_parent_path() ? files.script.parent_path() : std::filesystem::path(".");
  const std::string outputs = "png_out=" + gp_quote(png.get_temp_path().filename().string()) +
                              "; svg_out=" + gp_quote(svg.get_temp_path().filename().string());
  const std::string cmd = "cd " + sh_quote(dir.string()) + " && gnuplot -e " + sh_quote(outputs) + " " +
                          sh_quote(files.script.filename().string()) + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) throw std::runtime_error("cannot start gnuplot for " + files.script.string());
  std::string messages;
  char buf[512];
  while (std::fgets(buf, sizeof buf, pipe)) messages += buf;
  const int status = pclose(pipe);
  if (status != 0)
    throw std::runtime_error("gnuplot failed on " + files.script.string() + ": " + messages);
  // gnuplot may exit 0 after a failed write (a full disk): check the ends.
  check_figure_whole(png.get_temp_path(), files.png, is_png_whole, messages);
  check_figure_whole(svg.get_temp_path(), files.svg, is_svg_whole, messages);
  png.commit();
  svg.commit();
  return files;
}

}  // namespace rcm
