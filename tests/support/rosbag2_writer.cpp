#include "support/rosbag2_writer.hpp"

#include <lz4frame.h>
#include <sqlite3.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <map>
#include <memory>
#include <stdexcept>
#include <utility>

#include "io/rosbag2/cdr.hpp"

namespace rcm::test {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

constexpr const char* kJointStateType = "sensor_msgs/msg/JointState";
constexpr const char* kWrenchType = "geometry_msgs/msg/WrenchStamped";
constexpr const char* kForceFrame = "PSM1_base";

// The definitions rosbag2 stores with a topic (MCAP Schema data, SQLite
// message_definitions): the type's .msg text followed by its dependencies.
constexpr const char* kJointStateMsg = R"(std_msgs/Header header

string[] name
float64[] position
float64[] velocity
float64[] effort

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
)";

constexpr const char* kWrenchStampedMsg = R"(std_msgs/Header header
Wrench wrench

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec

================================================================================
MSG: geometry_msgs/Wrench
Vector3  force
Vector3  torque

================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
)";

std::string message_definition(const std::string& type) {
  if (type == kJointStateType) return kJointStateMsg;
  if (type == kWrenchType) return kWrenchStampedMsg;
  return "";
}

// ---------------------------------------------------------------------------
// SQLite storage

class Db3File {
 public:
  Db3File(const fs::path& path, int schema, bool qos) : path_(path), schema_(schema), qos_(qos || schema >= 3) {
    if (schema != 0 && schema != 3 && schema != 4)
      throw std::invalid_argument("rosbag2 SQLite schema " + std::to_string(schema) + ": 0, 3 or 4 are written");
    std::error_code ec;
    fs::remove(path, ec);
    fs::remove(path.string() + "-journal", ec);
    sqlite3* raw = nullptr;
    const int rc = sqlite3_open(path.c_str(), &raw);
    db_.reset(raw);
    if (rc != SQLITE_OK) fail("open");
    // As rosbag2 writes by default, and one transaction: per-row commits would
    // make a benchmark's million rows take minutes.
    exec("PRAGMA journal_mode = MEMORY; PRAGMA synchronous = OFF;");
    if (schema >= 3) {
      exec("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);");
      exec("INSERT INTO schema VALUES (" + std::to_string(schema) + ", '" + (schema == 3 ? "humble" : "jazzy") + "');");
      exec("CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);");
    }
    std::string cols =
        "id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT NOT NULL";
    if (qos_) cols += ", offered_qos_profiles TEXT NOT NULL";
    if (schema >= 4) cols += ", type_description_hash TEXT NOT NULL";
    exec("CREATE TABLE topics(" + cols + ");");
    if (schema >= 4)
      exec("CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, encoding TEXT NOT "
           "NULL, encoded_message_definition TEXT NOT NULL, type_description_hash TEXT NOT NULL);");
    exec("CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data "
         "BLOB NOT NULL);");
    exec("CREATE INDEX timestamp_idx ON messages (timestamp ASC);");
    exec("BEGIN;");
    insert_ = prepare("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)");
  }

  void add_topic(int id, const BagTopic& t) {
    std::string sql = "INSERT INTO topics VALUES (?, ?, ?, ?";
    if (qos_) sql += ", ''";
    if (schema_ >= 4) sql += ", ''";
    Statement s = prepare(sql + ")");
    sqlite3_bind_int(s.get(), 1, id);
    bind_text(s.get(), 2, t.name);
    bind_text(s.get(), 3, t.type);
    bind_text(s.get(), 4, t.format);
    step_done(s.get(), "insert topic");
    if (schema_ >= 4) {
      Statement d = prepare(
          "INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition, type_description_hash) "
          "VALUES (?, 'ros2msg', ?, '')");
      bind_text(d.get(), 1, t.type);
      bind_text(d.get(), 2, message_definition(t.type));
      step_done(d.get(), "insert message definition");
    }
  }

  void add_message(int topic_id, std::int64_t receive_ns, const std::uint8_t* data, std::size_t size) {
    sqlite3_stmt* s = insert_.get();
    sqlite3_bind_int(s, 1, topic_id);
    sqlite3_bind_int64(s, 2, receive_ns);
    sqlite3_bind_blob64(s, 3, size ? data : reinterpret_cast<const std::uint8_t*>(""), size, SQLITE_STATIC);
    step_done(s, "insert message");
    sqlite3_reset(s);
  }

