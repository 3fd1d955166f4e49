#include "rcm/io/rosbag2.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <map>
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

// Calls `on_message` for the messages of `topics` in every file, in order;
// records every topic met (for "no such topic" errors).
void for_each_message(const std::vector<std::filesystem::path>& files, const std::vector<std::string>& topics,
                      Rosbag2ReadInfo& info, std::map<std::string, TopicSeen>& seen,
                      const std::function<void(const std::filesystem::path&, const RawMessage&)>& on_message) {
  auto is_wanted = [&](const std::string& name) { return std::find(topics.begin(), topics.end(), name) != topics.end(); };
  for (const auto& path : files) {
    const std::string ext = lower_extension(path);
    if (ext == ".db3") {
      info.storage = "sqlite3";
      const rosbag2::SqliteBagInfo db = rosbag2::read_sqlite_bag(
          path,
          [&](const rosbag2::SqliteTopic& t) {
            seen[t.name] = {t.type, t.serialization_format};
            return is_wanted(t.name);
          },
          [&](const rosbag2::SqliteMessage& m) {
            on_message(path, {&m.topic->name, &m.topic->type, &m.topic->serialization_format, m.receive_ns, m.data,
                              m.size});
          });
      info.sqlite_schema = db.schema_version;
      if (!db.ros_distro.empty()) info.ros_distro = db.ros_distro;
    } else if (ext == ".mcap") {
      info.storage = "mcap";
      const mcap::ReadResult r = mcap::read_mcap(
          path,
          [&](const mcap::Channel& c) {
            seen[c.topic] = {c.schema_name, c.message_encoding};
            return is_wanted(c.topic);
          },
          [&](const mcap::MessageRef& m) {
            on_message(path, {&m.channel->topic, &m.channel->schema_name, &m.channel->message_encoding,
                              static_cast<std::int64_t>(m.log_time_ns), m.data, m.size});
          });
      if (r.truncated) info.warnings.push_back(path.string() + ": " + r.truncation);
    } else {
      throw InputError(locate(path.string(), ""),
                       "storage file of unknown kind (" + (ext.empty() ? std::string("no extension") : ext) +
                           "); rosbag2 storage is .db3 (sqlite3) or .mcap");
    }
    info.files.push_back(path.string());
  }
}

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

Recording load_rosbag2_recording(const std::filesystem::path& path, const TopicReadOptions& options,
                                 Rosbag2ReadInfo* info_out) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(locate(path.string(), ""), "no such file or directory");
  if (options.topic.empty()) throw InputError(locate(path.string(), ""), "no JointState topic given");
  Rosbag2ReadInfo info;
  BagFiles bag;
  if (std::filesystem::is_directory(path, ec)) {
    bag = read_metadata(path);
  } else {
    bag.files = {path};
  }
  info.metadata_version = bag.metadata_version;
  info.warnings = bag.warnings;
  info.topic = options.topic;
  info.force_topic = options.force_topic;
  info.receive_time = options.time == MessageTime::receive;

  const bool header_time = options.time == MessageTime::header;
  const std::string source = path.string();
  JointStateRecordingBuilder builder(source, options.topic, options, header_time ? "header.stamp" : "receive time");
  std::optional<ForceSamples> force;
  if (!options.force_topic.empty())
    force.emplace(source, options.force_topic, header_time ? "header.stamp" : "receive time");

  std::vector<std::string> topics = {options.topic};
  if (force) topics.push_back(options.force_topic);
  std::map<std::string, TopicSeen> seen;
  cdr::JointState js;
  cdr::WrenchStamped wrench;
  // Once per topic and file: every file of a bag declares its topics again.
  bool joint_topic_checked = false, force_topic_checked = false;
  std::string checked_file;
  for_each_message(bag.files, topics, info, seen, [&](const std::filesystem::path& file, const RawMessage& raw) {
    if (file.native() != checked_file) {
      checked_file = file.native();
      joint_topic_checked = force_topic_checked = false;
    }
    if (*raw.topic == options.topic) {
      if (!joint_topic_checked) check_topic(file.string(), seen, options.topic, kJointStateType, "JointState");
      joint_topic_checked = true;
      const std::size_t k = info.messages++;
      decode_or_throw(file, options.topic, k, raw, js);
      if (header_time && js.header.is_zero()) {
        ++info.zero_stamp_messages;
        return;
      }
      builder.add(k, header_time ? js.header.get_stamp_ns() : raw.receive_ns, view_joint_state(js));
    } else {
      if (!force_topic_checked) check_topic(file.string(), seen, options.force_topic, kWrenchType, "force");
      force_topic_checked = true;
      const std::size_t k = info.force_messages++;
      decode_or_throw(file, options.force_topic, k, raw, wrench);
      if (header_time && wrench.header.is_zero()) {
        ++info.force_zero_stamp_messages;
        return;
      }
      if (force->size() == 0) info.force_frame_id = wrench.header.frame_id;
      force->add(k, header_time ? wrench.header.get_stamp_ns() : raw.receive_ns,
                 Eigen::Vector3d(wrench.force[0], wrench.force[1], wrench.force[2]));
    }
  });
  check_topic(source, seen, options.topic, kJointStateType, "JointState");
  if (builder.size() == 0)
    throw InputError(locate(source, options.topic),
                     std::to_string(info.messages) +
                         " messages, none valid: every header.stamp is zero (invalid data for the dVRK); "
                         "--time receive uses the recorder's receive time instead");
  Recording rec = builder.finish(RecordingLayout::rosbag2);
  info.joint_names = builder.joint_names();
  info.time_origin_ns = builder.time_origin_ns();
  if (force) {
    check_topic(source, seen, options.force_topic, kWrenchType, "force");
    if (force->size() == 0)
      throw InputError(locate(source, options.force_topic),
                       std::to_string(info.force_messages) +
                           " messages, none valid: every header.stamp is zero; --time receive uses the recorder's "
                           "receive time instead");
    builder.attach_force(rec, *force);
  }
  if (info_out) *info_out = std::move(info);
  return rec;
}

}  // namespace rcm
