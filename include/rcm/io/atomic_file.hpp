#pragma once
// Every file rcm writes crosses the disk here, so that no reader, and no run
// cut short by SIGKILL, a power cut or a full disk, finds a half-written file
// under its final name. The bytes go to a hidden temporary in the same
// directory (a rename never crosses file systems), which is written, fsync'ed
// and closed with every error checked, then renamed over the final name; the
// directory is fsync'ed so that the rename itself survives a crash. On any
// failure the temporary is removed, an earlier file under the final name is
// left as it was, and InputError names the file and the system's reason
// ("results.json: cannot be written: No space left on device").
//
// Temporaries are named ".NAME.rcm-tmp.PID.N". One left behind by a process
// that was killed is removed by the next write of the same name (its PID no
// longer runs); rcm never reads names that start with '.'.
//
// Results, models, reports, figures and simulated sessions are whole files
// written once. What streams from a recording of any length (a converted
// recording, a monitor trace, a force series) is written in parts with
// AtomicFileWriter: into the temporary as it is produced, under its name only
// on commit(), so that it too appears whole or not at all. The live nodes
// publish topics and write no files.

#include <filesystem>
#include <string>
#include <string_view>

namespace rcm {

// Writes `bytes` to `path` as described above.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

// A file written in parts: append() as the bytes come (buffered, 1 MB at a
// time), commit() syncs and renames. Destroyed uncommitted (an error on the
// way), the temporary is removed and the final name is not touched. Throws
// InputError naming the path when a write fails.
class AtomicFileWriter {
 public:
  explicit AtomicFileWriter(std::filesystem::path path);
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  const std::filesystem::path& get_path() const { return path_; }
  void append(std::string_view bytes);
  void commit();

 private:
  static constexpr std::size_t kFlushBytes = std::size_t{1} << 20;
  void flush();
  std::filesystem::path path_, temp_;
  int fd_ = -1;
  std::string buffer_;
};

// A file that another program or library writes by name (gnuplot, LibTorch's
// save): it writes get_temp_path(), then commit() syncs it and renames it to
// get_path(). Destroyed uncommitted, the temporary is removed.
class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::filesystem::path& get_path() const { return path_; }
  const std::filesystem::path& get_temp_path() const { return temp_; }
  // Throws InputError naming get_path() when the temporary is missing, empty
  // or cannot be synced or renamed; the temporary is removed then.
  void commit();
  // Removes the temporary (if any); the final name is not touched.
  void discard() noexcept;

 private:
  std::filesystem::path path_, temp_;
  bool done_ = false;
};

}  // namespace rcm