  void finish() {
    insert_.reset();
    exec("COMMIT;");
    if (sqlite3_close(db_.release()) != SQLITE_OK)
      throw std::runtime_error(path_.string() + ": cannot close the database");
  }

 private:
  struct CloseDb {
    void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
  };
  struct Finalize {
    void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
  };
  using Statement = std::unique_ptr<sqlite3_stmt, Finalize>;

  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(path_.string() + ": " + what + ": " + (db_ ? sqlite3_errmsg(db_.get()) : "out of memory"));
  }
  void exec(const std::string& sql) {
    char* err = nullptr;
    if (sqlite3_exec(db_.get(), sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string what = err ? err : "error";
      sqlite3_free(err);
      throw std::runtime_error(path_.string() + ": " + what + " in: " + sql);
    }
  }
  Statement prepare(const std::string& sql) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db_.get(), sql.c_str(), -1, &s, nullptr) != SQLITE_OK) fail("prepare " + sql);
    return Statement(s);
  }
  static void bind_text(sqlite3_stmt* s, int i, const std::string& v) {
    sqlite3_bind_text(s, i, v.c_str(), static_cast<int>(v.size()), SQLITE_TRANSIENT);
  }
  void step_done(sqlite3_stmt* s, const char* what) {
    if (sqlite3_step(s) != SQLITE_DONE) fail(what);
  }

  fs::path path_;
  int schema_;
  bool qos_;
  std::unique_ptr<sqlite3, CloseDb> db_;
  Statement insert_;
};

// ---------------------------------------------------------------------------
// MCAP storage (mcap.dev/spec, version 0)

constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

// clang-format off
enum Op : std::uint8_t {
  kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04, kMessage = 0x05, kChunk = 0x06,
  kMessageIndex = 0x07, kChunkIndex = 0x08, kStatistics = 0x0B, kSummaryOffset = 0x0E, kDataEnd = 0x0F
};
// clang-format on

// CRC-32 of zlib (reflected 0xEDB88320), written here rather than shared with
// the reader so that a mistake in one cannot hide in the other.
class Crc32 {
 public:
  void update(const std::uint8_t* p, std::size_t n) {
    static const auto table = [] {
      std::array<std::uint32_t, 256> t{};
      for (std::uint32_t i = 0; i < 256; ++i) {
        std::uint32_t v = i;
        for (int k = 0; k < 8; ++k) v = (v & 1u) ? (v >> 1) ^ 0xEDB88320u : v >> 1;
        t[i] = v;
      }
      return t;
    }();
    std::uint32_t c = c_;
    for (std::size_t i = 0; i < n; ++i) c = table[(c ^ p[i]) & 0xffu] ^ (c >> 8);
    c_ = c;
  }
  std::uint32_t value() const { return ~c_; }

 private:
  std::uint32_t c_ = 0xffffffffu;
};

std::uint32_t crc32_of(const Bytes& b) {
  Crc32 c;
  c.update(b.data(), b.size());
  return c.value();
}

void put(Bytes& b, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void put_string(Bytes& b, const std::string& s) {
  put(b, s.size(), 4);
  b.insert(b.end(), s.begin(), s.end());
}
void put_record(Bytes& out, std::uint8_t op, const Bytes& body) {
  out.push_back(op);
  put(out, body.size(), 8);
  out.insert(out.end(), body.begin(), body.end());
}

Bytes compress(const std::string& compression, const Bytes& in) {
  Bytes out;
  if (compression == "zstd") {
    out.resize(ZSTD_compressBound(in.size()));
    const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 3);
    if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    out.resize(n);
  } else if (compression == "lz4") {
    // The LZ4 frame format (not the raw block format): MCAP's "lz4".
    LZ4F_preferences_t prefs{};
    prefs.frameInfo.contentSize = in.size();
    out.resize(LZ4F_compressFrameBound(in.size(), &prefs));
    const std::size_t n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
    if (LZ4F_isError(n)) throw std::runtime_error(std::string("lz4 compression failed: ") + LZ4F_getErrorName(n));
    out.resize(n);
  } else {
    out = in;
  }
  return out;
}

