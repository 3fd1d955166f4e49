// The tests' bags: rcm's writer over an earlier bag of the same name, and the
// raw layer on the writer's own SQLite file (io/rosbag2/db3_writer.hpp).
#include "support/rosbag2_writer.hpp"

#include <system_error>

#include "io/rosbag2/db3_writer.hpp"

namespace rcm::test {

void write_rosbag2(const std::filesystem::path& path, const rcm::Recording& recording,
                   const Rosbag2WriteOptions& options) {
  std::error_code ec;
  std::filesystem::remove_all(path, ec);
  rcm::save_rosbag2_recording(path, recording, options);
}

void write_db3(const std::filesystem::path& path, int schema, const std::vector<BagTopic>& topics,
               const std::vector<BagMessage>& messages, bool qos) {
  rcm::rosbag2::detail::Db3File db(path, schema, qos);
  for (std::size_t i = 0; i < topics.size(); ++i)
    db.add_topic(static_cast<int>(i + 1), {topics[i].name, topics[i].type, topics[i].format});
  for (const BagMessage& m : messages) db.add_message(m.topic_id, m.receive_ns, m.data.data(), m.data.size());
  db.finish();
}

std::string metadata_yaml(int version, const std::string& storage, const std::vector<std::string>& files) {
  std::string y = "rosbag2_bagfile_information:\n  version: " + std::to_string(version) +
                  "\n  storage_identifier: " + storage + "\n  relative_file_paths:\n";
  for (const auto& f : files) y += "    - " + f + "\n";
  y += "  compression_format: \"\"\n  compression_mode: \"\"\n";
  return y;
}

}  // namespace rcm::test
