#pragma once
// Internal to io (the bag writer; the tests write defects with it): a rosbag2
// SQLite storage file (.db3) in each schema rosbag2 has written (0: before
// Humble, 3: Humble, 4: Jazzy), filled topic by topic and message by message
// in one transaction.

#include <sqlite3.h>

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "io/rosbag2/message_definitions.hpp"

namespace rcm::rosbag2::detail {

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

}  // namespace rcm::rosbag2::detail