class McapFile {
 public:
  McapFile(const fs::path& path, const Rosbag2WriteOptions& o)
      : path_(path),
        compression_(o.mcap_chunked ? o.mcap_compression : ""),
        chunked_(o.mcap_chunked),
        chunk_bytes_(o.mcap_chunk_bytes),
        summary_(o.mcap_summary),
        message_indexes_(o.mcap_message_indexes) {
    out_.open(path, std::ios::binary | std::ios::trunc);
    if (!out_) throw std::runtime_error(path.string() + ": cannot create the file");
    emit(kMagic, sizeof kMagic);
    Bytes header, body;
    put_string(body, "ros2");
    put_string(body, "rcm test support (rosbag2_writer)");
    put_record(header, kHeader, body);
    emit(header);
  }

  // Channel ids count from 1 in the order of registration; one schema per type.
  std::uint16_t add_channel(const std::string& topic, const std::string& type) {
    std::uint16_t schema_id = 0;
    for (const Schema& s : schemas_)
      if (s.name == type) schema_id = s.id;
    if (schema_id == 0) {
      schema_id = static_cast<std::uint16_t>(schemas_.size() + 1);
      schemas_.push_back({schema_id, type, message_definition(type)});
    }
    const auto id = static_cast<std::uint16_t>(channels_.size() + 1);
    channels_.push_back({id, schema_id, topic, 0});
    return id;
  }

  void add_message(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                   std::uint64_t publish_time, const Bytes& data) {
    Channel& c = channels_.at(channel_id - 1);
    Bytes& out = chunked_ ? chunk_ : direct_;
    if (!chunked_) direct_.clear();
    // Every chunk declares what its messages use, so that a chunk reads on its
    // own (as the reference writers do); outside chunks, once per file.
    std::vector<bool>& declared = chunked_ ? chunk_declared_ : file_declared_;
    declared.resize(channels_.size() + 1);
    std::vector<bool>& schema_declared = chunked_ ? chunk_schema_declared_ : file_schema_declared_;
    schema_declared.resize(schemas_.size() + 1);
    if (!declared[channel_id]) {
      if (!schema_declared[c.schema_id]) {
        put_record(out, kSchema, schema_body(schemas_[c.schema_id - 1]));
        schema_declared[c.schema_id] = true;
      }
      put_record(out, kChannel, channel_body(c));
      declared[channel_id] = true;
    }
    const std::uint64_t offset = out.size();
    out.push_back(kMessage);
    put(out, 2 + 4 + 8 + 8 + data.size(), 8);
    put(out, channel_id, 2);
    put(out, sequence, 4);
    put(out, log_time, 8);
    put(out, publish_time, 8);
    out.insert(out.end(), data.begin(), data.end());

    ++c.messages;
    ++messages_;
    start_time_ = std::min(start_time_, log_time);
    end_time_ = std::max(end_time_, log_time);
    if (!chunked_) {
      emit(out);
      return;
    }
    chunk_start_ = std::min(chunk_start_, log_time);
    chunk_end_ = std::max(chunk_end_, log_time);
    chunk_index_[channel_id].push_back({log_time, offset});
    if (chunk_.size() >= chunk_bytes_) flush_chunk();
  }

