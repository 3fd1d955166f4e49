// rcm convert: a rosbag's joint-state topic (and optionally a force topic) to
// the rcm CSV layout, validated as every recording is (docs/ros.md). Built
// only with ROS; every command also reads .bag files directly.

#if RCM_HAVE_ROS

#include <fmt/format.h>

#include <iostream>
#include <memory>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/ros/bag_reader.hpp"

namespace {

struct Options {
  std::string in, out, joint_names;
  rcm::BagReadOptions bag;
  bool json = false;
};

void run(Options o) {
  if (!o.joint_names.empty()) {
    o.bag.joint_names.clear();
    std::size_t start = 0;
    while (true) {
      const std::size_t end = o.joint_names.find(',', start);
      o.bag.joint_names.push_back(o.joint_names.substr(start, end == std::string::npos ? end : end - start));
      if (end == std::string::npos) break;
      start = end + 1;
    }
    for (const auto& n : o.bag.joint_names)
      if (n.empty()) throw rcm::InputError(rcm::cli::flag_location("--joint-names"), "empty joint name");
  }
  rcm::BagReadInfo info;
  const rcm::Recording rec = rcm::load_bag_recording(o.in, o.bag, &info);
  rcm::save_recording(o.out, rec);
  const Eigen::Index T = rec.time.size();
  const double duration = T > 1 ? rec.time(T - 1) - rec.time(0) : 0.0;
  if (o.json) {
    nlohmann::json j = {{"input", o.in},
                        {"output", o.out},
                        {"topic", o.bag.topic},
                        {"messages", info.messages},
                        {"samples", T},
                        {"joints", rec.num_joints()},
                        {"joint_names", info.joint_names},
                        {"duration_s", duration},
                        {"time_source", info.bag_time ? "bag_time" : "header_stamp"},
                        {"time_origin_ns", info.time_origin_ns},
                        {"repeated_samples", rec.repeated_rows},
                        {"repeated_samples_removed", rec.repeated_rows_removed},
                        {"force_topic", o.bag.force_topic.empty() ? nlohmann::json(nullptr) : nlohmann::json(o.bag.force_topic)},
                        {"force_messages", info.force_messages},
                        {"force_frame_id", info.force_frame_id}};
    rcm::cli::print_json(j);
    return;
  }
  std::string names;
  for (const auto& n : info.joint_names) names += (names.empty() ? "" : ", ") + n;
  std::cout << fmt::format("{} {}: {} samples, {} joints ({}), {:.3f} s\n", o.in, o.bag.topic, T, rec.num_joints(),
                           names.empty() ? std::string("no names, by position") : names, duration);
  std::cout << fmt::format("  time: {} - origin {}.{:09d} s{}\n",
                           info.bag_time ? "bag receive time (header stamps are zero)" : "header.stamp",
                           info.time_origin_ns / 1000000000, info.time_origin_ns % 1000000000,
                           rec.repeated_rows ? fmt::format("; {} repeated samples{}", rec.repeated_rows,
                                                           rec.repeated_rows_removed ? " removed" : " kept (--dedupe drops them)")
                                             : std::string());
  if (!o.bag.force_topic.empty())
    std::cout << fmt::format("  force: {} ({} messages, frame_id '{}'), interpolated at the joint samples\n",
                             o.bag.force_topic, info.force_messages, info.force_frame_id);
  std::cout << "  written " << o.out << "\n";
}

const bool registered = rcm::cli::register_command({"convert", 15, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Convert a rosbag's sensor_msgs/JointState topic (and a force topic) to an rcm CSV recording");
  cmd->add_option("BAG", o->in, "input rosbag")->required();
  cmd->add_option("CSV", o->out, "output recording (rcm CSV layout)")->required();
  cmd->add_option("--topic", o->bag.topic, "sensor_msgs/JointState topic (default /PSM1/measured_js)");
  cmd->add_option("--force-topic", o->bag.force_topic,
                  "geometry_msgs/WrenchStamped topic written as force_x,y,z (base frame; evaluation only)");
  cmd->add_option("--joint-names", o->joint_names,
                  "joint order of the output by name, comma separated (default: the first message's order)");
  cmd->add_flag("--dedupe", o->bag.read.dedupe, "drop samples that repeat the previous one");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o] { run(*o); });
}});

}  // namespace

#endif  // RCM_HAVE_ROS
