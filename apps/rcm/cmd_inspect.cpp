// rcm inspect: validate and summarize a recording or a session manifest.

#include <fmt/format.h>

#include <iostream>
#include <optional>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "message_cli.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/io/session.hpp"

namespace {
namespace cmd_inspect {

struct Options {
  std::string file;
  bool json = false, dedupe = false;
  double rate_hz = 0.0;
};

// A recording read in chunks: constant memory whatever its length (the exact
// median interval may read it a second time, rcm/io/recording_reader.hpp).
nlohmann::json summary_json(const std::filesystem::path& path, const rcm::RecordingReadOptions& read) {
  const auto reader = rcm::open_recording(path, read);
  const rcm::RecordingSummary s =
      rcm::summarize_recording(*reader, [&] { return rcm::open_recording(path, read); });
  const std::string& source = reader->source();
  const rcm::RecordingLayout layout = reader->layout();
  auto ranges = [](const std::vector<rcm::RecordingSummary::Range>& v) {
    nlohmann::json a = nlohmann::json::array();
    for (const auto& x : v) a.push_back({x.min, x.max});
    return a;
  };
  nlohmann::json j = {{"file", source},
                      {"layout", layout == rcm::RecordingLayout::rostopic_csv ? "rostopic"
                                : layout == rcm::RecordingLayout::rosbag     ? "rosbag"
                                : layout == rcm::RecordingLayout::rosbag2    ? "rosbag2"
                                                                              : "rcm"},
                      {"samples", s.samples},
                      {"joints", s.joints},
                      {"duration_s", s.duration_s},
                      {"rate_hz", s.rate_hz},
                      {"dt_median_s", s.dt_median_s},
                      {"dt_min_s", s.dt_min_s},
                      {"dt_max_s", s.dt_max_s},
                      {"jitter_s", s.jitter_s},
                      {"repeated_rows", s.repeated_rows},
                      {"repeated_rows_removed", s.repeated_rows_removed},
                      {"time_from_rate", s.time_from_rate},
                      {"has_force", s.has_force},
                      {"position_range", ranges(s.position)},
                      {"velocity_range", ranges(s.velocity)},
                      {"effort_range", ranges(s.effort)}};
  if (s.has_force) j["force_range"] = ranges(s.force);
  if (const rcm::Rosbag2ReadInfo* b = rcm::cli::find_rosbag2_info(source))
    j["rosbag2"] = {{"storage", b->storage},
                    {"files", b->files},
                    {"metadata_version", b->metadata_version},
                    {"sqlite_schema", b->sqlite_schema},
                    {"topic", b->topic},
                    {"time_source", b->receive_time ? "receive_time" : "header_stamp"},
                    {"messages", b->messages},
                    {"zero_stamp_messages", b->zero_stamp_messages},
                    {"joint_names", b->joint_names},
                    {"warnings", b->warnings}};
  return j;
}

void print_recording(const nlohmann::json& j, const std::string& indent) {
  std::cout << fmt::format("{}{}: {} samples, {} joints, {:.3f} s at {:.1f} Hz (dt {:.2f}..{:.2f} ms, jitter {:.3f} ms)\n",
                           indent, j["file"].get<std::string>(), j["samples"].get<std::size_t>(),
                           j["joints"].get<int>(), j["duration_s"].get<double>(), j["rate_hz"].get<double>(),
                           1e3 * j["dt_min_s"].get<double>(), 1e3 * j["dt_max_s"].get<double>(),
                           1e3 * j["jitter_s"].get<double>());
  const std::size_t repeated = j["repeated_rows"].get<std::size_t>();
  if (repeated > 0)
    std::cout << fmt::format("{}  repeated rows: {} ({:.1f} %){}\n", indent, repeated,
                             100.0 * repeated / (j["samples"].get<double>() + (j["repeated_rows_removed"].get<bool>() ? repeated : 0)),
                             j["repeated_rows_removed"].get<bool>() ? ", removed (--dedupe)" : ", kept (use --dedupe to drop them)");
  if (j["time_from_rate"].get<bool>()) std::cout << indent << "  time: numbered from --rate (no time column)\n";
  if (j.contains("rosbag2")) {
    const nlohmann::json& b = j["rosbag2"];
    std::cout << fmt::format("{}  rosbag2 ({}, {} file(s)): {} messages on {}, time {}", indent,
                             b["storage"].get<std::string>(), b["files"].size(), b["messages"].get<std::size_t>(),
                             b["topic"].get<std::string>(), b["time_source"].get<std::string>());
    const std::size_t zero = b["zero_stamp_messages"].get<std::size_t>();
    std::cout << (zero > 0 ? fmt::format(", {} skipped (zero header.stamp: invalid data)\n", zero) : std::string("\n"));
  }
  std::vector<std::vector<std::string>> rows;
  for (std::size_t k = 0; k < j["position_range"].size(); ++k) {
    auto f = [&](const char* key) {
      return fmt::format("{:.4g}..{:.4g}", j[key][k][0].get<double>(), j[key][k][1].get<double>());
    };
    rows.push_back({std::to_string(k + 1), f("position_range"), f("velocity_range"), f("effort_range")});
  }
  std::string table = rcm::cli::format_table({"joint", "position", "velocity", "effort"}, rows);
  for (std::size_t p = 0; (p = table.find('\n', p)) != std::string::npos && p + 1 < table.size(); p += indent.size() + 3)
    table.insert(p + 1, indent + "  ");
  std::cout << indent << "  " << table;
  if (j["has_force"].get<bool>())
    std::cout << fmt::format("{}  force columns: x {:.3g}..{:.3g}, y {:.3g}..{:.3g}, z {:.3g}..{:.3g} N\n", indent,
                             j["force_range"][0][0].get<double>(), j["force_range"][0][1].get<double>(),
                             j["force_range"][1][0].get<double>(), j["force_range"][1][1].get<double>(),
                             j["force_range"][2][0].get<double>(), j["force_range"][2][1].get<double>());
  else
    std::cout << indent << "  force columns: none\n";
}

void print_contents(const rcm::Rosbag2Contents& c) {
  std::cout << fmt::format("rosbag2 recording: {} ({} file(s){}{})\n", c.layout, c.files.size(),
                           c.metadata_version ? fmt::format(", metadata.yaml version {}", c.metadata_version) : "",
                           c.ros_distro.empty() ? "" : ", ROS " + c.ros_distro);
  std::vector<std::vector<std::string>> rows;
  for (const auto& t : c.topics)
    rows.push_back({t.name, t.type, t.serialization, std::to_string(t.messages),
                    t.get_rate_hz() > 0 ? fmt::format("{:.1f}", t.get_rate_hz()) : "-"});
  std::string table = rcm::cli::format_table({"topic", "type", "format", "messages", "rate Hz"}, rows);
  for (std::size_t p = 0; (p = table.find('\n', p)) != std::string::npos && p + 1 < table.size(); p += 3)
    table.insert(p + 1, "  ");
  std::cout << "  " << table;
}

nlohmann::json contents_json(const rcm::Rosbag2Contents& c) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& t : c.topics)
    a.push_back({{"name", t.name}, {"type", t.type}, {"serialization", t.serialization}, {"messages", t.messages},
                 {"rate_hz", t.get_rate_hz()}});
  return a;
}

