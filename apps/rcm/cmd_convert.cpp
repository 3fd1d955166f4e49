// rcm convert: a bag's joint-state topic (and optionally a force topic) to the
// rcm CSV layout, validated as every recording is (docs/ros.md): a rosbag2
// recording always, a ROS 1 bag when built with ROS. Every command also reads
// bags directly; convert makes a file other tools read.

#include <fmt/format.h>

#include <iostream>
#include <memory>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "message_cli.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/io/rosbag2.hpp"
#if RCM_HAVE_ROS
#include "rcm/ros/bag_reader.hpp"
#endif

namespace {
namespace cmd_convert {

struct Options {
  std::string in, out, joint_names;
  bool dedupe = false, json = false;
};

// What the two readers report, in one shape.
struct ReadInfo {
  std::vector<std::string> joint_names;
  std::int64_t time_origin_ns = 0;
  std::string time_source;  // "header_stamp", "bag_time", "receive_time"
  std::size_t messages = 0, zero_stamp_messages = 0, force_messages = 0;
  std::string force_frame_id, format;
};

// The bag's reader; `info` is filled by get_info() once it has been read.
std::unique_ptr<rcm::MessageRecordingReader> open(const Options& o, const rcm::TopicReadOptions& options) {
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
  throw rcm::InputError(where, "not a bag: convert reads a rosbag2 directory, a .db3 or .mcap file, or a ROS 1 .bag");
}

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
  // Chunk by chunk into the output's temporary: memory does not grow with the bag.
  const auto reader = open(o, bag);
  rcm::RecordingWriter writer(o.out, reader->num_joints(), reader->has_force());
  rcm::Recording chunk;
  double first_time = 0.0, last_time = 0.0;
  while (reader->read_chunk(chunk)) {
    if (writer.samples() == 0) first_time = chunk.time(0);
    last_time = chunk.time(chunk.time.size() - 1);
    writer.write(chunk);
  }
  writer.commit();
  const ReadInfo info = get_info(*reader, bag);
  const auto T = static_cast<Eigen::Index>(writer.samples());
  const double duration = T > 1 ? last_time - first_time : 0.0;
  const std::size_t repeated = reader->repeated_rows();
  const bool removed = reader->repeated_rows_removed();
  if (o.json) {
    nlohmann::json j = {{"input", o.in},
                        {"output", o.out},
                        {"format", info.format},
                        {"topic", bag.topic},
                        {"messages", info.messages},
                        {"zero_stamp_messages", info.zero_stamp_messages},
                        {"samples", T},
                        {"joints", reader->num_joints()},
                        {"joint_names", info.joint_names},
                        {"duration_s", duration},
                        {"time_source", info.time_source},
                        {"time_origin_ns", info.time_origin_ns},
                        {"repeated_samples", repeated},
                        {"repeated_samples_removed", removed},
                        {"force_topic", bag.force_topic.empty() ? nlohmann::json(nullptr) : nlohmann::json(bag.force_topic)},
                        {"force_messages", info.force_messages},
                        {"force_frame_id", info.force_frame_id}};
    rcm::cli::print_json(j);
    return;
  }
  std::string names;
  for (const auto& n : info.joint_names) names += (names.empty() ? "" : ", ") + n;
  std::cout << fmt::format("{} {}: {} samples, {} joints ({}), {:.3f} s\n", o.in, bag.topic, T, reader->num_joints(),
                           names.empty() ? std::string("no names, by position") : names, duration);
  const std::string time = info.time_source == "bag_time"       ? "bag receive time (header stamps are zero)"
                           : info.time_source == "receive_time" ? "receive time (--time receive)"
                                                                : "header.stamp";
  std::cout << fmt::format("  time: {} - origin {}.{:09d} s{}\n", time,
                           info.time_origin_ns / 1000000000, info.time_origin_ns % 1000000000,
                           repeated ? fmt::format("; {} repeated samples{}", repeated,
                                                           removed ? " removed" : " kept (--dedupe drops them)")
                                             : std::string());
  if (info.zero_stamp_messages > 0)
    std::cout << fmt::format("  skipped: {} of {} messages with a zero header.stamp (invalid data)\n",
                             info.zero_stamp_messages, info.messages);
  if (!bag.force_topic.empty())
    std::cout << fmt::format("  force: {} ({} messages, frame_id '{}'), interpolated at the joint samples\n",
                             bag.force_topic, info.force_messages, info.force_frame_id);
  std::cout << "  written " << o.out << "\n";
}

const bool registered = rcm::cli::register_command({"convert", 15, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "convert",
      "Convert a bag's sensor_msgs/JointState topic (and a force topic) to an rcm CSV recording. Streams: the bag is "
      "read and the CSV written a chunk at a time, so memory does not grow with the recording (a ROS 1 bag's index "
      "is held by rosbag_storage)");
  cmd->add_option("BAG", o->in, "input: rosbag2 directory, .db3 or .mcap file, or ROS 1 .bag")->required();
  cmd->add_option("CSV", o->out, "output recording (rcm CSV layout)")->required();
  rcm::cli::add_topic_options(*cmd);
  cmd->add_option("--joint-names", o->joint_names,
                  "joint order of the output by name, comma separated (default: the first message's order)");
  cmd->add_flag("--dedupe", o->dedupe, "drop samples that repeat the previous one");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_convert
}  // namespace
