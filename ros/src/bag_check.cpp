#include "bag_check.hpp"

#include <bzlib.h>
#include <roslz4/lz4s.h>

#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"

namespace rcm::ros1 {
namespace {

enum Op : std::uint8_t { kMessageData = 0x02, kBagHeader = 0x03, kIndexData = 0x04, kChunk = 0x05, kChunkInfo = 0x06,
                         kConnection = 0x07 };
constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr std::uint64_t kMagicSize = sizeof kMagic - 1;

std::uint64_t le(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

using Fields = std::map<std::string, std::string>;

struct Record {
  std::uint64_t pos = 0;
  std::uint8_t op = 0;
  Fields fields;
  std::uint64_t data_pos = 0;
  std::uint32_t data_len = 0;
};

class Checker {
 public:
  explicit Checker(const std::filesystem::path& path) : file_(path.string()) {}

  void run() {
    std::error_code ec;
    size_ = std::filesystem::file_size(file_, ec);
    in_.open(file_, std::ios::binary);
    if (ec || !in_) fail(0, "", "cannot open the file");
    char magic[kMagicSize] = {};
    if (size_ < kMagicSize || !read(0, reinterpret_cast<std::uint8_t*>(magic), kMagicSize) ||
        std::memcmp(magic, kMagic, kMagicSize) != 0)
      fail(0, "", "not a ROS 1 bag of format 2.0 (it does not start with \"#ROSBAG V2.0\")");

    std::vector<Record> records;
    for (std::uint64_t pos = kMagicSize; pos < size_;) {
      records.push_back(read_record(pos));
      const Record& r = records.back();
      record_index_[r.pos] = records.size() - 1;
      if (records.size() == 1 && r.op != kBagHeader) fail(r.pos, "record", "the first record is not the bag header");
      if (r.op == kChunk) check_chunk(r);
      if (r.op == kConnection) check_connection(r);
      if (r.op == kIndexData) check_index(r, records);
      if (r.op == kChunkInfo) check_chunk_info(r);
      pos = r.data_pos + r.data_len;
    }
    if (records.empty()) fail(kMagicSize, "bag header", "the file ends after the magic");
    check_index_section(records);
  }

 private:
  [[noreturn]] void fail(std::uint64_t offset, const std::string& what, const std::string& why) const {
    // Worded as rosbag's own open errors are reported by the reader.
    throw InputError(InputLocation::plain(file_, "byte " + std::to_string(offset) + (what.empty() ? "" : " (" + what + ")")),
                     "not a readable rosbag: " + why);
  }

  bool read(std::uint64_t pos, std::uint8_t* dst, std::uint64_t n) {
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(pos));
    in_.read(reinterpret_cast<char*>(dst), static_cast<std::streamsize>(n));
    return static_cast<std::uint64_t>(in_.gcount()) == n;
  }

  // Splits "len name=value" fields; the op field must be one byte.
  void parse_fields(const std::uint8_t* p, std::uint64_t n, std::uint64_t offset, Fields& out) const {
    out.clear();
    for (std::uint64_t i = 0; i < n;) {
      if (n - i < 4) fail(offset + i, "header field", "field length cut by the end of the header");
      const std::uint64_t len = le(p + i, 4);
      if (len > n - i - 4) fail(offset + i, "header field", "field of " + std::to_string(len) + " bytes overruns the header");
      const char* f = reinterpret_cast<const char*>(p + i + 4);
      const void* eq = std::memchr(f, '=', len);
      if (!eq) fail(offset + i, "header field", "field without '='");
      const auto name_len = static_cast<std::size_t>(static_cast<const char*>(eq) - f);
      out[std::string(f, name_len)] = std::string(f + name_len + 1, len - name_len - 1);
      i += 4 + len;
    }
  }

  // A record of `n` bytes at `pos` in `p` (the file, or a chunk's records).
  static bool frame(const std::uint8_t* p, std::uint64_t n, std::uint64_t pos, std::uint64_t& header_len,
                    std::uint64_t& data_len) {
    if (n - pos < 4) return false;
    header_len = le(p + pos, 4);
    if (header_len > n - pos - 4 || n - pos - 4 - header_len < 4) return false;
    data_len = le(p + pos + 4 + header_len, 4);
    return data_len <= n - pos - 8 - header_len;
  }

  std::uint8_t op_of(const Fields& f, std::uint64_t offset) const {
    const auto it = f.find("op");
    if (it == f.end() || it->second.size() != 1) fail(offset, "record", "no one-byte op field");
    return static_cast<std::uint8_t>(it->second[0]);
  }

  std::uint64_t field(const Record& r, const char* name, int bytes) const {
    const auto it = r.fields.find(name);
    if (it == r.fields.end() || it->second.size() != static_cast<std::size_t>(bytes))
      fail(r.pos, "record op " + std::to_string(r.op), std::string("field '") + name + "' missing or not " +
                                                             std::to_string(bytes) + " bytes");
    return le(reinterpret_cast<const std::uint8_t*>(it->second.data()), bytes);
  }

  Record read_record(std::uint64_t pos) {
    Record r;
    r.pos = pos;
    std::uint8_t len[4];
    if (size_ - pos < 4 || !read(pos, len, 4)) fail(pos, "record", "record header length cut by the end of the file");
    const std::uint64_t header_len = le(len, 4);
    if (header_len > size_ - pos - 4) fail(pos, "record", "header of " + std::to_string(header_len) + " bytes runs past the end of the file");
    header_.resize(header_len);
    read(pos + 4, header_.data(), header_len);
    parse_fields(header_.data(), header_len, pos + 4, r.fields);
    r.op = op_of(r.fields, pos);
    const std::uint64_t dpos = pos + 4 + header_len;
    if (size_ - dpos < 4 || !read(dpos, len, 4)) fail(dpos, "record", "data length cut by the end of the file");
    r.data_len = static_cast<std::uint32_t>(le(len, 4));
    r.data_pos = dpos + 4;
    if (r.data_len > size_ - r.data_pos)
      fail(pos, "record", "data of " + std::to_string(r.data_len) + " bytes runs past the end of the file");
    return r;
  }

  // Decompresses into records_, growing the buffer only as output arrives, so
  // that a corrupt declared size is found before anything that large is allocated.
  void decompress(const Record& r, const std::string& compression, std::uint64_t declared) {
    if (compression == "none") {
      records_.resize(r.data_len);
      read(r.data_pos, records_.data(), r.data_len);
      return;
    }
    packed_.resize(r.data_len);
    read(r.data_pos, packed_.data(), r.data_len);
    std::uint64_t room = std::min<std::uint64_t>(declared, std::max<std::uint64_t>(4 * std::uint64_t{r.data_len}, 1 << 16));
    while (true) {
      records_.resize(room);
      unsigned int produced = static_cast<unsigned int>(room);
      int rc;
      bool small;
      if (compression == "lz4") {
        rc = roslz4_buffToBuffDecompress(reinterpret_cast<char*>(packed_.data()), r.data_len,
                                         reinterpret_cast<char*>(records_.data()), &produced);
        small = rc == ROSLZ4_OUTPUT_SMALL;
        rc = rc == ROSLZ4_OK ? 0 : rc;
      } else {
        rc = BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(records_.data()), &produced,
                                        reinterpret_cast<char*>(packed_.data()), r.data_len, 0, 0);
        small = rc == BZ_OUTBUFF_FULL;
        rc = rc == BZ_OK ? 0 : rc;
      }
      if (small && room < declared) {
        room = std::min<std::uint64_t>(declared, 2 * room);
        continue;
      }
      if (small) fail(r.pos, "chunk", compression + " data decompresses to more than the declared size " + std::to_string(declared));
      if (rc != 0) fail(r.pos, "chunk", compression + " data does not decompress (error " + std::to_string(rc) + ")");
      if (produced != declared)
        fail(r.pos, "chunk", compression + " data decompresses to " + std::to_string(produced) +
                                 " bytes, the chunk header says " + std::to_string(declared));
      records_.resize(produced);
      return;
    }
  }

