#include "rcm/io/recording.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <iostream>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string_view>

#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"
#include "rcm/io/rosbag2.hpp"
#include "csv_parts.hpp"

namespace rcm {
namespace detail {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// Splits one CSV line into fields. Quotes are honoured so that ignored text
// columns (rostopic writes joint names) may contain commas; quoted fields do not
// span lines. Fields are views into `line` (quotes kept, trimmed later).
void split_fields(std::string_view line, std::vector<std::string_view>& fields) {
  fields.clear();
  std::size_t start = 0;
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      fields.push_back(line.substr(start, i - start));
      start = i + 1;
    }
  }
  fields.push_back(line.substr(start));
}

InputLocation locate(const std::string& source, std::size_t line, const std::string& field) {
  InputLocation where;
  where.file = source;
  where.line = line;
  where.field = field;
  where.kind = InputLocation::Kind::csv_column;  // rostopic names contain dots
  return where;
}

// Finds name_{first}, name_{first+1}, ... and returns the consecutive run; a
// later index without its predecessor is an error rather than a silent cut.
std::vector<Column> find_series(const std::map<std::string, std::size_t>& by_name,
                                const std::string& prefix, int first, const std::string& source) {
  std::vector<Column> out;
  for (int i = first;; ++i) {
    const auto it = by_name.find(prefix + std::to_string(i));
    if (it == by_name.end()) break;
    out.push_back({it->second, it->first});
  }
  const int next = first + static_cast<int>(out.size());
  for (const auto& [name, idx] : by_name) {
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string rest = name.substr(prefix.size());
    if (rest.empty() || !std::all_of(rest.begin(), rest.end(), [](unsigned char c) { return c >= '0' && c <= '9'; }) || rest.size() > 6) continue;
    const int k = std::stoi(rest);
    if (k > next) {
      throw InputError(locate(source, 1, name),
                       "present but column " + prefix + std::to_string(next) + " is missing");
    }
  }
  return out;
}

double parse_cell(std::string_view cell, const std::string& source, std::size_t line,
                  const std::string& column) {
  std::string_view s = trim(cell);
  if (s.size() >= 2 && s.front() == '"' && s.back() == '"') s = trim(s.substr(1, s.size() - 2));
  if (s.empty()) throw InputError(locate(source, line, column), "empty cell, expected a number");
  std::string_view digits = s;
  if (digits.front() == '+') digits.remove_prefix(1);
  double value = 0.0;
  const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  if (ec == std::errc::result_out_of_range)
    throw InputError(locate(source, line, column),
                     "number out of range, got " + quote_token(std::string(s)));
  if (ec != std::errc() || ptr != digits.data() + digits.size())
    throw InputError(locate(source, line, column),
                     "expected a number, got " + quote_token(std::string(s)));
  if (!std::isfinite(value))
    throw InputError(locate(source, line, column),
                     "expected a finite number, got " + quote_token(std::string(s)));
  return value;
}

std::map<std::string, std::size_t> index_header(const std::vector<std::string_view>& fields,
                                                const std::string& source) {
  std::map<std::string, std::size_t> by_name;
  for (std::size_t i = 0; i < fields.size(); ++i) {
    std::string_view f = trim(fields[i]);
    if (f.size() >= 2 && f.front() == '"' && f.back() == '"') f = f.substr(1, f.size() - 2);
    if (i == 0 && f.size() >= 3 && static_cast<unsigned char>(f[0]) == 0xEF &&
        static_cast<unsigned char>(f[1]) == 0xBB && static_cast<unsigned char>(f[2]) == 0xBF)
      f.remove_prefix(3);  // UTF-8 byte order mark written by some spreadsheet tools
    std::string name(f);
    if (name.empty()) continue;
    const bool inserted = by_name.emplace(name, i).second;
    if (!inserted) {
      InputLocation where = locate(source, 1, name);
      where.column = i + 1;
      throw InputError(where, "duplicate column name");
    }
  }
  return by_name;
}

std::vector<std::pair<std::size_t, std::string_view>> split_lines(std::string_view all) {
  // Lines, with their 1-based numbers; blank lines carry no data and are skipped.
  std::vector<std::pair<std::size_t, std::string_view>> lines;
  std::size_t number = 0, start = 0;
  while (start <= all.size()) {
    std::size_t end = all.find('\n', start);
    if (end == std::string_view::npos) end = all.size();
    ++number;
    std::string_view line = all.substr(start, end - start);
    if (!trim(line).empty()) lines.emplace_back(number, line);
    if (end == all.size()) break;
    start = end + 1;
  }
  return lines;
}

}  // namespace detail

