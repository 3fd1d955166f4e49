// Message recordings in the rcm CLI (docs/formats.md): rosbag2 directories, .db3
// and .mcap files always; ROS 1 .bag files when built with ROS (RCM_HAVE_ROS,
// set by ros/CMakeLists.txt), a clear error otherwise.
// - load_recording() hands such a path to its reader with the options below,
//   so every command that takes a recording accepts one, and so do sessions;
// - the commands that read recordings gain --topic, --force-topic and --time.
// Registered last (order 1000) so that the other commands exist when their
// options are added.

#include <iostream>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "command_registry.hpp"
#include "message_cli.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/rosbag2.hpp"
#if RCM_HAVE_ROS
#include "rcm/ros/bag_reader.hpp"
#endif

namespace rcm::cli {
namespace {

std::mutex& info_mutex() {
  static std::mutex m;
  return m;
}
std::map<std::string, Rosbag2ReadInfo>& infos() {
  static std::map<std::string, Rosbag2ReadInfo> m;
  return m;
}

}  // namespace

TopicReadOptions& get_topic_options() {
  static TopicReadOptions options;  // set by --topic / --force-topic / --time before any command runs
  return options;
}

namespace {
// The --topic and --force-topic options of every command, to tell whether the
// command line named a topic (it then overrides a session's).
std::vector<CLI::Option*>& topic_flags() {
  static std::vector<CLI::Option*> v;
  return v;
}
std::vector<CLI::Option*>& force_topic_flags() {
  static std::vector<CLI::Option*> v;
  return v;
}
bool any_given(const std::vector<CLI::Option*>& options) {
  for (const CLI::Option* o : options)
    if (o->count() > 0) return true;
  return false;
}
}  // namespace

TopicReadOptions get_topic_options(const RecordingReadOptions& read) {
  return with_session_topics(get_topic_options(), read, any_given(topic_flags()), any_given(force_topic_flags()));
}

void add_topic_options(CLI::App& cmd) {
  if (cmd.get_option_no_throw("--topic") != nullptr) return;
  topic_flags().push_back(cmd.add_option("--topic", get_topic_options().topic,
                                         "bags (.bag, rosbag2 directory, .db3, .mcap): the sensor_msgs/JointState "
                                         "topic (default /PSM1/measured_js, or the session's \"topics\")")
                               ->group("Bags"));
  force_topic_flags().push_back(
      cmd.add_option("--force-topic", get_topic_options().force_topic,
                     "bags: a geometry_msgs/WrenchStamped topic read as the force columns (evaluation only, base "
                     "frame; default: the session's \"topics\", else none)")
          ->group("Bags"));
  cmd.add_option("--time", get_topic_options().time,
                 "bags: 'header' (header.stamp; rosbag2 messages with a zero stamp are invalid data, skipped and "
                 "counted) or 'receive' (the recorder's receive time)")
      ->transform(CLI::CheckedTransformer(
          std::map<std::string, MessageTime>{{"header", MessageTime::header}, {"receive", MessageTime::receive}}))
      ->group("Bags");
}

std::unique_ptr<Rosbag2RecordingReader> open_rosbag2(const std::filesystem::path& path,
                                                     const TopicReadOptions& options, std::size_t chunk_rows) {
  auto reader = open_rosbag2_recording(path, options, chunk_rows);
  reader->set_on_end([key = path.string()](RecordingReader& r) {
    const Rosbag2ReadInfo& info = static_cast<Rosbag2RecordingReader&>(r).info();
    for (const std::string& w : info.warnings) std::cerr << "warning: " << w << "\n";
    if (info.zero_stamp_messages > 0)
      std::cerr << "note: " << key << " " << info.topic << ": " << info.zero_stamp_messages << " of " << info.messages
                << " messages skipped (zero header.stamp: invalid data)\n";
    const std::lock_guard<std::mutex> lock(info_mutex());
    infos()[key] = info;
  });
  return reader;
}

Recording load_rosbag2(const std::filesystem::path& path, const TopicReadOptions& options) {
  const auto reader = open_rosbag2(path, options);
  return read_whole_recording(*reader);
}

const Rosbag2ReadInfo* find_rosbag2_info(const std::string& path) {
  const std::lock_guard<std::mutex> lock(info_mutex());
  const auto it = infos().find(path);
  return it == infos().end() ? nullptr : &it->second;
}

namespace {

void add_options_to_readers(CLI::App& app) {
  // The commands that read recordings (dynamics fit/eval are nested).
  static const char* const readers[] = {"inspect", "force", "monitor", "run", "tissue", "fit", "eval"};
  for (CLI::App* sub : app.get_subcommands({})) {
    add_options_to_readers(*sub);
    for (const char* name : readers)
      if (sub->get_name() == name) add_topic_options(*sub);
  }
}

const bool registered = register_command({"(message recordings)", 1000, [](CLI::App& app) {
  add_options_to_readers(app);
  auto rosbag2_reader = [](const std::filesystem::path& path, const RecordingReadOptions& read,
                           std::size_t chunk_rows) -> std::unique_ptr<RecordingReader> {
    return open_rosbag2(path, get_topic_options(read), chunk_rows);
  };
  for (const char* key : {".db3", ".mcap", "/"}) register_recording_stream(key, rosbag2_reader);
#if RCM_HAVE_ROS
  register_recording_stream(".bag", [](const std::filesystem::path& path, const RecordingReadOptions& read,
                                       std::size_t chunk_rows) -> std::unique_ptr<RecordingReader> {
    return open_bag_recording(path, get_topic_options(read), chunk_rows);
  });
#else
  register_recording_reader(".bag", [](const std::filesystem::path& path, const RecordingReadOptions&) -> Recording {
    InputLocation where;
    where.file = path.string();
    throw InputError(where, "a ROS 1 bag, but this rcm was built without ROS 1 (RCM_WITH_ROS=OFF or the ROS "
                            "packages missing; Debian: libroscpp-dev librosbag-dev libsensor-msgs-dev); convert "
                            "it with `rostopic echo -b FILE.bag -p /PSM1/measured_js > FILE.csv`");
  });
#endif
}});

}  // namespace
}  // namespace rcm::cli
