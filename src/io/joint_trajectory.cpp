#include "rcm/io/joint_trajectory.hpp"

#include <charconv>
#include <cmath>
#include <string>

#include "csv_parts.hpp"
#include "rcm/common/error.hpp"
#include "rcm/common/text_file.hpp"
#include "rcm/io/atomic_file.hpp"

namespace rcm {

using detail::locate;

JointTrajectory parse_joint_trajectory(const std::string& text, const std::string& source) {
  const auto lines = detail::split_lines(text);
  if (lines.empty()) throw InputError(locate(source, 0, ""), "file is empty, expected a header row");
  if (lines.front().first != 1)
    throw InputError(locate(source, 1, ""), "expected the header row on line 1, found a blank line");
  std::vector<std::string_view> fields;
  detail::split_fields(lines.front().second, fields);
  const std::size_t header_fields = fields.size();
  const auto by_name = detail::index_header(fields, source);
  const auto time_it = by_name.find("time");
  if (time_it == by_name.end()) throw InputError(locate(source, 1, "time"), "missing: a trajectory needs a time column");
  const detail::Column time{time_it->second, "time"};
  const std::vector<detail::Column> position = detail::find_series(by_name, "position_", 1, source);
  const std::vector<detail::Column> velocity = detail::find_series(by_name, "velocity_", 1, source);
  if (position.size() != velocity.size()) {
    const bool fewer_velocities = velocity.size() < position.size();
    const std::size_t n = fewer_velocities ? velocity.size() : position.size();
    throw InputError(locate(source, 1, (fewer_velocities ? "velocity_" : "position_") + std::to_string(n + 1)),
                     "missing: position and velocity must be given for the same joints");
  }
  if (position.size() < 3)
    throw InputError(locate(source, 1, "position_" + std::to_string(position.size() + 1)),
                     "missing: too few joints (" + std::to_string(position.size()) + "), at least 3 are required");
  if (lines.size() == 1) throw InputError(locate(source, 1, ""), "header only, no data rows");

  const Eigen::Index T = static_cast<Eigen::Index>(lines.size() - 1);
  const int N = static_cast<int>(position.size());
  JointTrajectory out;
  out.source = source;
  out.time.resize(T);
  out.position.resize(T, N);
  out.velocity.resize(T, N);
  out.line.resize(static_cast<std::size_t>(T));
  for (Eigen::Index t = 0; t < T; ++t) {
    const auto& [number, line] = lines[static_cast<std::size_t>(t + 1)];
    detail::split_fields(line, fields);
    if (fields.size() != header_fields)
      throw InputError(locate(source, number, ""),
                       "expected " + std::to_string(header_fields) + " comma-separated fields as in the header, found " +
                           std::to_string(fields.size()) + (fields.size() < header_fields ? " (truncated row?)" : ""));
    out.line[static_cast<std::size_t>(t)] = number;
    out.time[t] = detail::parse_cell(fields[time.index], source, number, time.name);
    for (int j = 0; j < N; ++j) {
      out.position(t, j) = detail::parse_cell(fields[position[j].index], source, number, position[j].name);
      out.velocity(t, j) = detail::parse_cell(fields[velocity[j].index], source, number, velocity[j].name);
    }
    if (t > 0 && !(out.time[t] > out.time[t - 1]))
      throw InputError(locate(source, number, "time"),
                       "time must increase strictly: " + std::to_string(out.time[t]) + " s after " +
                           std::to_string(out.time[t - 1]) + " s on line " +
                           std::to_string(out.line[static_cast<std::size_t>(t - 1)]));
  }
  return out;
}

JointTrajectory load_joint_trajectory(const std::filesystem::path& path) {
  return parse_joint_trajectory(read_text_file(path), path.string());
}

void save_joint_trajectory(const std::filesystem::path& path, const JointTrajectory& r) {
  const Eigen::Index T = r.time.size();
  const int N = r.num_joints();
  InputLocation where;
  where.file = r.source;
  if (T == 0 || r.position.rows() != T || r.velocity.rows() != T || r.velocity.cols() != N || N < 1)
    throw InputError(where, "a trajectory needs as many positions and velocities as time stamps, and samples");
  for (Eigen::Index t = 0; t < T; ++t) {
    if (!std::isfinite(r.time[t]) || !r.position.row(t).allFinite() || !r.velocity.row(t).allFinite())
      throw InputError(where, "sample " + std::to_string(t) + " is not finite");
    if (t > 0 && !(r.time[t] > r.time[t - 1]))
      throw InputError(where, "time must increase strictly (sample " + std::to_string(t) + ")");
  }
  std::string out;
  out.reserve(static_cast<std::size_t>(T) * static_cast<std::size_t>(2 * N + 1) * 14 + 128);
  out += "time";
  for (const char* prefix : {"position_", "velocity_"})
    for (int j = 1; j <= N; ++j) (out += ',') += prefix + std::to_string(j);
  out += '\n';
  char buf[32];
  auto put = [&](double v) {
    const auto res = std::to_chars(buf, buf + sizeof buf, v);  // shortest round-trip form
    out.append(buf, res.ptr);
  };
  for (Eigen::Index t = 0; t < T; ++t) {
    put(r.time[t]);
    for (const Eigen::MatrixXd* m : {&r.position, &r.velocity})
      for (int j = 0; j < N; ++j) {
        out += ',';
        put((*m)(t, j));
      }
    out += '\n';
  }
  write_file_atomic(path, out);
}

}  // namespace rcm
