#include "rcm/io/recording_reader.hpp"

#include <iostream>
#include <map>
#include <mutex>

#include "io/csv_recording_reader.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/rosbag2.hpp"

namespace rcm {

RecordingReader::RecordingReader(std::string source, RecordingLayout layout, std::size_t chunk_rows, bool dedupe)
    : source_(std::move(source)), layout_(layout), chunk_rows_(std::max<std::size_t>(chunk_rows, 1)), dedupe_(dedupe) {}

bool RecordingReader::read_chunk(Recording& chunk) {
  const auto rows = static_cast<Eigen::Index>(chunk_rows_);
  chunk.source = source_;
  chunk.layout = layout_;
  chunk.time_from_rate = time_from_rate_;
  chunk.time.resize(rows);
  chunk.position.resize(rows, joints_);
  chunk.velocity.resize(rows, joints_);
  chunk.effort.resize(rows, joints_);
  if (has_force_) {
    if (!chunk.force) chunk.force.emplace();
    chunk.force->resize(rows, 3);
  } else {
    chunk.force.reset();
  }
  chunk.line.resize(has_lines_ ? chunk_rows_ : 0);
  std::size_t filled = 0;
  while (filled < chunk_rows_ && !end_of_data_) filled = fill_chunk(chunk, filled);
  if (filled < chunk_rows_) {
    const auto n = static_cast<Eigen::Index>(filled);
    chunk.time.conservativeResize(n);
    chunk.position.conservativeResize(n, joints_);
    chunk.velocity.conservativeResize(n, joints_);
    chunk.effort.conservativeResize(n, joints_);
    if (chunk.force) chunk.force->conservativeResize(n, 3);
    if (has_lines_) chunk.line.resize(filled);
  }
  samples_ += filled;
  chunk.repeated_rows = repeated_;
  chunk.repeated_rows_removed = repeated_rows_removed();
  if (end_of_data_ && !end_noted_) {
    end_noted_ = true;
    if (on_end_) on_end_(*this);
  }
  return filled > 0;
}

Recording read_whole_recording(RecordingReader& reader) {
  // Chunks are kept as read and copied once into matrices of the final size.
  std::vector<Recording> chunks;
  Eigen::Index total = 0;
  while (true) {
    Recording chunk;
    if (!reader.read_chunk(chunk)) break;
    total += chunk.time.size();
    chunks.push_back(std::move(chunk));
  }
  Recording rec;
  rec.source = reader.source();
  rec.layout = reader.layout();
  rec.time_from_rate = reader.time_from_rate();
  rec.repeated_rows = reader.repeated_rows();
  rec.repeated_rows_removed = reader.repeated_rows_removed();
  const int N = reader.num_joints();
  rec.time.resize(total);
  rec.position.resize(total, N);
  rec.velocity.resize(total, N);
  rec.effort.resize(total, N);
  if (reader.has_force()) rec.force = Eigen::MatrixXd(total, 3);
  Eigen::Index at = 0;
  for (Recording& c : chunks) {
    const Eigen::Index n = c.time.size();
    rec.time.segment(at, n) = c.time;
    rec.position.middleRows(at, n) = c.position;
    rec.velocity.middleRows(at, n) = c.velocity;
    rec.effort.middleRows(at, n) = c.effort;
    if (rec.force) rec.force->middleRows(at, n) = *c.force;
    rec.line.insert(rec.line.end(), c.line.begin(), c.line.end());
    at += n;
    c = Recording();
  }
  return rec;
}

namespace {

// A recording in memory, handed out in chunks.
class RowsReader final : public RecordingReader {
 public:
  RowsReader(Recording rec, std::size_t chunk_rows)
      : RecordingReader(rec.source, rec.layout, chunk_rows, rec.repeated_rows_removed), rec_(std::move(rec)) {
    set_shape(rec_.num_joints(), rec_.has_force());
    set_time_from_rate(rec_.time_from_rate);
    set_has_lines(!rec_.line.empty());
    set_repeated_rows(rec_.repeated_rows);
  }

