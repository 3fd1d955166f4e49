#include "rcm/tissue/tissue_pairs.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <numeric>

#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/json_file.hpp"

namespace rcm {

void validate_tissue_pairs(const TissuePairs& pairs, std::size_t min_pairs) {
  const std::string& src = pairs.source;
  if (pairs.x.size() != pairs.y.size()) {
    throw InputError({src, 0, 0, ""}, fmt::format("tissue pairs: {} x values but {} y values",
                                                  pairs.x.size(), pairs.y.size()));
  }
  if (pairs.size() < min_pairs) {
    throw InputError({src, 0, 0, ""},
                     fmt::format("tissue pairs: need at least {} pairs to fit g, got {}", min_pairs,
                                 pairs.size()));
  }
  auto where = [&](std::size_t i, const char* column) {
    InputLocation loc{src, 0, 0, column};
    if (i < pairs.origin.size()) loc.line = pairs.origin[i];
    else loc.field = fmt::format("{}[{}]", column, i);
    return loc;
  };
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    if (!std::isfinite(pairs.x[static_cast<Eigen::Index>(i)])) {
      throw InputError(where(i, "x"), "expected a finite number");
    }
    if (!std::isfinite(pairs.y[static_cast<Eigen::Index>(i)])) {
      throw InputError(where(i, "y"), "expected a finite number");
    }
  }
  if (pairs.x.maxCoeff() <= pairs.x.minCoeff()) {
    throw InputError({src, 0, 0, "x"},
                     fmt::format("all {} pairs have the same x = {}; g cannot be identified",
                                 pairs.size(), pairs.x[0]));
  }
}