  void finish() {
    if (chunked_ && !chunk_.empty()) flush_chunk();
    // DataEnd: CRC of every byte before it, leading magic included.
    Bytes data_end, body;
    put(body, crc_.value(), 4);
    put_record(data_end, kDataEnd, body);
    emit(data_end);

    // The summary CRC covers the summary and summary offset sections and the
    // Footer up to its summary_crc field.
    crc_ = Crc32{};
    std::uint64_t summary_start = 0, summary_offset_start = 0;
    if (summary_) {
      summary_start = pos_;
      struct Group {
        std::uint8_t op;
        std::uint64_t start, length;
      };
      std::vector<Group> groups;
      auto group = [&](std::uint8_t op, const std::vector<Bytes>& bodies) {
        if (bodies.empty()) return;
        const std::uint64_t start = pos_;
        Bytes records;
        for (const Bytes& b : bodies) put_record(records, op, b);
        emit(records);
        groups.push_back({op, start, pos_ - start});
      };
      std::vector<Bytes> bodies;
      for (const Schema& s : schemas_) bodies.push_back(schema_body(s));
      group(kSchema, bodies);
      bodies.clear();
      for (const Channel& c : channels_) bodies.push_back(channel_body(c));
      group(kChannel, bodies);
      group(kStatistics, {statistics_body()});
      group(kChunkIndex, chunk_indexes_);
      summary_offset_start = pos_;
      Bytes offsets;
      for (const Group& g : groups) {
        Bytes b;
        b.push_back(g.op);
        put(b, g.start, 8);
        put(b, g.length, 8);
        put_record(offsets, kSummaryOffset, b);
      }
      emit(offsets);
    }
    Bytes footer;
    footer.push_back(kFooter);
    put(footer, 8 + 8 + 4, 8);
    put(footer, summary_start, 8);
    put(footer, summary_offset_start, 8);
    emit(footer);
    Bytes tail;
    put(tail, crc_.value(), 4);
    tail.insert(tail.end(), kMagic, kMagic + sizeof kMagic);
    emit(tail);
    out_.close();
    if (!out_) throw std::runtime_error(path_.string() + ": write failed");
  }

 private:
  struct Schema {
    std::uint16_t id;
    std::string name, data;
  };
  struct Channel {
    std::uint16_t id, schema_id;
    std::string topic;
    std::uint64_t messages;
  };

  static Bytes schema_body(const Schema& s) {
    Bytes b;
    put(b, s.id, 2);
    put_string(b, s.name);
    put_string(b, "ros2msg");
    put_string(b, s.data);  // uint32-length-prefixed bytes, like a string
    return b;
  }
  static Bytes channel_body(const Channel& c) {
    Bytes b, metadata;
    put(b, c.id, 2);
    put(b, c.schema_id, 2);
    put_string(b, c.topic);
    put_string(b, "cdr");
    put_string(metadata, "offered_qos_profiles");
    put_string(metadata, "");
    put(b, metadata.size(), 4);
    b.insert(b.end(), metadata.begin(), metadata.end());
    return b;
  }
  Bytes statistics_body() const {
    Bytes b, counts;
    put(b, messages_, 8);
    put(b, schemas_.size(), 2);
    put(b, channels_.size(), 4);
    put(b, 0, 4);  // attachments
    put(b, 0, 4);  // metadata
    put(b, chunk_indexes_.size(), 4);
    put(b, messages_ ? start_time_ : 0, 8);
    put(b, messages_ ? end_time_ : 0, 8);
    for (const Channel& c : channels_) {
      put(counts, c.id, 2);
      put(counts, c.messages, 8);
    }
    put(b, counts.size(), 4);
    b.insert(b.end(), counts.begin(), counts.end());
    return b;
  }

