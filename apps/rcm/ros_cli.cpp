// Rosbag recordings in the rcm CLI (ros/, docs/ros.md). Built with ROS
// (RCM_HAVE_ROS, set by ros/CMakeLists.txt):
// - load_recording() reads files ending in .bag through rcm::load_bag_recording,
//   so every command that takes a recording accepts a bag, and so do sessions
//   whose manifest names .bag files;
// - the commands that read recordings gain --topic and --force-topic.
// Without ROS a .bag gives a clear error instead of a CSV parse error.
// Registered last (order 1000) so that the other commands exist when their
// options are added.

#include <string>

#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/recording.hpp"
#if RCM_HAVE_ROS
#include "rcm/ros/bag_reader.hpp"
#endif

namespace {

#if RCM_HAVE_ROS
rcm::BagReadOptions& cli_bag_options() {
  static rcm::BagReadOptions options;  // set by --topic / --force-topic before any command runs
  return options;
}

void add_bag_options(CLI::App& app) {
  // The commands that read recordings (dynamics fit/eval are nested).
  static const char* const readers[] = {"inspect", "force", "monitor", "run", "tissue", "fit", "eval"};
  for (CLI::App* sub : app.get_subcommands({})) {
    add_bag_options(*sub);
    bool reads = false;
    for (const char* name : readers) reads = reads || sub->get_name() == name;
    if (!reads || sub->get_option_no_throw("--topic") != nullptr) continue;
    sub->add_option("--topic", cli_bag_options().topic,
                    "rosbag recordings (.bag): the sensor_msgs/JointState topic (default /PSM1/measured_js)")
        ->group("Rosbag");
    sub->add_option("--force-topic", cli_bag_options().force_topic,
                    "rosbag recordings: a geometry_msgs/WrenchStamped topic read as the force columns "
                    "(evaluation only, base frame)")
        ->group("Rosbag");
  }
}
#endif

const bool registered = rcm::cli::register_command({"(rosbag recordings)", 1000, [](CLI::App& app) {
#if RCM_HAVE_ROS
  add_bag_options(app);
  rcm::register_recording_reader(".bag", [](const std::filesystem::path& path, const rcm::RecordingReadOptions& read) {
    rcm::BagReadOptions options = cli_bag_options();
    options.read = read;
    return rcm::load_bag_recording(path, options);
  });
#else
  (void)app;
  rcm::register_recording_reader(".bag", [](const std::filesystem::path& path, const rcm::RecordingReadOptions&)
                                             -> rcm::Recording {
    rcm::InputLocation where;
    where.file = path.string();
    throw rcm::InputError(where, "a rosbag, but this rcm was built without ROS 1 (RCM_WITH_ROS=OFF or the ROS "
                                 "packages missing; Debian: libroscpp-dev librosbag-dev libsensor-msgs-dev); convert "
                                 "it with `rostopic echo -b FILE.bag -p /PSM1/measured_js > FILE.csv`");
  });
#endif
}});

}  // namespace
