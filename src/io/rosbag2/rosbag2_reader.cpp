#include "rcm/io/rosbag2.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <map>
#include <memory>
#include <optional>

#include "io/rosbag2/cdr.hpp"
#include "io/rosbag2/mcap_reader.hpp"
#include "rcm/common/error.hpp"
#include "io/rosbag2/sqlite_bag.hpp"

namespace rcm {
namespace {

constexpr const char* kJointStateType = "sensor_msgs/msg/JointState";
constexpr const char* kWrenchType = "geometry_msgs/msg/WrenchStamped";

InputLocation locate(const std::string& file, const std::string& where) { return InputLocation::plain(file, where); }

std::string lower_extension(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return e;
}

struct BagFiles {
  std::vector<std::filesystem::path> files;
  int metadata_version = 0;
  std::vector<std::string> warnings;
};

// The storage files of a bag directory, in order, from its metadata.yaml.
BagFiles read_metadata(const std::filesystem::path& dir) {
  const std::filesystem::path yaml_path = dir / "metadata.yaml";
  const std::string file = yaml_path.string();
  BagFiles out;
  std::error_code ec;
  if (!std::filesystem::exists(yaml_path, ec)) {
    // A recorder that did not finish leaves no metadata.yaml; its files are still readable.
    std::vector<std::filesystem::path> found;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
      const std::string ext = lower_extension(e.path());
      if (e.is_regular_file() && (ext == ".db3" || ext == ".mcap")) found.push_back(e.path());
    }
    if (found.empty())
      throw InputError(locate(dir.string(), ""),
                       "a directory without metadata.yaml or any .db3/.mcap file: not a rosbag2 recording");
    // Split files are named <bag>_<index>.<ext>: order by that index, not by text.
    auto index_of = [](const std::filesystem::path& p) {
      const std::string stem = p.stem().string();
      const auto u = stem.find_last_of('_');
      try {
        return u == std::string::npos ? 0L : std::stol(stem.substr(u + 1));
      } catch (const std::exception&) {
        return 0L;
      }
    };
    std::sort(found.begin(), found.end(), [&](const auto& a, const auto& b) {
      return index_of(a) != index_of(b) ? index_of(a) < index_of(b) : a < b;
    });
    out.files = found;
    out.warnings.push_back(dir.string() + ": no metadata.yaml (the recorder did not finish?): reading its " +
                           std::to_string(found.size()) + " storage file(s) in split order");
    return out;
  }
  YAML::Node root;
  try {
    root = YAML::LoadFile(file);
  } catch (const YAML::Exception& e) {
    InputLocation where = locate(file, "");
    if (e.mark.line >= 0) where.line = static_cast<std::size_t>(e.mark.line) + 1;
    throw InputError(where, "not valid YAML: " + e.msg);
  }
  try {
    const YAML::Node info = root["rosbag2_bagfile_information"];
    if (!info || !info.IsMap()) throw InputError(locate(file, "rosbag2_bagfile_information"), "missing");
    if (!info["version"]) throw InputError(locate(file, "rosbag2_bagfile_information.version"), "missing");
    out.metadata_version = info["version"].as<int>();
    if (out.metadata_version < 1)
      throw InputError(locate(file, "rosbag2_bagfile_information.version"),
                       std::to_string(out.metadata_version) + " is not a rosbag2 metadata version");
    if (out.metadata_version > 9)
      out.warnings.push_back(file + ": metadata version " + std::to_string(out.metadata_version) +
                             " is newer than rcm knows (9); its files are read as version 9's");
    for (const char* key : {"compression_format", "compression_mode"}) {
      const YAML::Node c = info[key];
      if (c && c.IsScalar() && !c.as<std::string>().empty() && c.as<std::string>() != "NONE")
        throw InputError(locate(file, std::string("rosbag2_bagfile_information.") + key),
                         "'" + c.as<std::string>() +
                             "': compressed bags are not read; write an uncompressed copy first (ros2 bag convert)");
    }
    const YAML::Node paths = info["relative_file_paths"];
    if (!paths || !paths.IsSequence() || paths.size() == 0)
      throw InputError(locate(file, "rosbag2_bagfile_information.relative_file_paths"),
                       "missing or empty: the bag names no storage file");
    for (std::size_t i = 0; i < paths.size(); ++i) {
      const std::filesystem::path rel = paths[i].as<std::string>();
      // Early rosbag2 wrote paths relative to the bag's parent directory.
      std::filesystem::path p = dir / rel;
      if (!std::filesystem::exists(p, ec) && std::filesystem::exists(dir / rel.filename(), ec)) p = dir / rel.filename();
      if (!std::filesystem::exists(p, ec))
        throw InputError(locate(file, "rosbag2_bagfile_information.relative_file_paths[" + std::to_string(i) + "]"),
                         "'" + rel.string() + "': no such file in " + dir.string());
      out.files.push_back(p);
    }
  } catch (const YAML::Exception& e) {
    InputLocation where = locate(file, "rosbag2_bagfile_information");
    if (e.mark.line >= 0) where.line = static_cast<std::size_t>(e.mark.line) + 1;
    throw InputError(where, "unexpected value: " + e.msg);
  }
  return out;
}

// One message of a wanted topic, whatever the storage.
struct RawMessage {
  const std::string* topic;
  const std::string* type;
  const std::string* encoding;
  std::int64_t receive_ns;
  const std::uint8_t* data;
  std::size_t size;
};

struct TopicSeen {
  std::string type, encoding;
};

// The messages of the wanted topics in every file of a bag, in order, one
// at a time; records every topic met (for "no such topic" errors).
class BagCursor {
 public:
  BagCursor(std::vector<std::filesystem::path> files, std::vector<std::string> topics, Rosbag2ReadInfo& info)
      : files_(std::move(files)), topics_(std::move(topics)), info_(info) {}