namespace {

std::string trim(const std::string& s) {
  std::size_t a = 0, b = s.size();
  while (a < b && (s[a] == ' ' || s[a] == '\t' || s[a] == '\r')) ++a;
  while (b > a && (s[b - 1] == ' ' || s[b - 1] == '\t' || s[b - 1] == '\r')) --b;
  return s.substr(a, b - a);
}

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> cells;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    cells.push_back(trim(line.substr(start, comma == std::string::npos ? std::string::npos
                                                                       : comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return cells;
}

}  // namespace

TissuePairs parse_tissue_pairs(const std::string& text, const std::string& source) {
  TissuePairs pairs;
  pairs.source = source;
  std::vector<double> xs, ys;
  std::size_t line_no = 0;
  std::size_t pos = 0;
  int col_x = -1, col_y = -1;
  std::size_t num_columns = 0;
  bool have_header = false;
  while (pos <= text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    if (trim(line).empty()) {
      if (end >= text.size()) break;
      continue;  // blank lines (e.g. the trailing newline) carry nothing
    }
    const auto cells = split_csv_line(line);
    if (!have_header) {
      have_header = true;
      num_columns = cells.size();
      for (std::size_t c = 0; c < cells.size(); ++c) {
        std::string name = cells[c];
        if (c == 0 && name.size() >= 3 && name.compare(0, 3, "\xEF\xBB\xBF") == 0) name.erase(0, 3);
        if (name == "x") {
          if (col_x >= 0) throw InputError({source, line_no, c + 1, "x"}, "column x appears twice");
          col_x = static_cast<int>(c);
        } else if (name == "y") {
          if (col_y >= 0) throw InputError({source, line_no, c + 1, "y"}, "column y appears twice");
          col_y = static_cast<int>(c);
        }
      }
      if (col_x < 0 || col_y < 0) {
        throw InputError({source, line_no, 0, col_x < 0 ? "x" : "y"},
                         "missing column: the header must name columns \"x\" (D tan(theta), m) "
                         "and \"y\" (force, N), got " + quote_token(trim(line), 80));
      }
      continue;
    }
    if (cells.size() != num_columns) {
      throw InputError({source, line_no, 0, ""},
                       fmt::format("expected {} cells as in the header, got {}", num_columns,
                                   cells.size()));
    }
    double values[2];
    const int cols[2] = {col_x, col_y};
    for (int k = 0; k < 2; ++k) {
      const std::string& cell = cells[static_cast<std::size_t>(cols[k])];
      const char* name = k == 0 ? "x" : "y";
      InputLocation loc{source, line_no, static_cast<std::size_t>(cols[k]) + 1, name};
      if (cell.empty()) throw InputError(loc, "expected a number, got an empty cell");
      errno = 0;
      char* stop = nullptr;
      const double v = std::strtod(cell.c_str(), &stop);
      if (stop != cell.c_str() + cell.size() || errno == ERANGE) {
        throw InputError(loc, "expected a number, got " + quote_token(cell));
      }
      if (!std::isfinite(v)) throw InputError(loc, "expected a finite number, got " + quote_token(cell));
      values[k] = v;
    }
    xs.push_back(values[0]);
    ys.push_back(values[1]);
    pairs.origin.push_back(line_no);
    if (end >= text.size()) break;
  }
  if (!have_header) throw InputError({source, 0, 0, ""}, "empty file: expected a header \"x,y\"");
  if (xs.empty()) throw InputError({source, 0, 0, ""}, "no pairs after the header");
  pairs.x = Eigen::Map<const Eigen::VectorXd>(xs.data(), static_cast<Eigen::Index>(xs.size()));
  pairs.y = Eigen::Map<const Eigen::VectorXd>(ys.data(), static_cast<Eigen::Index>(ys.size()));
  return pairs;
}

TissuePairs load_tissue_pairs(const std::filesystem::path& path) {
  return parse_tissue_pairs(read_text_file(path), path.string());
}

void save_tissue_pairs(const std::filesystem::path& path, const TissuePairs& pairs) {
  if (pairs.x.size() != pairs.y.size()) {
    throw std::invalid_argument("save_tissue_pairs: x and y differ in size");
  }
  std::string text = "x,y\n";
  text.reserve(text.size() + pairs.size() * 48);
  for (Eigen::Index i = 0; i < pairs.x.size(); ++i) {
    text += fmt::format("{},{}\n", pairs.x[i], pairs.y[i]);
  }
  write_file_atomic(path, text);
}

namespace {

void check_offset(double D_star, const std::string& source) {
  if (!std::isfinite(D_star) || D_star == 0.0) {
    throw InputError({source, 0, 0, "coaxial_offset_m"},
                     fmt::format("the calibration needs a known non-zero coaxial offset D*, got {}",
                                 D_star));
  }
}

std::size_t origin_of(const Recording& recording, std::size_t t) {
  return t < recording.line.size() ? recording.line[t] : t;
}

}  // namespace

namespace {

// A pair with finite x and y is kept with its origin; anything else is counted.
void keep_pair(const Recording& recording, Eigen::Index t, double x, double y, std::vector<double>& xs,
               std::vector<double>& ys, TissuePairsResult& result) {
  if (!std::isfinite(x) || !std::isfinite(y)) {
    ++result.report.dropped_non_finite;
    return;
  }
  xs.push_back(x);
  ys.push_back(y);
  result.pairs.origin.push_back(origin_of(recording, static_cast<std::size_t>(t)));
}

void finish_pairs(const std::vector<double>& xs, const std::vector<double>& ys, TissuePairsResult& result) {
  result.report.kept = xs.size();
  result.pairs.x = Eigen::Map<const Eigen::VectorXd>(xs.data(), static_cast<Eigen::Index>(xs.size()));
  result.pairs.y = Eigen::Map<const Eigen::VectorXd>(ys.data(), static_cast<Eigen::Index>(ys.size()));
}

}  // namespace

TissuePairsResult compute_tissue_pairs(const Recording& recording, const Eigen::MatrixXd& tau_fs,
                                       const Eigen::Vector3d& q0, double D_star,
                                       const TissuePairOptions& options) {
  check_offset(D_star, recording.source);
  const auto T = static_cast<Eigen::Index>(recording.num_samples());
  const IncisionFrame incision = make_incision_frame(q0);
  // Checks tau_fs (rcm/dynamics/torque_residual.hpp) before anything is computed.
  const IncisionForceSeries series =
      compute_incision_force_series(incision, recording, tau_fs, D_star, options.jacobian);

  TissuePairsResult result;
  result.report.samples = static_cast<std::size_t>(T);
  result.pairs.source = recording.source;
  std::vector<double> xs, ys;
  xs.reserve(static_cast<std::size_t>(T));
  ys.reserve(static_cast<std::size_t>(T));
  for (Eigen::Index t = 0; t < T; ++t) {
    const double theta = series.theta[t];
    const JacobianStatus status = series.status[static_cast<std::size_t>(t)];
    if (status == JacobianStatus::singular) {
      ++result.report.dropped_singular;
      continue;
    }
    if (status == JacobianStatus::ill_conditioned && options.drop_ill_conditioned) {
      ++result.report.dropped_ill_conditioned;
      continue;
    }
    if (!(std::fabs(theta) >= options.min_theta_rad)) {
      ++result.report.dropped_small_theta;
      continue;
    }
    const double y = series.f_inc_base.row(t).norm();
    const double x = D_star * std::tan(theta);
    keep_pair(recording, t, x, y, xs, ys, result);
  }
  finish_pairs(xs, ys, result);
  return result;
}

TissuePairsResult compute_tissue_pairs_from_measured_force(const Recording& recording,
                                                           const Eigen::Vector3d& q0,
                                                           double D_star,
                                                           const TissuePairOptions& options) {
  check_offset(D_star, recording.source);
  if (!recording.has_force()) {
    throw InputError({recording.source, 0, 0, "force_x"},
                     "measured-force pairs need the columns force_x, force_y, force_z");
  }
  const IncisionFrame incision = make_incision_frame(q0);
  const auto T = static_cast<Eigen::Index>(recording.num_samples());
  TissuePairsResult result;
  result.report.samples = static_cast<std::size_t>(T);
  result.pairs.source = recording.source;
  std::vector<double> xs, ys;
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Vector3d q = recording.position.row(t).head<3>().transpose();
    const double theta = compute_pivot_angle(incision, q);
    if (!(std::fabs(theta) >= options.min_theta_rad)) {
      ++result.report.dropped_small_theta;
      continue;
    }
    const double x = D_star * std::tan(theta);
    const double y = recording.force->row(t).norm();
    keep_pair(recording, t, x, y, xs, ys, result);
  }
  finish_pairs(xs, ys, result);
  return result;
}

TissuePairs compute_binned_pairs(const TissuePairs& pairs, std::size_t bins) {
  const std::size_t n = pairs.size();
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  // Stable: equal x keep their input order, so the result is deterministic.
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return pairs.x[static_cast<Eigen::Index>(a)] < pairs.x[static_cast<Eigen::Index>(b)];
  });
  TissuePairs out;
  out.source = pairs.source + (bins > 0 && bins < n ? fmt::format(" ({} bins)", bins) : "");
  if (bins == 0 || bins >= n) {
    out.x.resize(static_cast<Eigen::Index>(n));
    out.y.resize(static_cast<Eigen::Index>(n));
    for (std::size_t i = 0; i < n; ++i) {
      out.x[static_cast<Eigen::Index>(i)] = pairs.x[static_cast<Eigen::Index>(order[i])];
      out.y[static_cast<Eigen::Index>(i)] = pairs.y[static_cast<Eigen::Index>(order[i])];
      if (order[i] < pairs.origin.size()) out.origin.push_back(pairs.origin[order[i]]);
    }
    return out;
  }
  out.x.resize(static_cast<Eigen::Index>(bins));
  out.y.resize(static_cast<Eigen::Index>(bins));
  for (std::size_t b = 0; b < bins; ++b) {
    const std::size_t lo = b * n / bins, hi = (b + 1) * n / bins;
    double sx = 0.0, sy = 0.0;
    for (std::size_t i = lo; i < hi; ++i) {
      sx += pairs.x[static_cast<Eigen::Index>(order[i])];
      sy += pairs.y[static_cast<Eigen::Index>(order[i])];
    }
    const double count = static_cast<double>(hi - lo);
    out.x[static_cast<Eigen::Index>(b)] = sx / count;
    out.y[static_cast<Eigen::Index>(b)] = sy / count;
  }
  return out;
}

TissuePairs compute_rescaled_pairs(const TissuePairs& pairs, double D_from, double D_to) {
  if (!(std::isfinite(D_from) && std::isfinite(D_to) && D_from != 0.0)) {
    throw std::invalid_argument("compute_rescaled_pairs: offsets must be finite and D_from != 0");
  }
  TissuePairs out = pairs;
  out.x *= D_to / D_from;
  return out;
}

const OptionTable<TissuePairOptions>& get_option_table(OptionTag<TissuePairOptions>) {
  static const auto table =
      OptionTable<TissuePairOptions>("TissuePairOptions")
          .add("min_theta_rad", &TissuePairOptions::min_theta_rad,
               "samples with a pivot angle below this carry no information on g and are dropped", "rad",
               OptionLimits::from_below(0, 1.5))
          .add("drop_ill_conditioned", &TissuePairOptions::drop_ill_conditioned,
               "drop samples whose J_D* is ill-conditioned too, not only singular ones")
          .add_section("jacobian", &TissuePairOptions::jacobian, "when J_D* counts as ill-conditioned or singular");
  return table;
}

}  // namespace rcm