 private:
  std::size_t fill_chunk(Recording& chunk, std::size_t filled) override {
    const auto n = static_cast<Eigen::Index>(
        std::min<std::size_t>(chunk_rows() - filled, rec_.num_samples() - next_));
    const auto at = static_cast<Eigen::Index>(filled), from = static_cast<Eigen::Index>(next_);
    chunk.time.segment(at, n) = rec_.time.segment(from, n);
    chunk.position.middleRows(at, n) = rec_.position.middleRows(from, n);
    chunk.velocity.middleRows(at, n) = rec_.velocity.middleRows(from, n);
    chunk.effort.middleRows(at, n) = rec_.effort.middleRows(from, n);
    if (rec_.force) chunk.force->middleRows(at, n) = rec_.force->middleRows(from, n);
    if (!rec_.line.empty()) std::copy_n(rec_.line.begin() + from, n, chunk.line.begin() + at);
    next_ += static_cast<std::size_t>(n);
    if (next_ == rec_.num_samples()) end_of_data_ = true;
    return filled + static_cast<std::size_t>(n);
  }

  Recording rec_;
  std::size_t next_ = 0;
};

std::mutex& reader_mutex() {
  static std::mutex m;
  return m;
}
std::map<std::string, RecordingFileReader>& readers() {
  static std::map<std::string, RecordingFileReader> r;  // function-local: safe across TUs
  return r;
}
std::map<std::string, RecordingStreamOpener>& streams() {
  static std::map<std::string, RecordingStreamOpener> r;
  return r;
}

std::string reader_key(const std::filesystem::path& path) {
  std::error_code ec;
  return std::filesystem::is_directory(path, ec) ? "/" : path.extension().string();
}

}  // namespace

std::unique_ptr<RecordingReader> open_recording_rows(Recording recording, std::size_t chunk_rows) {
  return std::make_unique<RowsReader>(std::move(recording), chunk_rows);
}

void register_recording_reader(const std::string& extension, RecordingFileReader reader) {
  const std::lock_guard<std::mutex> lock(reader_mutex());
  streams().erase(extension);
  readers()[extension] = std::move(reader);
}

void register_recording_stream(const std::string& extension, RecordingStreamOpener opener) {
  const std::lock_guard<std::mutex> lock(reader_mutex());
  readers().erase(extension);
  streams()[extension] = std::move(opener);
}

std::unique_ptr<RecordingReader> open_recording(const std::filesystem::path& path, const RecordingReadOptions& options,
                                                std::size_t chunk_rows) {
  const std::string key = reader_key(path);
  RecordingStreamOpener opener;
  RecordingFileReader reader;
  {
    const std::lock_guard<std::mutex> lock(reader_mutex());
    if (const auto it = streams().find(key); it != streams().end()) opener = it->second;
    if (const auto it = readers().find(key); it != readers().end()) reader = it->second;
  }
  if (opener) return opener(path, options, chunk_rows);
  if (reader) return open_recording_rows(reader(path, options), chunk_rows);
  if (is_rosbag2_path(path)) return open_rosbag2_recording(path, with_session_topics({}, options), chunk_rows);
  return detail::open_csv_recording(path, options, chunk_rows);
}

std::unique_ptr<RecordingReader> open_recording_text(std::string text, std::string source,
                                                     const RecordingReadOptions& options, std::size_t chunk_rows) {
  return detail::open_csv_text(std::move(text), source, options, chunk_rows);
}

Recording load_recording(const std::filesystem::path& path, const RecordingReadOptions& options) {
  const std::string key = reader_key(path);
  RecordingFileReader reader;
  {
    const std::lock_guard<std::mutex> lock(reader_mutex());
    if (const auto it = readers().find(key); it != readers().end()) reader = it->second;
  }
  if (reader) return reader(path, options);
  const auto stream = open_recording(path, options);
  Recording rec = read_whole_recording(*stream);
  if (const auto* bag = dynamic_cast<const Rosbag2RecordingReader*>(stream.get()))
    for (const std::string& w : bag->info().warnings) std::cerr << "warning: " << w << "\n";
  return rec;
}

Recording parse_recording(const std::string& text, const std::string& source, const RecordingReadOptions& options) {
  const auto stream = open_recording_text(text, source, options);
  return read_whole_recording(*stream);
}

}  // namespace rcm