  // The next message (its pointers valid until the next call); false after the last file.
  bool next(RawMessage& raw) {
    while (true) {
      if (sqlite_) {
        rosbag2::SqliteMessage m;
        if (sqlite_->next(m)) {
          raw = {&m.topic->name, &m.topic->type, &m.topic->serialization_format, m.receive_ns, m.data, m.size};
          return true;
        }
        sqlite_.reset();
        info_.files.push_back(files_[file_ - 1].string());
      } else if (mcap_) {
        mcap::MessageRef m;
        if (mcap_->next(m)) {
          raw = {&m.channel->topic, &m.channel->schema_name, &m.channel->message_encoding,
                 static_cast<std::int64_t>(m.log_time_ns), m.data, m.size};
          return true;
        }
        const mcap::ReadResult& r = mcap_->result();
        if (r.truncated) info_.warnings.push_back(files_[file_ - 1].string() + ": " + r.truncation);
        mcap_.reset();
        info_.files.push_back(files_[file_ - 1].string());
      }
      if (file_ == files_.size()) return false;
      open(files_[file_++]);
    }
  }
  // The file of the last message.
  const std::filesystem::path& file() const { return files_[file_ - 1]; }
  const std::map<std::string, TopicSeen>& seen() const { return seen_; }

 private:
  bool is_wanted(const std::string& name) const {
    return std::find(topics_.begin(), topics_.end(), name) != topics_.end();
  }
  void open(const std::filesystem::path& path) {
    const std::string ext = lower_extension(path);
    if (ext == ".db3") {
      info_.storage = "sqlite3";
      sqlite_ = std::make_unique<rosbag2::SqliteCursor>(path, [&](const rosbag2::SqliteTopic& t) {
        seen_[t.name] = {t.type, t.serialization_format};
        return is_wanted(t.name);
      });
      info_.sqlite_schema = sqlite_->info().schema_version;
      if (!sqlite_->info().ros_distro.empty()) info_.ros_distro = sqlite_->info().ros_distro;
    } else if (ext == ".mcap") {
      info_.storage = "mcap";
      mcap_ = std::make_unique<mcap::Cursor>(path, [this](const mcap::Channel& c) {
        seen_[c.topic] = {c.schema_name, c.message_encoding};
        return is_wanted(c.topic);
      });
    } else {
      throw InputError(locate(path.string(), ""),
                       "storage file of unknown kind (" + (ext.empty() ? std::string("no extension") : ext) +
                           "); rosbag2 storage is .db3 (sqlite3) or .mcap");
    }
  }

