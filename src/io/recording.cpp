#include "rcm/io/recording.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string_view>

#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/json_file.hpp"
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

RecordingWriter::RecordingWriter(const std::filesystem::path& path, int joints, bool has_force)
    : file_(path), joints_(joints), has_force_(has_force) {
  std::string header = "time";
  for (const char* prefix : {"position_", "velocity_", "effort_"})
    for (int j = 1; j <= joints; ++j) (header += ',') += prefix + std::to_string(j);
  if (has_force) header += ",force_x,force_y,force_z";
  header += '\n';
  file_.append(header);
}

void RecordingWriter::write(const Recording& r) {
  if (r.num_samples() == 0) return;
  validate_recording(r);
  if (r.num_joints() != joints_ || r.has_force() != has_force_)
    throw std::invalid_argument("RecordingWriter: a chunk of another shape than the file's");
  if (samples_ > 0 && !(r.time[0] > last_time_)) {
    InputLocation where;
    where.file = r.source.empty() ? "<recording>" : r.source;
    where.field = "time";
    where.line = r.line.empty() ? 0 : r.line.front();
    throw InputError(where, "time must increase strictly (sample " + std::to_string(samples_) + ")");
  }
  const int N = joints_;
  std::string& out = text_;
  out.clear();
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
  file_.append(out);
  samples_ += r.num_samples();
  last_time_ = r.time[r.time.size() - 1];
}

void RecordingWriter::commit() { file_.commit(); }

void save_recording(const std::filesystem::path& path, const Recording& r) {
  validate_recording(r);
  RecordingWriter writer(path, r.num_joints(), r.has_force());
  writer.write(r);
  writer.commit();
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