namespace {

using detail::Column;
using detail::find_series;
using detail::index_header;
using detail::locate;
using detail::parse_cell;
using detail::split_fields;
using detail::split_lines;
using detail::trim;

struct Layout {
  RecordingLayout kind = RecordingLayout::rcm_csv;
  std::optional<Column> time;
  bool time_in_ns = false;
  int joints = 0;
  std::vector<Column> position, velocity, effort, force;
  std::size_t header_fields = 0;
};

Layout parse_header(const std::vector<std::string_view>& fields, const std::string& source,
                    const RecordingReadOptions& options) {
  Layout layout;
  layout.header_fields = fields.size();
  std::map<std::string, std::size_t> by_name = index_header(fields, source);

  const bool rostopic = by_name.count("%time") || by_name.count("field.position0");
  std::string pos_prefix = "position_", vel_prefix = "velocity_", eff_prefix = "effort_";
  int first = 1;
  if (rostopic) {
    layout.kind = RecordingLayout::rostopic_csv;
    pos_prefix = "field.position";
    vel_prefix = "field.velocity";
    eff_prefix = "field.effort";
    first = 0;
    if (by_name.count("%time")) {
      layout.time = Column{by_name["%time"], "%time"};
      layout.time_in_ns = true;
    }
  } else if (by_name.count("time")) {
    layout.time = Column{by_name["time"], "time"};
  }
  if (!layout.time && !options.assumed_rate_hz) {
    throw InputError(locate(source, 1, ""),
                     std::string("no time column ('") + (rostopic ? "%time" : "time") +
                         "'); give the sampling rate explicitly (--rate HZ) to number the samples");
  }

  layout.position = find_series(by_name, pos_prefix, first, source);
  layout.velocity = find_series(by_name, vel_prefix, first, source);
  layout.effort = find_series(by_name, eff_prefix, first, source);
  const std::size_t n = std::max({layout.position.size(), layout.velocity.size(), layout.effort.size()});
  const std::string* prefixes[3] = {&pos_prefix, &vel_prefix, &eff_prefix};
  const std::vector<Column>* series[3] = {&layout.position, &layout.velocity, &layout.effort};
  for (int k = 0; k < 3; ++k) {
    if (series[k]->size() < n) {
      throw InputError(locate(source, 1, *prefixes[k] + std::to_string(first + static_cast<int>(series[k]->size()))),
                       "missing: position, velocity and effort must be given for the same " +
                           std::to_string(n) + " joints");
    }
  }
  if (static_cast<int>(n) < options.min_joints) {
    throw InputError(locate(source, 1, pos_prefix + std::to_string(first + static_cast<int>(n))),
                     "missing: too few joints (" + std::to_string(n) + "), at least " +
                         std::to_string(options.min_joints) + " are required");
  }
  layout.joints = static_cast<int>(n);

  if (!rostopic) {
    const char* axes[3] = {"force_x", "force_y", "force_z"};
    int present = 0;
    for (const char* a : axes) present += by_name.count(a) ? 1 : 0;
    if (present != 0 && present != 3) {
      for (const char* a : axes)
        if (!by_name.count(a))
          throw InputError(locate(source, 1, a), "missing: force columns come as force_x, force_y, force_z together");
    }
    if (present == 3)
      for (const char* a : axes) layout.force.push_back({by_name[a], a});
  }
  return layout;
}

}  // namespace

