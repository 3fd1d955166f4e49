#pragma once
// Internal to the MCAP reader: the format's records (opcodes, sizes, the field
// decoder, where a record is for messages) and the CRC-32 of its checksums.
// mcap_reader.cpp reads a file with them.

#include <lz4frame.h>
#include <zstd.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "io/rosbag2/mcap_reader.hpp"

namespace rcm::mcap::detail {

constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
constexpr std::uint64_t kPrefix = 9;       // opcode + uint64 content length
constexpr std::uint64_t kFooterBody = 20;  // summary_start, summary_offset_start, summary_crc
constexpr std::uint64_t kTail = kPrefix + kFooterBody + sizeof kMagic;
constexpr std::uint64_t kChunkFixed = 8 + 8 + 8 + 4 + 4;  // times, sizes, crc, compression length
constexpr std::uint64_t kMessageFixed = 2 + 4 + 8 + 8;
constexpr std::size_t kReadBlock = 1 << 16;

// clang-format off
enum Op : std::uint8_t {
  kHeader = 0x01, kFooter, kSchema, kChannel, kMessage, kChunk, kMessageIndex, kChunkIndex, kAttachment,
  kAttachmentIndex, kStatistics, kMetadata, kMetadataIndex, kSummaryOffset, kDataEnd
};
// clang-format on

// "Header", "Chunk", ... or "unknown opcode 0x.." for messages.
std::string record_name(std::uint8_t op);
std::string hex32(std::uint32_t v);

// Little-endian unsigned integer of `bytes` bytes.
inline std::uint64_t le(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

// CRC-32 as in zlib (reflected polynomial 0xEDB88320), sliced by 8 because the
// data-section CRC covers every byte of a possibly multi-GB recording. Same
// chaining convention as zlib's crc32(): start from 0, feed pieces in order.
std::uint32_t crc32_update(std::uint32_t crc, const std::uint8_t* p, std::size_t n);

// Decodes the fields of one record body held in memory. A field that does not
// fit clears ok() instead of throwing, so that a record is checked once after
// all its fields are read.
class Fields {
 public:
  Fields(const std::uint8_t* p, std::uint64_t n) : p_(p), n_(n) {}
  std::uint64_t uint(int bytes) { return take(bytes) ? le(p_ + pos_ - bytes, bytes) : 0; }
  std::string str() {
    const std::uint64_t len = uint(4);
    if (!take(len)) return {};
    return std::string(reinterpret_cast<const char*>(p_ + pos_ - len), len);
  }
  void skip_prefixed() { take(uint(4)); }  // uint32-length bytes or map
  bool ok() const { return ok_; }

 private:
  bool take(std::uint64_t k) {
    if (!ok_ || k > n_ - pos_) return ok_ = false;
    pos_ += k;
    return true;
  }
  const std::uint8_t* p_;
  std::uint64_t n_, pos_ = 0;
  bool ok_ = true;
};

// "byte N (what)".
std::string at(std::uint64_t offset, const std::string& what);

// Where a record is; formatted only when an error is reported, so that the
// per-message path does not build strings.
struct Where {
  std::uint64_t offset = 0;  // of the record, in the file or in the chunk's decompressed records
  std::uint8_t op = 0;
  bool in_chunk = false;
  std::uint64_t chunk = 0;  // offset of the enclosing Chunk record
  std::string str() const;
};

// Buffers are reused from record to record and grow geometrically, so that
// reading allocates a few times per file rather than per chunk or message.
void grow(std::vector<std::uint8_t>& v, std::uint64_t n);

struct ZstdFree {
  void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};
struct Lz4Free {
  void operator()(LZ4F_dctx* c) const { LZ4F_freeDecompressionContext(c); }
};

}  // namespace rcm::mcap::detail
