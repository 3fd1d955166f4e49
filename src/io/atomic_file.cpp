#include "rcm/io/atomic_file.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <system_error>

#include "rcm/common/error.hpp"

namespace rcm {
namespace {

constexpr const char* kTempMarker = ".rcm-tmp.";

[[noreturn]] void fail(const std::filesystem::path& path, const std::string& reason) {
  InputLocation where;
  where.file = path.string();
  throw InputError(where, "cannot be written: " + reason);
}

std::string errno_text(int error) { return std::strerror(error); }

std::filesystem::path directory_of(const std::filesystem::path& path) {
  return path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
}

// Temporaries of `path` left by processes that no longer run (killed while
// writing). A live PID, even one reused by an unrelated process, keeps its file:
// removing a file still being written would be worse than leaving a stale one.
void remove_stale_temporaries(const std::filesystem::path& path) {
  const std::string prefix = "." + path.filename().string() + kTempMarker;
  std::error_code ec;
  std::filesystem::directory_iterator it(directory_of(path), ec), end;
  for (; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string rest = name.substr(prefix.size());
    const std::size_t dot = rest.find('.');
    if (dot == 0 || dot == std::string::npos || rest.find_first_not_of("0123456789") != dot) continue;
    const long pid = std::strtol(rest.substr(0, dot).c_str(), nullptr, 10);
    if (pid <= 0 || pid == static_cast<long>(::getpid())) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == -1 && errno == ESRCH) {
      std::error_code remove_ec;
      std::filesystem::remove(it->path(), remove_ec);
    }
  }
}

// Creates a new temporary next to `path` (O_EXCL: never an existing file);
// returns its descriptor and sets `temp`.
int create_temporary(const std::filesystem::path& path, std::filesystem::path& temp) {
  static std::atomic<unsigned> counter{0};
  remove_stale_temporaries(path);
  const std::filesystem::path dir = directory_of(path);
  for (int attempt = 0; attempt < 100; ++attempt) {
    temp = dir / ("." + path.filename().string() + kTempMarker + std::to_string(::getpid()) + "." +
                  std::to_string(counter.fetch_add(1)));
    const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd >= 0) return fd;
    if (errno != EEXIST) {
      const int error = errno;
      if (!path.has_filename()) fail(path, "not a file name");
      std::error_code ec;
      if (!std::filesystem::is_directory(dir, ec)) fail(path, "directory " + dir.string() + " does not exist");
      fail(path, errno_text(error));
    }
  }
  fail(path, "no free temporary name in " + dir.string());
}

// Makes the rename durable: without it a crash may leave the old name, or none.
// File systems that cannot sync a directory (EINVAL) have nothing to flush.
void sync_directory(const std::filesystem::path& path) {
  const int fd = ::open(directory_of(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  const int rc = ::fsync(fd);
  const int error = errno;
  ::close(fd);
  if (rc != 0 && error != EINVAL && error != EROFS)
    fail(path, "written, but its directory could not be synced: " + errno_text(error));
}

// fsync, checked close, rename; the temporary is removed on any failure.
void finish(const std::filesystem::path& path, const std::filesystem::path& temp, int fd) {
  auto give_up = [&](const std::string& reason) {
    ::unlink(temp.c_str());
    fail(path, reason);
  };
  if (::fsync(fd) != 0) {
    const int error = errno;
    ::close(fd);
    give_up(errno_text(error));
  }
  if (::close(fd) != 0) give_up(errno_text(errno));
  if (::rename(temp.c_str(), path.c_str()) != 0) give_up("cannot replace the file: " + errno_text(errno));
  sync_directory(path);
}


// Writes every byte to fd; on failure closes fd, removes the temporary and throws.
void write_all(const std::filesystem::path& path, const std::filesystem::path& temp, int fd, std::string_view bytes) {
  const char* data = bytes.data();
  std::size_t left = bytes.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, data, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int error = errno;
      ::close(fd);
      ::unlink(temp.c_str());
      fail(path, errno_text(error));
    }
    data += n;
    left -= static_cast<std::size_t>(n);
  }
}

}  // namespace

void write_file_atomic(const std::filesystem::path& path, std::string_view bytes) {
  std::filesystem::path temp;
  const int fd = create_temporary(path, temp);
  write_all(path, temp, fd, bytes);
  finish(path, temp, fd);
}

AtomicFileWriter::AtomicFileWriter(std::filesystem::path path) : path_(std::move(path)) {
  fd_ = create_temporary(path_, temp_);
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ < 0) return;
  ::close(fd_);
  ::unlink(temp_.c_str());
}

void AtomicFileWriter::append(std::string_view bytes) {
  if (fd_ < 0) fail(path_, "already committed");
  buffer_.append(bytes);
  if (buffer_.size() >= kFlushBytes) flush();
}

void AtomicFileWriter::flush() {
  const int fd = fd_;
  fd_ = -1;  // write_all closes it on failure
  write_all(path_, temp_, fd, buffer_);
  fd_ = fd;
  buffer_.clear();
}

void AtomicFileWriter::commit() {
  if (fd_ < 0) fail(path_, "already committed");
  flush();
  const int fd = fd_;
  fd_ = -1;
  finish(path_, temp_, fd);
}

AtomicFile::AtomicFile(std::filesystem::path path) : path_(std::move(path)) {
  const int fd = create_temporary(path_, temp_);
  // The writer opens the name itself; the empty file reserves it.
  ::close(fd);
}

AtomicFile::~AtomicFile() { discard(); }

void AtomicFile::discard() noexcept {
  if (done_) return;
  done_ = true;
  ::unlink(temp_.c_str());
}

void AtomicFile::commit() {
  if (done_) fail(path_, "already committed or discarded");
  struct stat st {};
  if (::stat(temp_.c_str(), &st) != 0 || st.st_size == 0) {
    discard();
    fail(path_, "the program that writes it left it empty or missing");
  }
  const int fd = ::open(temp_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    discard();
    fail(path_, errno_text(error));
  }
  done_ = true;
  finish(path_, temp_, fd);
}

}  // namespace rcm
