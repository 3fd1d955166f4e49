#include "io/rosbag2/sqlite_bag.hpp"

#include <sqlite3.h>

#include <memory>

#include "rcm/common/error.hpp"

namespace rcm::rosbag2 {
namespace {

[[noreturn]] void fail(const std::filesystem::path& path, const std::string& what) {
  InputLocation where;
  where.file = path.string();
  throw InputError(where, what);
}

struct CloseDb {
  void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
};
struct Finalize {
  void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};
using Statement = std::unique_ptr<sqlite3_stmt, Finalize>;

Statement prepare(sqlite3* db, const std::filesystem::path& path, const std::string& sql) {
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) != SQLITE_OK)
    fail(path, std::string("not a readable rosbag2 SQLite file: ") + sqlite3_errmsg(db));
  return Statement(s);
}

bool has_table(sqlite3* db, const std::filesystem::path& path, const char* table) {
  Statement s = prepare(db, path, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?");
  sqlite3_bind_text(s.get(), 1, table, -1, SQLITE_STATIC);
  const int rc = sqlite3_step(s.get());
  if (rc != SQLITE_ROW && rc != SQLITE_DONE) fail(path, std::string("not a readable SQLite file: ") + sqlite3_errmsg(db));
  return rc == SQLITE_ROW;
}

std::string column_text(sqlite3_stmt* s, int i) {
  const unsigned char* t = sqlite3_column_text(s, i);
  return t ? reinterpret_cast<const char*>(t) : std::string();
}

using Database = std::unique_ptr<sqlite3, CloseDb>;

// Opens read-only and checks rosbag2's two tables are there.
Database open_bag(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) fail(path, "no such file");
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr);
  Database db(raw);
  if (rc != SQLITE_OK) fail(path, std::string("cannot open as SQLite: ") + (raw ? sqlite3_errmsg(raw) : "out of memory"));
  for (const char* table : {"topics", "messages"})
    if (!has_table(db.get(), path, table))
      fail(path, std::string("no '") + table + "' table: not a rosbag2 SQLite file");
  return db;
}

}  // namespace

std::vector<SqliteTopicStats> count_sqlite_messages(const std::filesystem::path& path) {
  const Database db = open_bag(path);
  Statement s = prepare(db.get(), path,
                        "SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages GROUP BY topic_id");
  std::vector<SqliteTopicStats> out;
  int step;
  while ((step = sqlite3_step(s.get())) == SQLITE_ROW)
    out.push_back({sqlite3_column_int64(s.get(), 0), static_cast<std::size_t>(sqlite3_column_int64(s.get(), 1)),
                   sqlite3_column_int64(s.get(), 2), sqlite3_column_int64(s.get(), 3)});
  if (step != SQLITE_DONE) fail(path, std::string("counting messages: ") + sqlite3_errmsg(db.get()));
  return out;
}

struct SqliteCursor::Impl {
  std::filesystem::path path;
  Database db;
  Statement messages;
  SqliteBagInfo info;
  std::size_t row = 0;
  bool done = false;
};

SqliteCursor::SqliteCursor(const std::filesystem::path& path, const std::function<bool(const SqliteTopic&)>& wanted)
    : impl_(std::make_unique<Impl>()) {
  Impl& c = *impl_;
  c.path = path;
  c.db = open_bag(path);
  SqliteBagInfo& info = c.info;
  if (has_table(c.db.get(), path, "schema")) {
    Statement s = prepare(c.db.get(), path, "SELECT schema_version, ros_distro FROM schema");
    if (sqlite3_step(s.get()) == SQLITE_ROW) {
      info.schema_version = sqlite3_column_int(s.get(), 0);
      info.ros_distro = column_text(s.get(), 1);
    }
  }
  {
    Statement s = prepare(c.db.get(), path, "SELECT id, name, type, serialization_format FROM topics ORDER BY id");
    int step;
    while ((step = sqlite3_step(s.get())) == SQLITE_ROW) {
      SqliteTopic t;
      t.id = sqlite3_column_int64(s.get(), 0);
      t.name = column_text(s.get(), 1);
      t.type = column_text(s.get(), 2);
      t.serialization_format = column_text(s.get(), 3);
      info.topics.push_back(std::move(t));
    }
    if (step != SQLITE_DONE) fail(path, std::string("topics table: ") + sqlite3_errmsg(c.db.get()));
  }
  std::string ids;
  for (const SqliteTopic& t : info.topics)
    if (wanted(t)) ids += (ids.empty() ? "" : ",") + std::to_string(t.id);
  if (ids.empty()) {
    c.done = true;
    return;
  }
  // Stepped row by row: SQLite reads the pages as it goes (rosbag2's index
  // on timestamp gives the order without a sort of the whole table).
  c.messages = prepare(c.db.get(), path,
                       "SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN (" + ids +
                           ") ORDER BY timestamp, id");
}

SqliteCursor::~SqliteCursor() = default;
SqliteCursor::SqliteCursor(SqliteCursor&&) noexcept = default;
const SqliteBagInfo& SqliteCursor::info() const { return impl_->info; }

bool SqliteCursor::next(SqliteMessage& m) {
  Impl& c = *impl_;
  if (c.done) return false;
  sqlite3_stmt* s = c.messages.get();
  const int step = sqlite3_step(s);
  if (step != SQLITE_ROW) {
    c.done = true;
    if (step != SQLITE_DONE) fail(c.path, std::string("reading messages: ") + sqlite3_errmsg(c.db.get()));
    return false;
  }
  const std::int64_t topic_id = sqlite3_column_int64(s, 0);
  m = SqliteMessage();
  for (const SqliteTopic& t : c.info.topics)
    if (t.id == topic_id) m.topic = &t;
  if (sqlite3_column_type(s, 1) != SQLITE_INTEGER)
    fail(c.path, "messages row " + std::to_string(c.row) + " of topic " + m.topic->name +
                     ": timestamp is not an integer (ns)");
  m.receive_ns = sqlite3_column_int64(s, 1);
  const int type = sqlite3_column_type(s, 2);
  if (type != SQLITE_BLOB && type != SQLITE_NULL)
    fail(c.path, "messages row " + std::to_string(c.row) + " of topic " + m.topic->name + ": data is not a blob");
  m.data = static_cast<const std::uint8_t*>(sqlite3_column_blob(s, 2));
  m.size = static_cast<std::size_t>(sqlite3_column_bytes(s, 2));
  ++c.row;
  return true;
}

SqliteBagInfo read_sqlite_bag(const std::filesystem::path& path, const std::function<bool(const SqliteTopic&)>& wanted,
                              const std::function<void(const SqliteMessage&)>& on_message) {
  SqliteCursor cursor(path, wanted);
  SqliteMessage m;
  while (cursor.next(m)) on_message(m);
  return cursor.info();
}

}  // namespace rcm::rosbag2
