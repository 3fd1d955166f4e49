#pragma once
// A recording read as a stream of chunks, so that a command's memory does not
// grow with the recording's length: a three-hour procedure at 1.5 kHz is 16
// million samples, several GB as one Recording.
//
// Every format rcm reads (the contract CSV, `rostopic echo -p` CSV, ROS 1
// bags, rosbag2 SQLite and MCAP) is read here first; load_recording() is
// "every chunk, concatenated", so the checks live in one place and a chunked
// read gives exactly the samples a whole read gives. Each chunk holds at most
// chunk_rows consecutive samples; the reader keeps what crosses a chunk
// boundary (the previous row for repeated rows and time order, the force
// samples around the next joint sample), never the samples already handed
// out.
//
// A defect is reported when the reader reaches it, with the same located
// message as a whole read ("run.csv:1204: column effort_2: expected a
// number"): a file with several defects is reported at the first one in
// reading order. Chunks handed out before a defect are valid; a caller that
// writes files writes them only once read_chunk() has returned false, so that
// a defect late in a file leaves nothing behind.

#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"

namespace rcm {

// Samples per chunk unless the caller says otherwise: 8192 rows of 7 joints
// with force are about 1.6 MB.
inline constexpr std::size_t kDefaultChunkRows = 8192;

class RecordingReader {
 public:
  virtual ~RecordingReader() = default;
  RecordingReader(const RecordingReader&) = delete;
  RecordingReader& operator=(const RecordingReader&) = delete;

  // The next samples, at most chunk_rows() of them, into `chunk` (resized;
  // source, layout, time_from_rate and repeated_rows_removed set as a whole
  // read sets them, line numbers for text files, repeated_rows counted so far).
  // Returns false, with `chunk` holding no samples, once the recording is
  // exhausted. Throws InputError for a defect met on the way.
  bool read_chunk(Recording& chunk);

  const std::string& source() const { return source_; }
  RecordingLayout layout() const { return layout_; }
  // Known once the reader is open: a message reader has read its first sample.
  int num_joints() const { return joints_; }
  bool has_force() const { return has_force_; }
  bool time_from_rate() const { return time_from_rate_; }
  std::size_t chunk_rows() const { return chunk_rows_; }
  // Samples handed out so far, and repeated rows met so far (the totals once
  // read_chunk() has returned false).
  std::size_t samples_read() const { return samples_; }
  std::size_t repeated_rows() const { return repeated_; }
  bool repeated_rows_removed() const { return dedupe_ && repeated_ > 0; }
  // Called once, when the recording has been read to its end (a caller's
  // report of what the reader counted: skipped messages, warnings).
  void set_on_end(std::function<void(RecordingReader&)> on_end) { on_end_ = std::move(on_end); }

 protected:
  RecordingReader(std::string source, RecordingLayout layout, std::size_t chunk_rows, bool dedupe);
  // Appends the next samples to `chunk` (already sized to chunk_rows(),
  // `filled` rows written) and returns the new count; stops at chunk_rows()
  // or at the end of the recording (then sets end_of_data_).
  virtual std::size_t fill_chunk(Recording& chunk, std::size_t filled) = 0;

  void set_shape(int joints, bool has_force) {
    joints_ = joints;
    has_force_ = has_force;
  }
  void set_layout(RecordingLayout layout) { layout_ = layout; }
  void set_time_from_rate(bool v) { time_from_rate_ = v; }
  // Text readers number every sample's source line (Recording::line).
  void set_has_lines(bool v) { has_lines_ = v; }
  void count_repeated_row() { ++repeated_; }
  void set_repeated_rows(std::size_t n) { repeated_ = n; }
  bool end_of_data_ = false;

 private:
  std::string source_;
  RecordingLayout layout_;
  std::size_t chunk_rows_;
  bool dedupe_;
  int joints_ = 0;
  bool has_force_ = false;
  bool time_from_rate_ = false;
  bool has_lines_ = false, end_noted_ = false;
  std::function<void(RecordingReader&)> on_end_;
  std::size_t samples_ = 0, repeated_ = 0;
};

// Opens `path` as load_recording() does (a reader registered for its
// extension, rosbag2 paths, CSV otherwise). Throws InputError as
// load_recording() does for what it meets while opening (a missing file, a
// bad header, a bag without the topic).
std::unique_ptr<RecordingReader> open_recording(const std::filesystem::path& path,
                                                const RecordingReadOptions& options = {},
                                                std::size_t chunk_rows = kDefaultChunkRows);

// CSV text already in memory, read as parse_recording() reads it.
std::unique_ptr<RecordingReader> open_recording_text(std::string text, std::string source,
                                                     const RecordingReadOptions& options = {},
                                                     std::size_t chunk_rows = kDefaultChunkRows);

// A recording already in memory, handed out in chunks (for callers that take
// a reader).
std::unique_ptr<RecordingReader> open_recording_rows(Recording recording, std::size_t chunk_rows = kDefaultChunkRows);

// Every remaining chunk of `reader` as one Recording: what load_recording() returns.
Recording read_whole_recording(RecordingReader& reader);

// The summary of the samples `reader` has left, as summarize_recording() of
// the whole recording gives it, in bounded memory. The exact median sampling
// interval may need the intervals a second time (a recording with more than
// 65,536 distinct intervals): `reopen` then gives a fresh reader of the same
// recording (without it, std::logic_error).
RecordingSummary summarize_recording(RecordingReader& reader,
                                     const std::function<std::unique_ptr<RecordingReader>()>& reopen);

// Streaming readers of other formats, chosen like register_recording_reader()'s
// (extension, or "/" for a directory); one registered here is preferred to a
// whole-file reader of the same extension.
using RecordingStreamOpener = std::function<std::unique_ptr<RecordingReader>(
    const std::filesystem::path&, const RecordingReadOptions&, std::size_t chunk_rows)>;
void register_recording_stream(const std::string& extension, RecordingStreamOpener opener);

}  // namespace rcm
