// The MCAP format's records and CRC-32 (mcap_records.hpp).

#include "io/rosbag2/mcap_records.hpp"

#include <algorithm>
#include <cstdio>

namespace rcm::mcap::detail {

std::string record_name(std::uint8_t op) {
  static const char* const names[] = {"Header",     "Footer",       "Schema",        "Channel",       "Message",
                                      "Chunk",      "MessageIndex", "ChunkIndex",    "Attachment",    "AttachmentIndex",
                                      "Statistics", "Metadata",     "MetadataIndex", "SummaryOffset", "DataEnd"};
  if (op >= kHeader && op <= kDataEnd) return names[op - 1];
  char buf[32];
  std::snprintf(buf, sizeof buf, "unknown opcode 0x%02x", op);
  return buf;
}

std::string hex32(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08x", v);
  return buf;
}

namespace {

struct CrcTables {
  std::uint32_t t[8][256];
};

const CrcTables& crc_tables() {
  static const CrcTables tables = [] {
    CrcTables c{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t v = i;
      for (int k = 0; k < 8; ++k) v = (v >> 1) ^ (0xEDB88320u & (0u - (v & 1u)));
      c.t[0][i] = v;
    }
    for (int s = 1; s < 8; ++s)
      for (int i = 0; i < 256; ++i) c.t[s][i] = (c.t[s - 1][i] >> 8) ^ c.t[0][c.t[s - 1][i] & 0xff];
    return c;
  }();
  return tables;
}

}  // namespace

std::uint32_t crc32_update(std::uint32_t crc, const std::uint8_t* p, std::size_t n) {
  const auto& t = crc_tables().t;
  std::uint32_t c = ~crc;
  for (; n >= 8; p += 8, n -= 8) {
    const std::uint32_t lo = c ^ static_cast<std::uint32_t>(le(p, 4));
    const std::uint32_t hi = static_cast<std::uint32_t>(le(p + 4, 4));
    c = t[7][lo & 0xff] ^ t[6][(lo >> 8) & 0xff] ^ t[5][(lo >> 16) & 0xff] ^ t[4][lo >> 24] ^ t[3][hi & 0xff] ^
        t[2][(hi >> 8) & 0xff] ^ t[1][(hi >> 16) & 0xff] ^ t[0][hi >> 24];
  }
  for (; n > 0; ++p, --n) c = (c >> 8) ^ t[0][(c ^ *p) & 0xff];
  return ~c;
}

std::string at(std::uint64_t offset, const std::string& what) {
  return "byte " + std::to_string(offset) + " (" + what + ")";
}

std::string Where::str() const {
  if (!in_chunk) return at(offset, record_name(op) + " record");
  return at(chunk, "Chunk record") + ", " + at(offset, record_name(op) + " record in its decompressed records");
}

void grow(std::vector<std::uint8_t>& v, std::uint64_t n) {
  if (v.size() < n) v.resize(std::max<std::uint64_t>(n, std::min<std::uint64_t>(2 * v.size(), kMaxRecordBytes + 1)));
}

}  // namespace rcm::mcap::detail