  std::vector<std::filesystem::path> files_;
  std::vector<std::string> topics_;
  Rosbag2ReadInfo& info_;
  std::size_t file_ = 0;
  std::map<std::string, TopicSeen> seen_;
  std::unique_ptr<rosbag2::SqliteCursor> sqlite_;
  std::unique_ptr<mcap::Cursor> mcap_;
};

std::string list_topics(const std::map<std::string, TopicSeen>& seen) {
  if (seen.empty()) return "the recording has no topics";
  std::string s = "the recording has: ";
  bool first = true;
  for (const auto& [name, t] : seen) {
    s += (first ? "" : ", ") + name + " (" + t.type + ")";
    first = false;
  }
  return s;
}

void check_topic(const std::string& file, const std::map<std::string, TopicSeen>& seen, const std::string& topic,
                 const char* type, const char* what) {
  const auto it = seen.find(topic);
  if (it == seen.end())
    throw InputError(locate(file, topic), std::string("no such ") + what + " topic; " + list_topics(seen));
  if (it->second.type != type)
    throw InputError(locate(file, topic), "has type " + it->second.type + ", expected " + type);
  if (it->second.encoding != "cdr")
    throw InputError(locate(file, topic), "serialization format '" + it->second.encoding +
                                              "': only ROS 2's 'cdr' is read");
}

template <class Message>
void decode_or_throw(const std::filesystem::path& file, const std::string& topic, std::size_t k, const RawMessage& raw,
                     Message& out) {
  try {
    cdr::decode(raw.data, raw.size, out);
  } catch (const cdr::DecodeError& e) {
    throw InputError(locate(file.string(), describe_message_place(topic, k, std::nullopt, 0) + ": " + e.field()),
                     std::string("cannot be decoded as ") + (std::is_same_v<Message, cdr::JointState> ? kJointStateType
                                                                                                        : kWrenchType) +
                         " (CDR byte " + std::to_string(e.offset()) + "): " + e.what());
  }
}

}  // namespace

Rosbag2Contents list_rosbag2_contents(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(locate(path.string(), ""), "no such file or directory");
  const BagFiles bag = std::filesystem::is_directory(path, ec) ? read_metadata(path) : BagFiles{{path}, 0, {}};
  Rosbag2Contents out;
  out.metadata_version = bag.metadata_version;
  out.warnings = bag.warnings;
  std::map<std::string, Rosbag2Contents::Topic> topics;
  std::size_t chunks = 0;
  bool summary = true;
  for (const auto& file : bag.files) {
    const std::string ext = lower_extension(file);
    if (ext == ".db3") {
      const rosbag2::SqliteBagInfo db = rosbag2::read_sqlite_bag(
          file, [](const rosbag2::SqliteTopic&) { return false; }, [](const rosbag2::SqliteMessage&) {});
      for (const auto& st : rosbag2::count_sqlite_messages(file))
        for (const auto& t : db.topics)
          if (t.id == st.topic_id) {
            Rosbag2Contents::Topic& x = topics[t.name];
            if (x.messages == 0 || st.first_ns < x.first_ns) x.first_ns = st.first_ns;
            x.last_ns = std::max(x.last_ns, st.last_ns);
            x.messages += st.messages;
          }
      for (const auto& t : db.topics) {
        Rosbag2Contents::Topic& x = topics[t.name];
        x.name = t.name;
        x.type = t.type;
        x.serialization = t.serialization_format;
      }
      out.storage = "sqlite3";
      out.sqlite_schema = db.schema_version;
      if (!db.ros_distro.empty()) out.ros_distro = db.ros_distro;
    } else if (ext == ".mcap") {
      const mcap::ReadResult r = mcap::read_mcap(
          file, [](const mcap::Channel&) { return true; },
          [&](const mcap::MessageRef& m) {
            Rosbag2Contents::Topic& x = topics[m.channel->topic];
            const auto t = static_cast<std::int64_t>(m.log_time_ns);
            if (x.messages == 0 || t < x.first_ns) x.first_ns = t;
            x.last_ns = std::max(x.last_ns, t);
            ++x.messages;
          });
      for (const auto& c : r.channels) {
        Rosbag2Contents::Topic& x = topics[c.topic];
        x.name = c.topic;
        x.type = c.schema_name;
        x.serialization = c.message_encoding;
      }
      out.storage = "mcap";
      chunks += r.chunks;
      summary = summary && r.has_summary;
      if (r.truncated) out.warnings.push_back(file.string() + ": " + r.truncation);
    } else {
      throw InputError(locate(file.string(), ""), "storage file of unknown kind; rosbag2 storage is .db3 or .mcap");
    }
    out.files.push_back(file.string());
  }
  out.layout = out.storage == "mcap" ? "MCAP, " + (chunks ? std::to_string(chunks) + " chunks" : std::string("unchunked")) +
                                           (summary ? ", with summary" : ", no summary")
                                     : "SQLite " + (out.sqlite_schema ? "schema " + std::to_string(out.sqlite_schema)
                                                                      : std::string("(before Humble, no schema table)"));
  for (auto& [name, t] : topics) out.topics.push_back(std::move(t));
  return out;
}

