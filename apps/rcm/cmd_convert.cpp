// rcm convert: a bag's joint-state topic (and optionally a force topic) to the
// rcm CSV layout, validated as every recording is (docs/formats.md): a rosbag2
// recording always, a ROS 1 bag when built with ROS. Every command also reads
// bags directly; convert makes a file other tools read. The other way, any
// recording to a rosbag2 bag (.mcap, .db3), for ROS 2's own tools.

#include <fmt/format.h>

#include <iostream>
#include <memory>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "message_cli.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/io/rosbag2.hpp"
#include "rcm/io/rosbag2_writer.hpp"
#if RCM_HAVE_ROS
#include "rcm/ros/bag_reader.hpp"
#endif

namespace {
namespace cmd_convert {

struct Options {
  std::string in, out, joint_names;
  bool dedupe = false, json = false;
  std::int64_t time_origin_ns = 0;  // to a bag; 0: the input bag's, else the writer's default
};

// A rosbag2 storage file named as the output: the recording is written as a bag.
bool is_bag_output(const std::filesystem::path& out) { return out.extension() == ".mcap" || out.extension() == ".db3"; }

// What the two readers report, in one shape.
struct ReadInfo {
  std::vector<std::string> joint_names;
  std::int64_t time_origin_ns = 0;
  std::string time_source;  // "header_stamp", "bag_time", "receive_time"
  std::size_t messages = 0, zero_stamp_messages = 0, force_messages = 0;
  std::string force_frame_id, format;
};

rcm::Recording read(const Options& o, const rcm::TopicReadOptions& options, ReadInfo& info) {
  const std::filesystem::path in = o.in;
  if (rcm::is_rosbag2_path(in)) {
    const rcm::Recording rec = rcm::cli::load_rosbag2(in, options);
    const rcm::Rosbag2ReadInfo& r = *rcm::cli::find_rosbag2_info(o.in);
    info = {r.joint_names, r.time_origin_ns, options.time == rcm::MessageTime::receive ? "receive_time" : "header_stamp",
            r.messages, r.zero_stamp_messages, r.force_messages, r.force_frame_id, "rosbag2 (" + r.storage + ")"};
    return rec;
  }
  if (in.extension() == ".bag") {
#if RCM_HAVE_ROS
    rcm::BagReadInfo r;
    const rcm::Recording rec = rcm::load_bag_recording(in, options, &r);
    info = {r.joint_names, r.time_origin_ns, r.bag_time ? "bag_time" : "header_stamp", r.messages, 0,
            r.force_messages, r.force_frame_id, "rosbag"};
    return rec;
#else
    return rcm::load_recording(in);  // the .bag reader of a build without ROS says why not
#endif
  }
  if (is_bag_output(o.out)) {
    rcm::RecordingReadOptions read;
    read.dedupe = o.dedupe;
    rcm::Recording rec = rcm::load_recording(in, read);
    info.format = "recording";
    info.time_source = "time_column";
    info.messages = rec.num_samples();
    return rec;
  }
  rcm::InputLocation where;
  where.file = o.in;
  throw rcm::InputError(where, "not a bag: convert reads a rosbag2 directory, a .db3 or .mcap file, or a ROS 1 .bag "
                               "(a CSV recording converts to a bag: name the output .mcap or .db3)");
}

// To CSV: the bag's reader, read a chunk at a time into the output.
std::unique_ptr<rcm::MessageRecordingReader> open_bag(const Options& o, const rcm::TopicReadOptions& options) {
  const std::filesystem::path in = o.in;
  if (rcm::is_rosbag2_path(in)) return rcm::cli::open_rosbag2(in, options);
  if (in.extension() == ".bag") {
#if RCM_HAVE_ROS
    return rcm::open_bag_recording(in, options);
#else
    (void)rcm::open_recording(in);  // the .bag reader of a build without ROS says why not
#endif
  }
  rcm::InputLocation where;
  where.file = o.in;
  throw rcm::InputError(where, "not a bag: convert reads a rosbag2 directory, a .db3 or .mcap file, or a ROS 1 .bag "
                               "(a CSV recording converts to a bag: name the output .mcap or .db3)");
}

// What the reader counted, once it has been read to its end.
ReadInfo get_info(const rcm::MessageRecordingReader& reader, const rcm::TopicReadOptions& options) {
  if (const auto* b = dynamic_cast<const rcm::Rosbag2RecordingReader*>(&reader)) {
    const rcm::Rosbag2ReadInfo& r = b->info();
    return {r.joint_names, r.time_origin_ns, options.time == rcm::MessageTime::receive ? "receive_time" : "header_stamp",
            r.messages, r.zero_stamp_messages, r.force_messages, r.force_frame_id, "rosbag2 (" + r.storage + ")"};
  }
#if RCM_HAVE_ROS
  const rcm::BagReadInfo& r = static_cast<const rcm::BagRecordingReader&>(reader).info();
  return {r.joint_names, r.time_origin_ns, r.bag_time ? "bag_time" : "header_stamp", r.messages, 0,
          r.force_messages, r.force_frame_id, "rosbag"};
#else
  return {};
#endif
}

// What the summary prints of the recording written.
struct Written {
  Eigen::Index samples = 0;
  int joints = 0;
  double duration_s = 0.0;
  std::size_t repeated = 0;
  bool removed = false, has_force = false;
};

// A bag to CSV, chunk by chunk into the output's temporary: memory does not grow with the bag.
Written stream_to_csv(const Options& o, const rcm::TopicReadOptions& bag, ReadInfo& info) {
  const auto reader = open_bag(o, bag);
  rcm::RecordingWriter writer(o.out, reader->num_joints(), reader->has_force());
  rcm::Recording chunk;
  double first_time = 0.0, last_time = 0.0;
  while (reader->read_chunk(chunk)) {
    if (writer.samples() == 0) first_time = chunk.time(0);
    last_time = chunk.time(chunk.time.size() - 1);
    writer.write(chunk);
  }
  writer.commit();
  info = get_info(*reader, bag);
  Written w;
  w.samples = static_cast<Eigen::Index>(writer.samples());
  w.joints = reader->num_joints();
  w.duration_s = w.samples > 1 ? last_time - first_time : 0.0;
  w.repeated = reader->repeated_rows();
  w.removed = reader->repeated_rows_removed();
  w.has_force = reader->has_force();
  return w;
}

// The recording as a bag: the joint names it was read with (the dVRK's by
// default), the --topic and --force-topic names, stamps from --time-origin-ns.
void write_bag(const Options& o, const rcm::TopicReadOptions& topics, const ReadInfo& info, const rcm::Recording& rec) {
  rcm::Rosbag2WriteOptions w;
  w.storage = std::filesystem::path(o.out).extension() == ".db3" ? rcm::Rosbag2WriteOptions::Storage::sqlite3
                                                                  : rcm::Rosbag2WriteOptions::Storage::mcap;
  w.topic = topics.topic;
  if (!topics.force_topic.empty()) w.force_topic = topics.force_topic;
  if (info.joint_names.size() == static_cast<std::size_t>(rec.num_joints())) w.joint_names = info.joint_names;
  if (o.time_origin_ns > 0)
    w.time_origin_ns = o.time_origin_ns;
  else if (info.time_origin_ns > 0)
    w.time_origin_ns = info.time_origin_ns;  // a bag keeps its clock
  rcm::save_rosbag2_recording(o.out, rec, w);
}

void run(Options o) {
  rcm::TopicReadOptions bag = rcm::cli::get_topic_options();
  bag.read.dedupe = o.dedupe;
  if (!o.joint_names.empty()) {
    bag.joint_names.clear();
    std::size_t start = 0;
    while (true) {
      const std::size_t end = o.joint_names.find(',', start);
      bag.joint_names.push_back(o.joint_names.substr(start, end == std::string::npos ? end : end - start));
      if (end == std::string::npos) break;
      start = end + 1;
    }
    for (const auto& n : bag.joint_names)
      if (n.empty()) throw rcm::InputError(rcm::cli::flag_location("--joint-names"), "empty joint name");
  }
  ReadInfo info;
  Written rec;
  if (is_bag_output(o.out)) {
    // The bag writer takes the whole recording.
    const rcm::Recording whole = read(o, bag, info);
    write_bag(o, bag, info, whole);
    const Eigen::Index n = whole.time.size();
    rec = {n, whole.num_joints(), n > 1 ? whole.time(n - 1) - whole.time(0) : 0.0, whole.repeated_rows,
           whole.repeated_rows_removed, whole.has_force()};
  } else {
    rec = stream_to_csv(o, bag, info);
  }
  const Eigen::Index T = rec.samples;
  const double duration = rec.duration_s;
  if (o.json) {
    nlohmann::json j = {{"input", o.in},
                        {"output", o.out},
                        {"format", info.format},
                        {"topic", bag.topic},
                        {"messages", info.messages},
                        {"zero_stamp_messages", info.zero_stamp_messages},
                        {"samples", T},
                        {"joints", rec.joints},
                        {"joint_names", info.joint_names},
                        {"duration_s", duration},
                        {"time_source", info.time_source},
                        {"time_origin_ns", info.time_origin_ns},
                        {"repeated_samples", rec.repeated},
                        {"repeated_samples_removed", rec.removed},
                        {"force_topic", bag.force_topic.empty() ? nlohmann::json(nullptr) : nlohmann::json(bag.force_topic)},
                        {"force_messages", info.force_messages},
                        {"force_frame_id", info.force_frame_id}};
    rcm::cli::print_json(j);
    return;
  }
  std::string names;
  for (const auto& n : info.joint_names) names += (names.empty() ? "" : ", ") + n;
  std::cout << fmt::format("{} {}: {} samples, {} joints ({}), {:.3f} s\n", o.in, bag.topic, T, rec.joints,
                           names.empty() ? std::string("no names, by position") : names, duration);
  const std::string time = info.time_source == "bag_time"       ? "bag receive time (header stamps are zero)"
                           : info.time_source == "receive_time" ? "receive time (--time receive)"
                           : info.time_source == "time_column"  ? "the recording's time column"
                                                                : "header.stamp";
  std::cout << fmt::format("  time: {} - origin {}.{:09d} s{}\n", time,
                           info.time_origin_ns / 1000000000, info.time_origin_ns % 1000000000,
                           rec.repeated ? fmt::format("; {} repeated samples{}", rec.repeated,
                                                           rec.removed ? " removed" : " kept (--dedupe drops them)")
                                             : std::string());
  if (info.zero_stamp_messages > 0)
    std::cout << fmt::format("  skipped: {} of {} messages with a zero header.stamp (invalid data)\n",
                             info.zero_stamp_messages, info.messages);
  if (!bag.force_topic.empty())
    std::cout << fmt::format("  force: {} ({} messages, frame_id '{}'), interpolated at the joint samples\n",
                             bag.force_topic, info.force_messages, info.force_frame_id);
  if (is_bag_output(o.out))
    std::cout << fmt::format("  written {} (rosbag2, {}: {} JointState messages{})\n", o.out,
                             std::filesystem::path(o.out).extension() == ".db3" ? "SQLite" : "MCAP", T,
                             rec.has_force ? ", and the force" : "");
  else
    std::cout << "  written " << o.out << "\n";
}

const bool registered = rcm::cli::register_command({"convert", 15, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "convert",
      "Convert a bag's sensor_msgs/JointState topic (and a force topic) to an rcm CSV recording, or a recording to "
      "a rosbag2 bag (OUT ending in .mcap or .db3); to CSV in constant memory");
  cmd->add_option("IN", o->in, "input: rosbag2 directory, .db3 or .mcap file, ROS 1 .bag, or (to a bag) a CSV recording")
      ->required();
  cmd->add_option("OUT", o->out,
                  "output: an rcm CSV recording, or a rosbag2 file (.mcap, .db3) with the JointState topic --topic "
                  "and the force's WrenchStamped topic (--force-topic, default /PSM1/body/measured_cf)")
      ->required();
  cmd->add_option("--time-origin-ns", o->time_origin_ns,
                  "to a bag: header.stamp of time 0, ns (a zero stamp is invalid on ROS 2; default: a bag input's own "
                  "origin, else 1700000000 s)")
      ->check(CLI::PositiveNumber);
  rcm::cli::add_topic_options(*cmd);
  cmd->add_option("--joint-names", o->joint_names,
                  "joint order of the output by name, comma separated (default: the first message's order)");
  cmd->add_flag("--dedupe", o->dedupe, "drop samples that repeat the previous one");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_convert
}  // namespace