void run(const Options& o) {
  rcm::RecordingReadOptions read;
  read.dedupe = o.dedupe;
  if (o.rate_hz > 0) read.assumed_rate_hz = o.rate_hz;
  const bool is_json = o.file.size() > 5 && o.file.substr(o.file.size() - 5) == ".json";
  if (!is_json) {
    // A rosbag2 recording: what it holds first, so that a missing topic shows what is there.
    std::optional<rcm::Rosbag2Contents> contents;
    if (rcm::is_rosbag2_path(o.file)) {
      contents = rcm::list_rosbag2_contents(o.file);
      if (!o.json) print_contents(*contents);
    }
    nlohmann::json j = summary_json(o.file, read);
    if (contents) j["rosbag2"]["topics"] = contents_json(*contents);
    if (o.json) rcm::cli::print_json(j);
    else print_recording(j, "");
    return;
  }
  const rcm::Session s = rcm::load_session(o.file);
  nlohmann::json out = {{"file", o.file}, {"format", "rcm-session/1"}, {"robot", s.robot},
                        {"q0", rcm::cli::to_json(s.q0)}};
  const rcm::RecordingReadOptions session_read = rcm::get_read_options(s, read);
  auto load = [&](const std::filesystem::path& p) { return summary_json(p, session_read); };
  out["free_space"] = nlohmann::json::array();
  for (const auto& p : s.free_space) out["free_space"].push_back(load(p));
  if (s.baseline) out["baseline"] = load(*s.baseline);
  if (s.calibration) {
    out["calibration"] = load(s.calibration->recording);
    out["calibration"]["coaxial_offset_m"] = s.calibration->coaxial_offset_m;
  }
  out["trials"] = nlohmann::json::array();
  for (const auto& t : s.trials) {
    nlohmann::json jt = {{"name", t.name}, {"recording", load(t.recording)}};
    if (t.static_recording) jt["static"] = load(*t.static_recording);
    if (t.truth_misalignment_m) jt["truth_misalignment_m"] = rcm::cli::to_json(*t.truth_misalignment_m);
    out["trials"].push_back(jt);
  }
  if (o.json) {
    rcm::cli::print_json(out);
    return;
  }
  std::cout << fmt::format("session {} (robot {}, q0 [{:.4f}, {:.4f}, {:.4f}]): every file read and valid\n", o.file,
                           s.robot, s.q0[0], s.q0[1], s.q0[2]);
  std::cout << "free space:\n";
  for (const auto& j : out["free_space"]) print_recording(j, "  ");
  if (s.baseline) {
    std::cout << "baseline:\n";
    print_recording(out["baseline"], "  ");
  }
  if (s.calibration) {
    std::cout << fmt::format("calibration (D* = {:.1f} mm):\n", 1e3 * s.calibration->coaxial_offset_m);
    print_recording(out["calibration"], "  ");
  }
  std::cout << fmt::format("trials: {}\n", s.trials.size());
  for (const auto& jt : out["trials"]) {
    std::string truth = jt.contains("truth_misalignment_m")
                            ? fmt::format(" truth [{:.1f}, {:.1f}, {:.1f}] mm", 1e3 * jt["truth_misalignment_m"][0].get<double>(),
                                          1e3 * jt["truth_misalignment_m"][1].get<double>(),
                                          1e3 * jt["truth_misalignment_m"][2].get<double>())
                            : "";
    std::cout << fmt::format("  {}{}\n", jt["name"].get<std::string>(), truth);
    print_recording(jt["recording"], "    ");
    if (jt.contains("static")) print_recording(jt["static"], "    ");
  }
}

const bool registered = rcm::cli::register_command({"inspect", 10, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "inspect",
      "Validate and summarize a recording or a session (.json), read in chunks in constant memory");
  cmd->add_option("FILE", o->file,
                  "recording (rcm or rostopic CSV, ROS 1 .bag, rosbag2 directory, .db3 or .mcap) or session manifest")
      ->required();
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->add_flag("--dedupe", o->dedupe, "drop rows that repeat the previous sample exactly");
  cmd->add_option("--rate", o->rate_hz, "sampling rate (Hz) to assume for files without a time column");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_inspect
}  // namespace