bool is_rosbag2_path(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return true;
  const std::string ext = lower_extension(path);
  return ext == ".db3" || ext == ".mcap";
}

namespace {

// A rosbag2 recording's messages for MessageRecordingReader: decoded, the zero
// stamps of header time skipped and counted, every topic checked once per file.
class Rosbag2Source final : public MessageSource {
 public:
  Rosbag2Source(std::filesystem::path path, std::vector<std::filesystem::path> files, const TopicReadOptions& options,
                Rosbag2ReadInfo& info, bool force_only)
      : path_(std::move(path)),
        files_(files),
        options_(options),
        info_(info),
        force_only_(force_only),
        cursor_(std::move(files), wanted_topics(options, force_only), info) {}

  bool next(RecordingMessage& m) override {
    const bool header_time = options_.time == MessageTime::header;
    RawMessage raw;
    while (cursor_.next(raw)) {
      const std::filesystem::path& file = cursor_.file();
      if (file.native() != checked_file_) {
        // Once per topic and file: every file of a bag declares its topics again.
        checked_file_ = file.native();
        joint_checked_ = force_checked_ = false;
      }
      if (!force_only_ && *raw.topic == options_.topic) {
        if (!joint_checked_) check_topic(file.string(), cursor_.seen(), options_.topic, kJointStateType, "JointState");
        joint_checked_ = true;
        const std::size_t k = info_.messages++;
        decode_or_throw(file, options_.topic, k, raw, js_);
        if (header_time && js_.header.is_zero()) {
          ++info_.zero_stamp_messages;
          continue;
        }
        ++joint_valid_;
        m.topic = RecordingMessage::Topic::joints;
        m.index = k;
        m.t_ns = header_time ? js_.header.get_stamp_ns() : raw.receive_ns;
        m.joints.emplace(view_joint_state(js_));
        return true;
      }
      if (!force_checked_) check_topic(file.string(), cursor_.seen(), options_.force_topic, kWrenchType, "force");
      force_checked_ = true;
      const std::size_t k = info_.force_messages++;
      decode_or_throw(file, options_.force_topic, k, raw, wrench_);
      if (header_time && wrench_.header.is_zero()) {
        ++info_.force_zero_stamp_messages;
        continue;
      }
      if (force_valid_++ == 0) info_.force_frame_id = wrench_.header.frame_id;
      m.topic = RecordingMessage::Topic::force;
      m.index = k;
      m.t_ns = header_time ? wrench_.header.get_stamp_ns() : raw.receive_ns;
      m.force = Eigen::Vector3d(wrench_.force[0], wrench_.force[1], wrench_.force[2]);
      return true;
    }
    return false;
  }

  std::string get_time_label(RecordingMessage::Topic) const override {
    return options_.time == MessageTime::header ? "header.stamp" : "receive time";
  }

  void finish() override {
    const std::string source = path_.string();
    check_topic(source, cursor_.seen(), options_.topic, kJointStateType, "JointState");
    if (joint_valid_ == 0)
      throw InputError(locate(source, options_.topic),
                       std::to_string(info_.messages) +
                           " messages, none valid: every header.stamp is zero (invalid data for the dVRK); "
                           "--time receive uses the recorder's receive time instead");
    if (options_.force_topic.empty()) return;
    check_topic(source, cursor_.seen(), options_.force_topic, kWrenchType, "force");
    if (force_valid_ == 0)
      throw InputError(locate(source, options_.force_topic),
                       std::to_string(info_.force_messages) +
                           " messages, none valid: every header.stamp is zero; --time receive uses the recorder's "
                           "receive time instead");
  }

