#pragma once
// A reader of MCAP files (mcap.dev spec, version 0), the container that rosbag2
// writes by default since ROS 2 Iron. No MCAP C++ library is packaged in
// Debian, so this one is written on libzstd and liblz4 and reads exactly what
// rcm needs: the channels and their messages, in file order, streaming one
// chunk at a time so that recordings of several GB need little memory.
//
// Recordings come from robots that crash, disks that fill up and copies that
// go wrong, so the reader checks everything it can before trusting it: every
// record length against the file size before allocating, chunk CRCs, the
// data-section and summary CRCs, declared sizes of decompressed chunks, and
// that messages name declared channels. A file without its Footer is what a
// killed recorder leaves behind: it is read up to its last complete record and
// reported as truncated, not rejected; a file that has its Footer but whose
// records do not fit is corrupt and rejected.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace rcm::mcap {

struct Channel {
  std::uint16_t id = 0;
  std::uint16_t schema_id = 0;          // 0: no schema
  std::string topic;
  std::string message_encoding;         // "cdr" for ROS 2
  std::string schema_name;              // e.g. "sensor_msgs/msg/JointState" (empty without schema)
  std::string schema_encoding;          // e.g. "ros2msg"
};

struct MessageRef {
  const Channel* channel = nullptr;
  std::uint32_t sequence = 0;
  std::uint64_t log_time_ns = 0;
  std::uint64_t publish_time_ns = 0;
  const std::uint8_t* data = nullptr;   // valid only during the callback
  std::size_t size = 0;
  std::uint64_t record_offset = 0;      // byte offset in the file of the Message record (in the chunk's decompressed records when inside a chunk: then chunk_offset says where the chunk is)
  std::uint64_t chunk_offset = 0;       // byte offset of the enclosing Chunk record, 0 when not in a chunk
};

struct ReadResult {
  std::string profile, library;         // from the Header record
  std::vector<Channel> channels;        // every channel declared, in file order
  std::size_t chunks = 0;
  std::size_t messages = 0;             // messages seen (all channels)
  bool has_summary = false;             // a Footer with a non-zero summary_start
  bool truncated = false;               // the file ends early (no footer / cut in a record): read up to the last complete record/chunk
  std::string truncation;               // human-readable: where the file was cut and what was kept, for a warning
};

// Largest block the reader holds in memory at once: the decompressed records of
// one chunk, or one record body outside chunks. rosbag2 writes chunks of a few
// MB; a larger declared size is taken as corruption rather than allocated.
inline constexpr std::uint64_t kMaxRecordBytes = std::uint64_t{1} << 30;

// Reads the data section in file order and calls `on_message` for every message whose
// channel `wanted` accepts (called once per channel when it is declared; an empty
// `wanted` accepts every channel). Throws rcm::InputError (location: file = path,
// field = e.g. "byte 1234 (Chunk record)") saying what is wrong and where for: not an
// MCAP file (bad leading magic), unsupported version, a record whose length runs past a
// complete file (corruption when the footer is present), unknown chunk compression
// (supported: "", "lz4", "zstd"), decompression failure or wrong uncompressed size,
// chunk CRC mismatch (uncompressed_crc when non-zero), data section CRC mismatch
// (DataEnd.data_section_crc when non-zero), summary CRC mismatch (Footer.summary_crc
// when non-zero), a message on an undeclared channel, a channel naming an undeclared
// schema, sizes above kMaxRecordBytes. A file cut off by a crash (no footer magic at the
// end, or the last record or chunk incomplete) is NOT an error: everything up to the
// last complete record is read (a chunk counts only when complete) and
// truncated/truncation are set, like `mcap recover`. Records of unknown opcode are
// skipped, as the spec requires. Attachments, metadata, indexes and statistics are
// parsed only as far as needed to skip or check them.
// The same, pulled one message at a time: next() fills `message` (its data
// valid until the next call) and returns false at the end, once the summary
// and footer have been checked; result() then holds what read_mcap returns.
// Holds one decompressed chunk at a time.
class Cursor {
 public:
  Cursor(const std::filesystem::path& path, std::function<bool(const Channel&)> wanted);
  ~Cursor();
  Cursor(Cursor&&) noexcept;
  bool next(MessageRef& message);
  const ReadResult& result() const;

 private:
  class Reader;
  std::unique_ptr<Reader> reader_;
};

ReadResult read_mcap(const std::filesystem::path& path,
                     const std::function<bool(const Channel&)>& wanted,
                     const std::function<void(const MessageRef&)>& on_message);

}  // namespace rcm::mcap