  void emit(const std::uint8_t* p, std::size_t n) {
    out_.write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(n));
    crc_.update(p, n);
    pos_ += n;
  }
  void emit(const Bytes& b) { emit(b.data(), b.size()); }

  void flush_chunk() {
    const Bytes packed = compress(compression_, chunk_);
    const std::uint64_t chunk_start = pos_;
    Bytes head;
    head.push_back(kChunk);
    put(head, 8 + 8 + 8 + 4 + 4 + compression_.size() + 8 + packed.size(), 8);
    put(head, chunk_start_, 8);
    put(head, chunk_end_, 8);
    put(head, chunk_.size(), 8);
    put(head, crc32_of(chunk_), 4);
    put_string(head, compression_);
    put(head, packed.size(), 8);
    emit(head);
    emit(packed);
    const std::uint64_t chunk_length = pos_ - chunk_start;

    Bytes offsets;  // message_index_offsets: channel id -> file offset of its MessageIndex
    const std::uint64_t index_start = pos_;
    if (message_indexes_) {
      for (const auto& [channel, entries] : chunk_index_) {
        put(offsets, channel, 2);
        put(offsets, pos_, 8);
        Bytes body, record;
        put(body, channel, 2);
        put(body, entries.size() * 16, 4);
        for (const auto& [log_time, offset] : entries) {
          put(body, log_time, 8);
          put(body, offset, 8);
        }
        put_record(record, kMessageIndex, body);
        emit(record);
      }
    }
    Bytes index;
    put(index, chunk_start_, 8);
    put(index, chunk_end_, 8);
    put(index, chunk_start, 8);
    put(index, chunk_length, 8);
    put(index, offsets.size(), 4);
    index.insert(index.end(), offsets.begin(), offsets.end());
    put(index, pos_ - index_start, 8);
    put_string(index, compression_);
    put(index, packed.size(), 8);
    put(index, chunk_.size(), 8);
    chunk_indexes_.push_back(std::move(index));

    chunk_.clear();
    chunk_index_.clear();
    chunk_declared_.assign(chunk_declared_.size(), false);
    chunk_schema_declared_.assign(chunk_schema_declared_.size(), false);
    chunk_start_ = UINT64_MAX;
    chunk_end_ = 0;
  }

  fs::path path_;
  std::string compression_;
  bool chunked_;
  std::size_t chunk_bytes_;
  bool summary_, message_indexes_;
  std::ofstream out_;
  std::uint64_t pos_ = 0;
  Crc32 crc_;  // of the data section, then of the summary
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::uint64_t messages_ = 0, start_time_ = UINT64_MAX, end_time_ = 0;
  std::vector<bool> file_declared_, file_schema_declared_;
  Bytes direct_;  // one record outside chunks
  // The open chunk: its records, times, and (log_time, offset) per channel.
  Bytes chunk_;
  std::vector<bool> chunk_declared_, chunk_schema_declared_;
  std::uint64_t chunk_start_ = UINT64_MAX, chunk_end_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::vector<Bytes> chunk_indexes_;  // ChunkIndex bodies for the summary
};

// ---------------------------------------------------------------------------
// Recordings as messages

bool has_extension(const fs::path& p, const char* ext) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return e == ext;
}

struct FileStats {
  std::string name;
  std::int64_t first_ns = 0, last_ns = 0;  // receive times
  std::size_t messages = 0;
};

// Calls emit(topic 0 joint / 1 force, sample k, receive_ns, stamp_ns, cdr) for
// samples [begin, end) in receive-time order.
template <class Emit>
void for_each_message(const rcm::Recording& rec, const std::vector<std::int64_t>& stamps,
                      const std::vector<std::string>& names, const Rosbag2WriteOptions& o, std::size_t begin,
                      std::size_t end, Emit&& emit) {
  const auto n = static_cast<std::size_t>(rec.num_joints());
  cdr::JointState js;
  js.name = names;
  js.position.resize(n);
  js.velocity.resize(n);
  js.effort.resize(n);
  cdr::WrenchStamped w;
  w.header.frame_id = kForceFrame;
  for (std::size_t k = begin; k < end; ++k) {
    const auto row = static_cast<Eigen::Index>(k);
    const std::int64_t stamp = stamps[k];
    cdr::Header h;
    h.sec = static_cast<std::int32_t>(stamp / 1000000000);
    h.nanosec = static_cast<std::uint32_t>(stamp % 1000000000);
    js.header.sec = w.header.sec = h.sec;
    js.header.nanosec = w.header.nanosec = h.nanosec;
    for (std::size_t j = 0; j < n; ++j) {
      const auto col = static_cast<Eigen::Index>(j);
      js.position[j] = rec.position(row, col);
      js.velocity[j] = rec.velocity(row, col);
      js.effort[j] = rec.effort(row, col);
    }
    const std::int64_t receive = stamp + o.receive_delay_ns;
    emit(0, k, receive, stamp, cdr::encode(js));
    if (rec.has_force()) {
      for (int i = 0; i < 3; ++i) w.force[i] = (*rec.force)(row, i);
      emit(1, k, receive, stamp, cdr::encode(w));
    }
  }
}