  void check_chunk(const Record& r) {
    const std::string compression = r.fields.count("compression") ? r.fields.at("compression") : "";
    const std::uint64_t declared = field(r, "size", 4);
    if (compression != "none" && compression != "lz4" && compression != "bz2")
      fail(r.pos, "chunk", "unknown compression '" + compression + "' (none, lz4, bz2)");
    if (compression == "none" && declared != r.data_len)
      fail(r.pos, "chunk", "uncompressed chunk of " + std::to_string(r.data_len) + " bytes declares size " + std::to_string(declared));
    if (declared > kMaxChunkBytes)
      fail(r.pos, "chunk", "declared size " + std::to_string(declared) + " exceeds the " + std::to_string(kMaxChunkBytes) + "-byte limit");
    decompress(r, compression, declared);
    // Where rosbag may read a message in this chunk: message data records only.
    std::set<std::uint64_t>& messages = chunk_messages_[r.pos];
    Fields f;
    for (std::uint64_t p = 0; p < records_.size();) {
      std::uint64_t header_len = 0, data_len = 0;
      if (!frame(records_.data(), records_.size(), p, header_len, data_len))
        fail(r.pos, "chunk", "record at byte " + std::to_string(p) + " of its data overruns the chunk");
      parse_fields(records_.data() + p + 4, header_len, r.data_pos, f);
      const std::uint8_t op = op_of(f, r.data_pos);
      if (op == kMessageData) messages.insert(p);
      if (op == kConnection) parse_fields(records_.data() + p + 8 + header_len, data_len, r.data_pos, f);
      p += 8 + header_len + data_len;
    }
    last_chunk_ = r.pos;
  }