  std::unique_ptr<MessageSource> reopen_force() const override;

 private:
  static std::vector<std::string> wanted_topics(const TopicReadOptions& options, bool force_only) {
    std::vector<std::string> topics;
    if (!force_only) topics.push_back(options.topic);
    if (!options.force_topic.empty()) topics.push_back(options.force_topic);
    return topics;
  }

  std::filesystem::path path_;
  std::vector<std::filesystem::path> files_;
  TopicReadOptions options_;
  Rosbag2ReadInfo& info_;
  bool force_only_;
  BagCursor cursor_;
  cdr::JointState js_;
  cdr::WrenchStamped wrench_;
  std::string checked_file_;
  bool joint_checked_ = false, force_checked_ = false;
  std::size_t joint_valid_ = 0, force_valid_ = 0;
};

// A force-only source that owns the info it fills (a second pass's counts are not reported).
class OwningSource final : public MessageSource {
 public:
  OwningSource(const std::filesystem::path& path, const std::vector<std::filesystem::path>& files,
               const TopicReadOptions& options)
      : info_(std::make_unique<Rosbag2ReadInfo>()), source_(path, files, options, *info_, true) {}
  bool next(RecordingMessage& m) override { return source_.next(m); }
  std::string get_time_label(RecordingMessage::Topic t) const override { return source_.get_time_label(t); }
  std::unique_ptr<MessageSource> reopen_force() const override { return source_.reopen_force(); }

 private:
  std::unique_ptr<Rosbag2ReadInfo> info_;
  Rosbag2Source source_;
};

std::unique_ptr<MessageSource> Rosbag2Source::reopen_force() const {
  return std::make_unique<OwningSource>(path_, files_, options_);
}

BagFiles find_bag_files(const std::filesystem::path& path, const TopicReadOptions& options) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(locate(path.string(), ""), "no such file or directory");
  if (options.topic.empty()) throw InputError(locate(path.string(), ""), "no JointState topic given");
  if (std::filesystem::is_directory(path, ec)) return read_metadata(path);
  BagFiles bag;
  bag.files = {path};
  return bag;
}

}  // namespace

struct Rosbag2RecordingReader::Opening {
  Rosbag2ReadInfo info;
  BagFiles bag;
};

Rosbag2RecordingReader::Rosbag2RecordingReader(const std::filesystem::path& path, const TopicReadOptions& options,
                                               std::size_t chunk_rows, std::unique_ptr<Opening> opening)
    : MessageRecordingReader(path.string(), options, RecordingLayout::rosbag2,
                             std::make_unique<Rosbag2Source>(path, opening->bag.files, options, opening->info, false),
                             chunk_rows),
      opening_(std::move(opening)) {}

Rosbag2RecordingReader::~Rosbag2RecordingReader() = default;

const Rosbag2ReadInfo& Rosbag2RecordingReader::info() const {
  Rosbag2ReadInfo& info = opening_->info;
  info.joint_names = joint_names();
  info.time_origin_ns = time_origin_ns();
  return info;
}

std::unique_ptr<Rosbag2RecordingReader> open_rosbag2_recording(const std::filesystem::path& path,
                                                               const TopicReadOptions& options,
                                                               std::size_t chunk_rows) {
  auto opening = std::make_unique<Rosbag2RecordingReader::Opening>();
  opening->bag = find_bag_files(path, options);
  Rosbag2ReadInfo& info = opening->info;
  info.metadata_version = opening->bag.metadata_version;
  info.warnings = opening->bag.warnings;
  info.topic = options.topic;
  info.force_topic = options.force_topic;
  info.receive_time = options.time == MessageTime::receive;
  // The reader's constructor reads up to the first joint sample; `info` lives in `opening`, which it keeps.
  return std::unique_ptr<Rosbag2RecordingReader>(
      new Rosbag2RecordingReader(path, options, chunk_rows, std::move(opening)));
}

Recording load_rosbag2_recording(const std::filesystem::path& path, const TopicReadOptions& options,
                                 Rosbag2ReadInfo* info_out) {
  const auto reader = open_rosbag2_recording(path, options);
  Recording rec = read_whole_recording(*reader);
  if (info_out) *info_out = reader->info();
  return rec;
}

}  // namespace rcm