Recording parse_recording(const std::string& text, const std::string& source,
                          const RecordingReadOptions& options) {
  if (options.assumed_rate_hz && !(*options.assumed_rate_hz > 0.0 && std::isfinite(*options.assumed_rate_hz)))
    throw InputError(locate(source, 0, ""), "the assumed sampling rate must be a positive number of Hz");

  const std::vector<std::pair<std::size_t, std::string_view>> lines = split_lines(text);
  if (lines.empty()) throw InputError(locate(source, 0, ""), "file is empty, expected a header row");
  if (lines.front().first != 1)
    throw InputError(locate(source, 1, ""), "expected the header row on line 1, found a blank line");

  std::vector<std::string_view> fields;
  split_fields(lines.front().second, fields);
  const Layout layout = parse_header(fields, source, options);
  if (lines.size() == 1) throw InputError(locate(source, 1, ""), "header only, no data rows");

  const Eigen::Index T = static_cast<Eigen::Index>(lines.size() - 1);
  const int N = layout.joints;
  Recording rec;
  rec.source = source;
  rec.layout = layout.kind;
  rec.time.resize(T);
  rec.position.resize(T, N);
  rec.velocity.resize(T, N);
  rec.effort.resize(T, N);
  if (!layout.force.empty()) rec.force = Eigen::MatrixXd(T, 3);
  rec.line.resize(static_cast<std::size_t>(T));

  for (Eigen::Index t = 0; t < T; ++t) {
    const auto& [number, line] = lines[static_cast<std::size_t>(t + 1)];
    split_fields(line, fields);
    if (fields.size() != layout.header_fields) {
      InputLocation where = locate(source, number, "");
      throw InputError(where, "expected " + std::to_string(layout.header_fields) +
                                  " comma-separated fields as in the header, found " +
                                  std::to_string(fields.size()) +
                                  (fields.size() < layout.header_fields ? " (truncated row?)" : ""));
    }
    rec.line[static_cast<std::size_t>(t)] = number;
    if (layout.time) {
      const double v = parse_cell(fields[layout.time->index], source, number, layout.time->name);
      rec.time[t] = layout.time_in_ns ? v * 1e-9 : v;
    } else {
      rec.time[t] = static_cast<double>(t) / *options.assumed_rate_hz;
    }
    for (int j = 0; j < N; ++j) {
      rec.position(t, j) = parse_cell(fields[layout.position[j].index], source, number, layout.position[j].name);
      rec.velocity(t, j) = parse_cell(fields[layout.velocity[j].index], source, number, layout.velocity[j].name);
      rec.effort(t, j) = parse_cell(fields[layout.effort[j].index], source, number, layout.effort[j].name);
    }
    for (int k = 0; k < static_cast<int>(layout.force.size()); ++k)
      (*rec.force)(t, k) = parse_cell(fields[layout.force[k].index], source, number, layout.force[k].name);
  }
  rec.time_from_rate = !layout.time.has_value();

  // Repeated samples: the logger wrote the same joint message again.
  std::vector<char> repeated(static_cast<std::size_t>(T), 0);
  for (Eigen::Index t = 1; t < T; ++t) {
    if (rec.position.row(t) == rec.position.row(t - 1) && rec.velocity.row(t) == rec.velocity.row(t - 1) &&
        rec.effort.row(t) == rec.effort.row(t - 1)) {
      repeated[static_cast<std::size_t>(t)] = 1;
      ++rec.repeated_rows;
    }
  }
  if (options.dedupe && rec.repeated_rows > 0) {
    if (rec.time_from_rate) {
      // Time was numbered from the rate over the rows as written; dropping rows
      // would leave gaps that the rate no longer describes.
      throw InputError(locate(source, 0, ""),
                       "cannot drop repeated rows of a file without a time column (the rate numbers the rows as written)");
    }
    Eigen::Index k = 0;
    for (Eigen::Index t = 0; t < T; ++t) {
      if (repeated[static_cast<std::size_t>(t)]) continue;
      rec.time[k] = rec.time[t];
      rec.position.row(k) = rec.position.row(t);
      rec.velocity.row(k) = rec.velocity.row(t);
      rec.effort.row(k) = rec.effort.row(t);
      if (rec.force) rec.force->row(k) = rec.force->row(t);
      rec.line[static_cast<std::size_t>(k)] = rec.line[static_cast<std::size_t>(t)];
      ++k;
    }
    rec.time.conservativeResize(k);
    rec.position.conservativeResize(k, N);
    rec.velocity.conservativeResize(k, N);
    rec.effort.conservativeResize(k, N);
    if (rec.force) rec.force->conservativeResize(k, 3);
    rec.line.resize(static_cast<std::size_t>(k));
    rec.repeated_rows_removed = true;
  }

  for (Eigen::Index t = 1; t < rec.time.size(); ++t) {
    if (!(rec.time[t] > rec.time[t - 1])) {
      const bool is_repeat = !rec.repeated_rows_removed && repeated[static_cast<std::size_t>(t)];
      throw InputError(locate(source, rec.line[static_cast<std::size_t>(t)], layout.time ? layout.time->name : "time"),
                       "time must increase strictly: " + std::to_string(rec.time[t]) + " s after " +
                           std::to_string(rec.time[t - 1]) + " s on line " +
                           std::to_string(rec.line[static_cast<std::size_t>(t - 1)]) +
                           (is_repeat ? " (this row repeats the previous sample; --dedupe drops repeated rows)" : ""));
    }
  }
  return rec;
}