  // rosbag parses a connection record's data as header fields too (the
  // connection header: type, md5sum, message_definition).
  void check_connection(const Record& r) {
    header_.resize(r.data_len);
    read(r.data_pos, header_.data(), r.data_len);
    Fields f;
    parse_fields(header_.data(), r.data_len, r.data_pos, f);
  }

  void check_index(const Record& r, const std::vector<Record>& records) {
    if (field(r, "ver", 4) != 1) fail(r.pos, "index data", "version is not 1");
    const std::uint64_t count = field(r, "count", 4);
    field(r, "conn", 4);
    if (count * 12 != r.data_len) fail(r.pos, "index data", "data length does not match its count");
    (void)records;
    const auto it = chunk_messages_.find(last_chunk_);
    if (it == chunk_messages_.end()) fail(r.pos, "index data", "no chunk before it");
    std::vector<std::uint8_t> data(r.data_len);
    read(r.data_pos, data.data(), r.data_len);
    for (std::uint64_t i = 0; i < count; ++i) {
      const std::uint64_t offset = le(data.data() + 12 * i + 8, 4);
      if (!it->second.count(offset))
        fail(r.pos, "index data", "entry " + std::to_string(i) + " points at byte " + std::to_string(offset) +
                                      " of its chunk, which is not a message record");
    }
  }

  void check_chunk_info(const Record& r) {
    if (field(r, "ver", 4) != 1) fail(r.pos, "chunk info", "version is not 1");
    const std::uint64_t chunk_pos = field(r, "chunk_pos", 8);
    const std::uint64_t count = field(r, "count", 4);
    if (count * 8 != r.data_len) fail(r.pos, "chunk info", "data length does not match its count");
    if (!chunk_messages_.count(chunk_pos))
      fail(r.pos, "chunk info", "chunk_pos " + std::to_string(chunk_pos) + " is not the start of a chunk");
    chunk_connections_[chunk_pos] = count;
  }

  // rosbag reads conn_count connections and chunk_count chunk infos from
  // index_pos on, then after each chunk one index record per connection.
  void check_index_section(const std::vector<Record>& records) {
    const Record& h = records.front();
    const std::uint64_t index_pos = field(h, "index_pos", 8);
    const std::uint64_t conns = field(h, "conn_count", 4), chunks = field(h, "chunk_count", 4);
    if (index_pos == 0) return;  // not indexed: rosbag says so
    const auto at = record_index_.find(index_pos);
    if (at == record_index_.end()) fail(h.pos, "bag header", "index_pos " + std::to_string(index_pos) + " is not the start of a record");
    if (records.size() - at->second < conns + chunks)
      fail(index_pos, "index", "fewer records than the bag header's conn_count + chunk_count");
    for (std::uint64_t i = 0; i < conns + chunks; ++i) {
      const Record& r = records[at->second + i];
      if (r.op != (i < conns ? kConnection : kChunkInfo))
        fail(r.pos, "index", i < conns ? "expected a connection record" : "expected a chunk info record");
    }
    for (const auto& [chunk_pos, count] : chunk_connections_) {
      const std::size_t k = record_index_.at(chunk_pos);
      for (std::uint64_t i = 1; i <= count; ++i)
        if (k + i >= records.size() || records[k + i].op != kIndexData)
          fail(chunk_pos, "chunk", "fewer index records after it than its chunk info counts");
    }
  }

  std::string file_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
  std::vector<std::uint8_t> header_, packed_, records_;
  std::map<std::uint64_t, std::size_t> record_index_;               // record start -> index in the scan
  std::map<std::uint64_t, std::set<std::uint64_t>> chunk_messages_;  // chunk start -> message offsets in it
  std::map<std::uint64_t, std::uint64_t> chunk_connections_;        // chunk start -> connections (chunk info)
  std::uint64_t last_chunk_ = 0;
};

}  // namespace

void check_bag_structure(const std::filesystem::path& path) { Checker(path).run(); }

}  // namespace rcm::ros1
