// A recording as a rosbag2 bag: its messages (CDR), split into storage files,
// and metadata.yaml. The storage files are written by db3_writer.hpp (SQLite)
// and mcap_writer.hpp (MCAP).
#include "rcm/io/rosbag2_writer.hpp"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <climits>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>

#include "io/rosbag2/cdr.hpp"
#include "io/rosbag2/db3_writer.hpp"
#include "io/rosbag2/mcap_writer.hpp"
#include "io/rosbag2/message_definitions.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/atomic_file.hpp"

namespace rcm {
namespace {

using namespace rosbag2::detail;

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
void for_each_message(const Recording& rec, const std::vector<std::int64_t>& stamps,
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

FileStats write_storage_file(const fs::path& file, const Recording& rec, const std::vector<std::int64_t>& stamps,
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

std::vector<std::string> get_dvrk_joint_names(int num_joints) {
  static const char* const psm[] = {"outer_yaw",         "outer_pitch",     "outer_insertion", "outer_roll",
                                    "outer_wrist_pitch", "outer_wrist_yaw", "jaw"};
  std::vector<std::string> names;
  for (int j = 0; j < num_joints; ++j) names.push_back(j < 7 ? psm[j] : "joint_" + std::to_string(j + 1));
  return names;
}

namespace {

// A directory beside `path`, hidden as the atomic files' temporaries are.
fs::path make_temporary_directory(const fs::path& path) {
  const fs::path parent = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  for (int n = 0;; ++n) {
    const fs::path temp = parent / ("." + path.filename().string() + ".rcm-tmp." + std::to_string(::getpid()) + "." +
                                    std::to_string(n));
    std::error_code ec;
    if (fs::create_directory(temp, ec)) return temp;
    if (ec) throw InputError(InputLocation::plain(path.string(), ""), "cannot be written: " + ec.message());
  }
}

}  // namespace

void save_rosbag2_recording(const fs::path& path, const Recording& rec, const Rosbag2WriteOptions& o) {
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
  const std::vector<std::string> names = o.joint_names.empty() ? get_dvrk_joint_names(rec.num_joints()) : o.joint_names;
  if (names.size() != static_cast<std::size_t>(rec.num_joints()))
    throw std::invalid_argument(std::to_string(names.size()) + " joint names for " +
                                std::to_string(rec.num_joints()) + " joints");

  const std::size_t samples = rec.num_samples();
  std::vector<std::int64_t> stamps(samples);
  for (std::size_t k = 0; k < samples; ++k) {
    const auto row = static_cast<Eigen::Index>(k);
    auto sample_error = [&](const std::string& what) {
      InputLocation where = InputLocation::plain(rec.source, "time");
      if (k < rec.line.size()) where.line = rec.line[k];
      return InputError(where, what);
    };
    stamps[k] = o.time_origin_ns + std::llround(rec.time[row] * 1e9);
    // builtin_interfaces/Time holds int32 seconds; zero marks invalid data.
    if (stamps[k] <= 0 || stamps[k] / 1000000000 > INT32_MAX)
      throw sample_error("sample " + std::to_string(k) + ": stamp " + std::to_string(stamps[k]) +
                         " ns does not fit builtin_interfaces/Time");
    if (k > 0 && stamps[k] <= stamps[k - 1])
      throw sample_error("sample " + std::to_string(k) +
                         ": time closer than 1 ns to the previous sample; stamps would not increase");
  }

  if (bare) {
    AtomicFile file(path);
    write_storage_file(file.get_temp_path(), rec, stamps, names, o, 0, samples);
    file.commit();
    return;
  }
  std::error_code ec;
  if (fs::exists(path, ec) && !(fs::is_directory(path, ec) && fs::is_empty(path, ec)))
    throw InputError(InputLocation::plain(path.string(), ""),
                     "cannot be written: it exists and is not an empty directory; a bag directory is written whole");
  std::string stem = path.filename().string();
  if (stem.empty() || stem == ".") stem = path.parent_path().filename().string();
  const fs::path temp = make_temporary_directory(path);
  try {
    const std::size_t per_file = o.split_every > 0 ? o.split_every : samples;
    std::vector<FileStats> files;
    for (std::size_t begin = 0, i = 0; begin < samples; begin += per_file, ++i)
      files.push_back(write_storage_file(temp / (stem + "_" + std::to_string(i) + ext), rec, stamps, names, o, begin,
                                         std::min(samples, begin + per_file)));
    write_file_atomic(temp / "metadata.yaml", full_metadata_yaml(o, rec.has_force(), samples, files));
    if (fs::exists(path, ec)) fs::remove(path);  // empty, checked above
    fs::rename(temp, path);
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(temp, ec);
    throw InputError(InputLocation::plain(path.string(), ""), std::string("cannot be written: ") + e.code().message());
  } catch (const std::runtime_error& e) {
    fs::remove_all(temp, ec);
    if (dynamic_cast<const InputError*>(&e)) throw;
    throw InputError(InputLocation::plain(path.string(), ""), std::string("cannot be written: ") + e.what());
  } catch (...) {
    fs::remove_all(temp, ec);
    throw;
  }
}

}  // namespace rcm