namespace {
std::mutex& reader_mutex() {
  static std::mutex m;
  return m;
}
std::map<std::string, RecordingFileReader>& readers() {
  static std::map<std::string, RecordingFileReader> r;  // function-local: safe across TUs
  return r;
}
}  // namespace

void register_recording_reader(const std::string& extension, RecordingFileReader reader) {
  const std::lock_guard<std::mutex> lock(reader_mutex());
  readers()[extension] = std::move(reader);
}

Recording load_recording(const std::filesystem::path& path, const RecordingReadOptions& options) {
  std::error_code ec;
  const std::string key = std::filesystem::is_directory(path, ec) ? "/" : path.extension().string();
  RecordingFileReader reader;
  {
    const std::lock_guard<std::mutex> lock(reader_mutex());
    const auto it = readers().find(key);
    if (it != readers().end()) reader = it->second;
  }
  if (reader) return reader(path, options);
  if (is_rosbag2_path(path)) {
    Rosbag2ReadInfo info;
    Recording rec = load_rosbag2_recording(path, with_session_topics({}, options), &info);
    for (const std::string& w : info.warnings) std::cerr << "warning: " << w << "\n";
    return rec;
  }
  return parse_recording(read_text_file(path), path.string(), options);
}

Recording get_recording_rows(const Recording& recording, Eigen::Index begin, Eigen::Index end) {
  const Eigen::Index T = recording.time.size();
  if (begin < 0 || end > T || begin > end)
    throw std::out_of_range("get_recording_rows: [" + std::to_string(begin) + ", " + std::to_string(end) +
                            ") outside " + std::to_string(T) + " samples of " + recording.source);
  Recording out;
  out.source = recording.source;
  out.layout = recording.layout;
  const Eigen::Index n = end - begin;
  out.time = recording.time.segment(begin, n);
  out.position = recording.position.middleRows(begin, n);
  out.velocity = recording.velocity.middleRows(begin, n);
  out.effort = recording.effort.middleRows(begin, n);
  if (recording.force) out.force = recording.force->middleRows(begin, n);
  if (!recording.line.empty())
    out.line.assign(recording.line.begin() + begin, recording.line.begin() + end);
  out.time_from_rate = recording.time_from_rate;
  out.repeated_rows_removed = recording.repeated_rows_removed;
  return out;
}

void validate_recording(const Recording& r) {
  InputLocation where;
  where.file = r.source.empty() ? "<recording>" : r.source;
  const Eigen::Index T = r.time.size();
  if (T == 0) throw InputError(where, "recording has no samples");
  if (r.position.cols() < 3) throw InputError(where, "recording has fewer than 3 joints");
  if (r.position.rows() != T || r.velocity.rows() != T || r.effort.rows() != T ||
      r.velocity.cols() != r.position.cols() || r.effort.cols() != r.position.cols())
    throw InputError(where, "position, velocity and effort must all be T x N with the same T and N");
  if (r.force && (r.force->rows() != T || r.force->cols() != 3))
    throw InputError(where, "force must be T x 3");
  if (!r.line.empty() && r.line.size() != static_cast<std::size_t>(T))
    throw InputError(where, "line numbers must be given for every sample or none");
  auto check_finite = [&](const Eigen::MatrixXd& m, const char* what) {
    for (Eigen::Index t = 0; t < m.rows(); ++t)
      for (Eigen::Index j = 0; j < m.cols(); ++j)
        if (!std::isfinite(m(t, j))) {
          InputLocation w = where;
          w.line = r.line.empty() ? 0 : r.line[static_cast<std::size_t>(t)];
          w.field = std::string(what) + "_" + std::to_string(j + 1);
          throw InputError(w, "not a finite number (sample " + std::to_string(t) + ")");
        }
  };
  check_finite(r.time, "time");
  check_finite(r.position, "position");
  check_finite(r.velocity, "velocity");
  check_finite(r.effort, "effort");
  if (r.force) check_finite(*r.force, "force");
  for (Eigen::Index t = 1; t < T; ++t)
    if (!(r.time[t] > r.time[t - 1])) {
      InputLocation w = where;
      w.field = "time";
      w.line = r.line.empty() ? 0 : r.line[static_cast<std::size_t>(t)];
      throw InputError(w, "time must increase strictly (sample " + std::to_string(t) + ")");
    }
}

