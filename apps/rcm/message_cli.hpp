#pragma once
// The options and readers of message recordings (ROS 1 bags, rosbag2) in the
// CLI: one set of --topic / --force-topic / --time flags for every command.

#include <CLI/CLI.hpp>

#include <filesystem>
#include <memory>
#include <string>

#include "rcm/io/message_recording.hpp"
#include "rcm/io/rosbag2.hpp"

namespace rcm::cli {

// The options the flags set (one instance: a command line has one set of flags).
TopicReadOptions& get_topic_options();
// The options for one recording read with `read`: the session's topics in
// `read` apply unless the command line named others.
TopicReadOptions get_topic_options(const RecordingReadOptions& read);
// Adds --topic, --force-topic and --time to `cmd` (once).
void add_topic_options(CLI::App& cmd);
// A rosbag2 recording with `options`, in chunks; once it has been read to its
// end, its warnings and skipped-message count go to stderr and its read info
// is kept for find_rosbag2_info(). load_rosbag2: every chunk.
std::unique_ptr<Rosbag2RecordingReader> open_rosbag2(const std::filesystem::path& path,
                                                     const TopicReadOptions& options,
                                                     std::size_t chunk_rows = kDefaultChunkRows);
Recording load_rosbag2(const std::filesystem::path& path, const TopicReadOptions& options);
// The read info of a rosbag2 recording loaded in this run (by path as given), or null.
const Rosbag2ReadInfo* find_rosbag2_info(const std::string& path);

}  // namespace rcm::cli
