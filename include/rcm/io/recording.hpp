#pragma once
// One recording of the rcm-session/1 contract: time-stamped joint positions,
// velocities and efforts of N >= 3 joints, optionally the ground-truth force.
//
// Text layouts read here: the contract's own CSV (time, position_i, velocity_i,
// effort_i, force_x..z) and what `rostopic echo -p /PSM1/measured_js` writes
// (%time in ns, field.position0.., field.velocity0.., field.effort0..).
// Message recordings (ROS 1 bags, rosbag2) have their own readers
// (io/rosbag2.hpp, ros/bag_reader.hpp) reached through load_recording.

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "rcm/common/options_fwd.hpp"
#include "rcm/io/atomic_file.hpp"

namespace rcm {

enum class RecordingLayout { rcm_csv, rostopic_csv, in_memory, rosbag, rosbag2 };

struct Recording {
  std::string source;             // file path (for messages) or a description
  RecordingLayout layout = RecordingLayout::in_memory;

  Eigen::VectorXd time;           // s, strictly increasing, size T
  Eigen::MatrixXd position;       // T x N: rad, rad, m, rad...
  Eigen::MatrixXd velocity;       // T x N: rad/s, rad/s, m/s, rad/s...
  Eigen::MatrixXd effort;         // T x N: N m, N m, N, N m...
  std::optional<Eigen::MatrixXd> force;  // T x 3, N, base frame; ground truth only

  // 1-based source line of every sample, so that later stages can point the
  // user at the file (empty for in-memory recordings).
  std::vector<std::size_t> line;

  // Rows whose joint data repeat the previous row exactly (the logger ran
  // faster than the topic). Counted always; removed only when asked.
  std::size_t repeated_rows = 0;
  bool repeated_rows_removed = false;
  // True when the file had no time column and time was built from a rate the
  // user gave explicitly.
  bool time_from_rate = false;

  std::size_t num_samples() const { return static_cast<std::size_t>(time.size()); }
  int num_joints() const { return static_cast<int>(position.cols()); }
  bool has_force() const { return force.has_value(); }
};

struct RecordingReadOptions {
  // Drop rows whose position, velocity and effort equal the previous row's.
  bool dedupe = false;
  // When the file has no time column: the sampling rate to assume (Hz). Without
  // it such a file is an error; time is never invented silently.
  std::optional<double> assumed_rate_hz;
  // Minimum number of joints the caller needs.
  int min_joints = 3;
  // Message recordings (bags) of a session whose manifest names its topics
  // ("topics": {"joints": ..., "force": ...}): the topics to read unless the
  // command line names others. Empty: the reader's own (default or flags).
  std::string joint_topic, force_topic;
};
// The field table (rcm/common/options.hpp).
const OptionTable<RecordingReadOptions>& get_option_table(OptionTag<RecordingReadOptions>);

// Reads and validates a recording. Throws InputError naming file, line and
// column for every defect: missing column, non-numeric cell, NaN/inf,
// non-increasing time, too few joints, empty file.
Recording load_recording(const std::filesystem::path& path,
                         const RecordingReadOptions& options = {});

// Readers of other file formats, chosen by the file's extension (".bag"), or
// "/" for a directory: load_recording, and so everything that loads a session's
// files, hands such a file to its reader. rcm::core reads CSV, and rosbag2
// directories, .db3 and .mcap files (io/rosbag2.hpp, default topic and options)
// unless a reader is registered for them; the ROS library registers ".bag"
// (ros/, register_bag_recording_reader), the CLI registers its --topic options.
// Registering an extension again replaces its reader.
using RecordingFileReader = std::function<Recording(const std::filesystem::path&, const RecordingReadOptions&)>;
void register_recording_reader(const std::string& extension, RecordingFileReader reader);

// Same, from text already in memory; `source` names it in messages.
Recording parse_recording(const std::string& text, const std::string& source,
                          const RecordingReadOptions& options = {});

// Writes the contract's CSV layout atomically (temporary file + rename), with
// shortest round-trip number formatting so that reading it back is exact.
void save_recording(const std::filesystem::path& path, const Recording& recording);

// The same layout written a chunk at a time (io/recording_reader.hpp): into a
// temporary as the chunks come, under `path` only on commit(), so that the
// file appears whole or not at all. Each chunk is checked as
// validate_recording() checks a recording, and time must increase across
// chunks.
class RecordingWriter {
 public:
  RecordingWriter(const std::filesystem::path& path, int joints, bool has_force);
  void write(const Recording& chunk);
  void commit();
  std::size_t samples() const { return samples_; }

 private:
  AtomicFileWriter file_;
  int joints_;
  bool has_force_;
  std::size_t samples_ = 0;
  double last_time_ = 0.0;
  std::string text_;
};

// Checks the invariants of an in-memory recording (sizes agree, time strictly
// increasing, every value finite); throws InputError naming `recording.source`.
void validate_recording(const Recording& recording);

// Samples [begin, end) of `recording` as a recording of their own (source and
// lines kept, so that messages still point into the file).
Recording get_recording_rows(const Recording& recording, Eigen::Index begin, Eigen::Index end);

// What `rcm inspect` shows of a recording.
struct RecordingSummary {
  std::size_t samples = 0;
  int joints = 0;
  double duration_s = 0.0;
  double rate_hz = 0.0;            // 1 / median sampling interval
  double dt_median_s = 0.0;
  double dt_min_s = 0.0, dt_max_s = 0.0;
  double jitter_s = 0.0;           // standard deviation of the sampling interval
  std::size_t repeated_rows = 0;
  bool repeated_rows_removed = false;
  bool has_force = false;
  bool time_from_rate = false;
  struct Range { double min = 0, max = 0; };
  std::vector<Range> position, velocity, effort;  // per joint
  std::vector<Range> force;                       // x, y, z when present
};

RecordingSummary summarize_recording(const Recording& recording);

}  // namespace rcm