void save_recording(const std::filesystem::path& path, const Recording& r) {
  validate_recording(r);
  const int N = r.num_joints();
  std::string out;
  out.reserve(static_cast<std::size_t>(r.time.size()) * static_cast<std::size_t>(3 * N + 4) * 14 + 256);
  out += "time";
  for (const char* prefix : {"position_", "velocity_", "effort_"})
    for (int j = 1; j <= N; ++j) (out += ',') += prefix + std::to_string(j);
  if (r.force) out += ",force_x,force_y,force_z";
  out += '\n';
  char buf[32];
  auto put = [&](double v) {
    const auto res = std::to_chars(buf, buf + sizeof buf, v);  // shortest round-trip form
    out.append(buf, res.ptr);
  };
  for (Eigen::Index t = 0; t < r.time.size(); ++t) {
    put(r.time[t]);
    for (const Eigen::MatrixXd* m : {&r.position, &r.velocity, &r.effort})
      for (int j = 0; j < N; ++j) {
        out += ',';
        put((*m)(t, j));
      }
    if (r.force)
      for (int k = 0; k < 3; ++k) {
        out += ',';
        put((*r.force)(t, k));
      }
    out += '\n';
  }
  write_file_atomic(path, out);
}

RecordingSummary summarize_recording(const Recording& r) {
  RecordingSummary s;
  const Eigen::Index T = r.time.size();
  s.samples = static_cast<std::size_t>(T);
  s.joints = r.num_joints();
  s.repeated_rows = r.repeated_rows;
  s.repeated_rows_removed = r.repeated_rows_removed;
  s.has_force = r.has_force();
  s.time_from_rate = r.time_from_rate;
  if (T >= 2) {
    s.duration_s = r.time[T - 1] - r.time[0];
    std::vector<double> dt(static_cast<std::size_t>(T - 1));
    for (Eigen::Index t = 1; t < T; ++t) dt[static_cast<std::size_t>(t - 1)] = r.time[t] - r.time[t - 1];
    double mean = 0.0;
    for (double d : dt) mean += d;
    mean /= static_cast<double>(dt.size());
    double var = 0.0;
    for (double d : dt) var += (d - mean) * (d - mean);
    s.jitter_s = std::sqrt(var / static_cast<double>(dt.size()));
    s.dt_min_s = *std::min_element(dt.begin(), dt.end());
    s.dt_max_s = *std::max_element(dt.begin(), dt.end());
    std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
    s.dt_median_s = dt[dt.size() / 2];
    s.rate_hz = s.dt_median_s > 0 ? 1.0 / s.dt_median_s : 0.0;
  }
  auto ranges = [&](const Eigen::MatrixXd& m) {
    std::vector<RecordingSummary::Range> out;
    for (Eigen::Index j = 0; j < m.cols(); ++j)
      out.push_back({T ? m.col(j).minCoeff() : 0.0, T ? m.col(j).maxCoeff() : 0.0});
    return out;
  };
  s.position = ranges(r.position);
  s.velocity = ranges(r.velocity);
  s.effort = ranges(r.effort);
  if (r.force) s.force = ranges(*r.force);
  return s;
}

const OptionTable<RecordingReadOptions>& get_option_table(OptionTag<RecordingReadOptions>) {
  static const auto table =
      OptionTable<RecordingReadOptions>("RecordingReadOptions")
          .add("dedupe", &RecordingReadOptions::dedupe, "drop rows whose joint data repeat the previous row's")
          .add("assumed_rate_hz", &RecordingReadOptions::assumed_rate_hz,
               "sampling rate of a file without a time column (null: such a file is an error)", "Hz",
               OptionLimits::above(0))
          .add("min_joints", &RecordingReadOptions::min_joints, "joints a recording must have at least", "",
               OptionLimits::at_least(1))
          .add("joint_topic", &RecordingReadOptions::joint_topic,
               "bags: the JointState topic (empty: the reader's default or the session's)")
          .add("force_topic", &RecordingReadOptions::force_topic,
               "bags: the WrenchStamped force topic (empty: the reader's default or the session's)");
  return table;
}

}  // namespace rcm
