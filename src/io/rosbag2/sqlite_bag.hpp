#pragma once
// The messages of a rosbag2 SQLite file (.db3), every schema rosbag2 has
// written: topics(id, name, type, serialization_format[, offered_qos_profiles
// [, type_description_hash]]) and messages(id, topic_id, timestamp, data), the
// schema table from version 3 (Humble), message_definitions from 4 (Jazzy).
// Only what rcm reads is required; the file is opened read-only.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace rcm::rosbag2 {

struct SqliteTopic {
  std::int64_t id = 0;
  std::string name, type, serialization_format;
};

struct SqliteMessage {
  const SqliteTopic* topic = nullptr;
  std::int64_t receive_ns = 0;       // messages.timestamp: the recorder's receive time
  const std::uint8_t* data = nullptr;  // valid only during the callback
  std::size_t size = 0;
};

struct SqliteBagInfo {
  int schema_version = 0;  // 0: no schema table (rosbag2 before Humble)
  std::string ros_distro;
  std::vector<SqliteTopic> topics;  // by id
};

// Reads the topics, then calls `on_message` for every message of a topic that
// `wanted` accepts, in receive-time order (then row order, as rosbag2 reads).
// Throws InputError naming the file for a file that is not SQLite, a database
// without rosbag2's tables, or a corrupt page met while reading.
SqliteBagInfo read_sqlite_bag(const std::filesystem::path& path, const std::function<bool(const SqliteTopic&)>& wanted,
                              const std::function<void(const SqliteMessage&)>& on_message);

// The same, pulled one message at a time (next() false at the end; a
// message's data valid until the next call). info() is known on opening.
class SqliteCursor {
 public:
  SqliteCursor(const std::filesystem::path& path, const std::function<bool(const SqliteTopic&)>& wanted);
  ~SqliteCursor();
  SqliteCursor(SqliteCursor&&) noexcept;
  const SqliteBagInfo& info() const;
  bool next(SqliteMessage& message);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Per topic (by id): message count and first and last receive time, in one
// pass over the messages table.
struct SqliteTopicStats {
  std::int64_t topic_id = 0;
  std::size_t messages = 0;
  std::int64_t first_ns = 0, last_ns = 0;
};
std::vector<SqliteTopicStats> count_sqlite_messages(const std::filesystem::path& path);

}  // namespace rcm::rosbag2