FileStats write_storage_file(const fs::path& file, const rcm::Recording& rec, const std::vector<std::int64_t>& stamps,
                             const std::vector<std::string>& names, const Rosbag2WriteOptions& o, std::size_t begin,
                             std::size_t end) {
  FileStats stats;
  stats.name = file.filename().string();
  stats.first_ns = stamps[begin] + o.receive_delay_ns;
  stats.last_ns = stamps[end - 1] + o.receive_delay_ns;
  const bool force = rec.has_force();
  if (o.storage == Rosbag2WriteOptions::Storage::sqlite3) {
    Db3File db(file, o.sqlite_schema, true);
    db.add_topic(1, {o.topic, kJointStateType});
    if (force) db.add_topic(2, {o.force_topic, kWrenchType});
    for_each_message(rec, stamps, names, o, begin, end,
                     [&](int topic, std::size_t, std::int64_t receive, std::int64_t, const Bytes& data) {
                       db.add_message(topic + 1, receive, data.data(), data.size());
                       ++stats.messages;
                     });
    db.finish();
  } else {
    McapFile mcap(file, o);
    std::uint16_t channel[2] = {mcap.add_channel(o.topic, kJointStateType), 0};
    if (force) channel[1] = mcap.add_channel(o.force_topic, kWrenchType);
    for_each_message(rec, stamps, names, o, begin, end,
                     [&](int topic, std::size_t k, std::int64_t receive, std::int64_t stamp, const Bytes& data) {
                       mcap.add_message(channel[topic], static_cast<std::uint32_t>(k),
                                        static_cast<std::uint64_t>(receive), static_cast<std::uint64_t>(stamp), data);
                       ++stats.messages;
                     });
    mcap.finish();
  }
  return stats;
}

// metadata.yaml as `ros2 bag record` writes it, with only the fields that
// rosbag2 requires at `version` (compression 3, qos 4, files 5, custom_data 6,
// type hash 7, ros_distro 8), so that the reader sees what each release wrote.
std::string full_metadata_yaml(const Rosbag2WriteOptions& o, bool force, std::size_t samples,
                               const std::vector<FileStats>& files) {
  const int v = o.metadata_version;
  const std::string storage = o.storage == Rosbag2WriteOptions::Storage::sqlite3 ? "sqlite3" : "mcap";
  const std::int64_t start = files.front().first_ns, duration = files.back().last_ns - files.front().first_ns;
  std::size_t total = 0;
  for (const FileStats& f : files) total += f.messages;
  std::string y = "rosbag2_bagfile_information:\n  version: " + std::to_string(v) +
                  "\n  storage_identifier: " + storage + "\n  duration:\n    nanoseconds: " +
                  std::to_string(duration) + "\n  starting_time:\n    nanoseconds_since_epoch: " +
                  std::to_string(start) + "\n  message_count: " + std::to_string(total) +
                  "\n  topics_with_message_count:\n";
  auto topic = [&](const std::string& name, const char* type) {
    y += "    - topic_metadata:\n        name: " + name + "\n        type: " + type +
         "\n        serialization_format: cdr\n";
    if (v >= 4) y += "        offered_qos_profiles: \"\"\n";
    if (v >= 7) y += "        type_description_hash: \"\"\n";
    y += "      message_count: " + std::to_string(samples) + "\n";
  };
  topic(o.topic, kJointStateType);
  if (force) topic(o.force_topic, kWrenchType);
  if (v >= 3) y += "  compression_format: \"\"\n  compression_mode: \"\"\n";
  y += "  relative_file_paths:\n";
  for (const FileStats& f : files) y += "    - " + f.name + "\n";
  if (v >= 5) {
    y += "  files:\n";
    for (const FileStats& f : files)
      y += "    - path: " + f.name + "\n      starting_time:\n        nanoseconds_since_epoch: " +
           std::to_string(f.first_ns) + "\n      duration:\n        nanoseconds: " +
           std::to_string(f.last_ns - f.first_ns) + "\n      message_count: " + std::to_string(f.messages) + "\n";
  }
  if (v >= 6) y += "  custom_data: ~\n";
  if (v >= 8) y += "  ros_distro: jazzy\n";
  return y;
}

}  // namespace

std::vector<std::string> default_joint_names(int num_joints) {
  static const char* const psm[] = {"outer_yaw",         "outer_pitch",     "outer_insertion", "outer_roll",
                                    "outer_wrist_pitch", "outer_wrist_yaw", "jaw"};
  std::vector<std::string> names;
  for (int j = 0; j < num_joints; ++j) names.push_back(j < 7 ? psm[j] : "joint_" + std::to_string(j + 1));
  return names;
}

void write_rosbag2(const fs::path& path, const rcm::Recording& rec, const Rosbag2WriteOptions& o) {
  validate_recording(rec);
  const bool sqlite = o.storage == Rosbag2WriteOptions::Storage::sqlite3;
  const char* ext = sqlite ? ".db3" : ".mcap";
  const bool bare = has_extension(path, ".db3") || has_extension(path, ".mcap");
  if (bare && !has_extension(path, ext))
    throw std::invalid_argument(path.string() + ": the extension does not match the storage (" + ext + ")");
  if (bare && o.split_every > 0)
    throw std::invalid_argument(path.string() + ": a bare storage file cannot be split; name a directory");
  if (!sqlite && o.mcap_compression != "" && o.mcap_compression != "lz4" && o.mcap_compression != "zstd")
    throw std::invalid_argument("MCAP compression '" + o.mcap_compression + "': \"\", \"lz4\" or \"zstd\"");
  if (!sqlite && o.mcap_chunk_bytes == 0) throw std::invalid_argument("mcap_chunk_bytes must be positive");
  if (!bare && (o.metadata_version < 1 || o.metadata_version > 9))
    throw std::invalid_argument("metadata version " + std::to_string(o.metadata_version) + ": 1 to 9");
  const std::vector<std::string> names =
      o.joint_names.empty() ? default_joint_names(rec.num_joints()) : o.joint_names;
  if (names.size() != static_cast<std::size_t>(rec.num_joints()))
    throw std::invalid_argument(std::to_string(names.size()) + " joint names for " +
                                std::to_string(rec.num_joints()) + " joints");

  const std::size_t samples = rec.num_samples();
  std::vector<std::int64_t> stamps(samples);
  for (std::size_t k = 0; k < samples; ++k) {
    stamps[k] = o.time_origin_ns + std::llround(rec.time[static_cast<Eigen::Index>(k)] * 1e9);
    // builtin_interfaces/Time holds int32 seconds; zero marks invalid data.
    if (stamps[k] <= 0 || stamps[k] / 1000000000 > INT32_MAX)
      throw std::invalid_argument("sample " + std::to_string(k) + ": stamp " + std::to_string(stamps[k]) +
                                  " ns does not fit builtin_interfaces/Time");
    if (k > 0 && stamps[k] <= stamps[k - 1])
      throw std::invalid_argument("sample " + std::to_string(k) +
                                  ": time closer than 1 ns to the previous sample; stamps would not increase");
  }

  if (bare) {
    write_storage_file(path, rec, stamps, names, o, 0, samples);
    return;
  }
  fs::create_directories(path);
  // Leave no storage file of an earlier bag behind: a reader without
  // metadata.yaml would read it too.
  for (const auto& e : fs::directory_iterator(path))
    if (e.path().filename() == "metadata.yaml" || has_extension(e.path(), ".db3") ||
        has_extension(e.path(), ".mcap"))
      fs::remove(e.path());
  std::string stem = path.filename().string();
  if (stem.empty() || stem == ".") stem = path.parent_path().filename().string();
  const std::size_t per_file = o.split_every > 0 ? o.split_every : samples;
  std::vector<FileStats> files;
  for (std::size_t begin = 0, i = 0; begin < samples; begin += per_file, ++i)
    files.push_back(write_storage_file(path / (stem + "_" + std::to_string(i) + ext), rec, stamps, names, o, begin,
                                       std::min(samples, begin + per_file)));
  std::ofstream yaml(path / "metadata.yaml", std::ios::binary | std::ios::trunc);
  yaml << full_metadata_yaml(o, rec.has_force(), samples, files);
  if (!yaml) throw std::runtime_error((path / "metadata.yaml").string() + ": write failed");
}

void write_db3(const fs::path& path, int schema, const std::vector<BagTopic>& topics,
               const std::vector<BagMessage>& messages, bool qos) {
  Db3File db(path, schema, qos);
  for (std::size_t i = 0; i < topics.size(); ++i) db.add_topic(static_cast<int>(i + 1), topics[i]);
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
