#include "io/rosbag2/mcap_reader.hpp"

// The MCAP reader (rosbag2's .mcap storage): the file's records in order,
// chunks decompressed (zstd, lz4) and checked against their CRCs, the messages
// of the wanted channels handed on. The records' layout and the CRC are in
// mcap_records.cpp.

#include <algorithm>
#include <fstream>
#include <memory>
#include <system_error>
#include <unordered_map>
#include <utility>

#include "io/rosbag2/mcap_records.hpp"
#include "rcm/common/error.hpp"

namespace rcm::mcap {
namespace {

using namespace detail;

}  // namespace

class Cursor::Reader {
 public:
  Reader(const std::filesystem::path& path, std::function<bool(const Channel&)> wanted)
      : path_(path.string()), wanted_(std::move(wanted)) {
    open();
  }

  // The next message of a wanted channel, in file order; false at the end
  // (then the summary and footer have been checked).
  bool next(MessageRef& m) {
    while (true) {
      if (in_chunk_) {
        if (next_in_chunk(m)) return true;
        in_chunk_ = false;
        ++result_.chunks;
      }
      if (done_) return false;
      if (!step(m)) continue;
      return true;
    }
  }
  const ReadResult& result() const { return result_; }

 private:
  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw InputError(InputLocation::plain(path_, where), what);
  }
  [[noreturn]] void fail(const Where& where, const std::string& what) const { fail(where.str(), what); }
  static Where at_record(std::uint64_t offset, std::uint8_t op) { return Where{offset, op, false, 0}; }

  void read(std::uint8_t* dst, std::uint64_t n) {
    in_.read(reinterpret_cast<char*>(dst), static_cast<std::streamsize>(n));
    if (static_cast<std::uint64_t>(in_.gcount()) != n)
      fail(at(pos_, "read"), "cannot read " + std::to_string(n) + " bytes (file changed or I/O error)");
    if (data_crc_on_) data_crc_ = crc32_update(data_crc_, dst, n);
    pos_ += n;
  }
  // Reads rather than seeks: skipped bytes still count in the data-section CRC
  // (and in `crc` when given).
  void skip(std::uint64_t n, std::uint32_t* crc = nullptr) {
    block_.resize(kReadBlock);
    while (n > 0) {
      const std::uint64_t k = std::min<std::uint64_t>(n, block_.size());
      read(block_.data(), k);
      if (crc) *crc = crc32_update(*crc, block_.data(), k);
      n -= k;
    }
  }
  void seek(std::uint64_t offset) {
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(offset));
    pos_ = offset;
  }
  const std::uint8_t* read_body(std::uint64_t len, std::uint64_t offset, std::uint8_t op) {
    if (len > kMaxRecordBytes)
      fail(at_record(offset, op),
           "record length " + std::to_string(len) + " exceeds the " + std::to_string(kMaxRecordBytes) + "-byte limit");
    grow(body_, len);
    read(body_.data(), len);
    return body_.data();
  }

  void open() {
    std::error_code ec;
    size_ = std::filesystem::file_size(path_, ec);
    in_.open(path_, std::ios::binary);
    if (ec || !in_) fail(std::string(), "cannot open the file (" + (ec ? ec.message() : "not readable") + ")");
    std::uint8_t magic[8] = {};
    const std::uint64_t have = std::min<std::uint64_t>(size_, sizeof magic);
    read(magic, have);
    if (size_ == 0) fail(at(0, "leading magic"), "empty file, not an MCAP file");
    if (!std::equal(magic, magic + std::min<std::uint64_t>(have, 5), kMagic))
      fail(at(0, "leading magic"), "not an MCAP file (it does not start with \\x89MCAP)");
    if (have < sizeof magic)
      fail(at(0, "leading magic"), "the file ends inside the leading magic (" + std::to_string(size_) + " bytes)");
    if (magic[5] != kMagic[5])
      fail(at(5, "leading magic"), "unsupported MCAP version " +
                                       quote_token(std::string(1, static_cast<char>(magic[5]))) +
                                       " (this reader knows version '0')");
    if (!std::equal(magic + 6, magic + 8, kMagic + 6))
      fail(at(6, "leading magic"), "not an MCAP file (leading magic ends wrong)");

    // A Footer and trailing magic at the very end mean the writer finished: from
    // then on every inconsistency is corruption, never truncation.
    if (size_ >= sizeof magic + kTail) {
      std::uint8_t tail[kTail];
      seek(size_ - kTail);
      data_crc_on_ = false;
      read(tail, kTail);
      complete_ = tail[0] == kFooter && le(tail + 1, 8) == kFooterBody &&
                  std::equal(tail + kPrefix + kFooterBody, tail + kTail, kMagic);
      seek(sizeof magic);
      data_crc_on_ = true;
    }
    end_ = complete_ ? size_ - kTail : size_;
  }

  // `cut` names what the end of the file interrupts, empty at a record boundary.
  void truncated_at(std::uint64_t record_start, const std::string& cut) {
    result_.truncated = true;
    result_.truncation = "the file ends at byte " + std::to_string(size_) +
                         (cut.empty() ? " after a complete record"
                                      : " inside " + cut + " starting at byte " + std::to_string(record_start)) +
                         " (no complete Footer: the recorder did not finish); read " +
                         std::to_string(result_.messages) + " messages in " + std::to_string(result_.chunks) +
                         " complete chunks and the records before byte " + std::to_string(record_start);
  }

  // One record of the data section (a message of a wanted channel: true, in
  // `m`); at its end, the checks of the whole file, and done_.
  bool step(MessageRef& m) {
    const std::uint64_t start = pos_;
    const std::uint32_t crc_before = data_crc_;
    if (complete_ && start == end_) {
      finish_data();
      return false;
    }
    if (end_ - start < kPrefix) {
      truncated_at(start, start == size_ ? "" : "a record header");
      done_ = true;
      return false;
    }
    std::uint8_t prefix[kPrefix];
    read(prefix, kPrefix);
    const std::uint8_t op = prefix[0];
    const std::uint64_t len = le(prefix + 1, 8);
    if (len > end_ - pos_) {
      if (complete_)
        fail(at_record(start, op), "record length " + std::to_string(len) + " runs past the Footer at byte " +
                                       std::to_string(end_) + ": the file is corrupt");
      truncated_at(start, "the " + record_name(op) + " record");
      done_ = true;
      return false;
    }
    if (!seen_header_ && op != kHeader) fail(at_record(start, op), "expected the Header record right after the magic");
    switch (op) {
      case kHeader: {
        if (seen_header_) fail(at_record(start, op), "second Header record");
        seen_header_ = true;
        Fields f(read_body(len, start, op), len);
        result_.profile = f.str();
        result_.library = f.str();
        if (!f.ok()) fail(at_record(start, op), "record too short for its profile and library");
        break;
      }
      case kSchema: declare_schema(read_body(len, start, op), len, at_record(start, op)); break;
      case kChannel: declare_channel(read_body(len, start, op), len, at_record(start, op)); break;
      case kMessage:
      case kChunk:
        if (in_summary_) fail(at_record(start, op), "record after DataEnd, in the summary section");
        if (op == kMessage) return read_file_message(start, len, m);
        read_chunk(start, len);
        break;
      case kDataEnd: {
        if (in_summary_) fail(at_record(start, op), "second DataEnd record");
        Fields f(read_body(len, start, op), len);
        const auto expected = static_cast<std::uint32_t>(f.uint(4));
        if (!f.ok()) fail(at_record(start, op), "record too short for data_section_crc");
        // The reference writers start this CRC at the leading magic, not after the Header.
        if (expected != 0 && expected != crc_before)
          fail(at_record(start, op), "data section CRC mismatch: DataEnd says " + hex32(expected) + ", bytes 0.." +
                                         std::to_string(start) + " give " + hex32(crc_before));
        in_summary_ = true;
        data_crc_on_ = false;
        summary_begin_ = pos_;
        break;
      }
      case kFooter:
        if (complete_) fail(at_record(start, op), "Footer record before the end of the file");
        skip(len);
        result_.truncated = true;
        result_.truncation = "the file ends at byte " + std::to_string(size_) +
                             " without its trailing magic after the Footer at byte " + std::to_string(start) +
                             "; all " + std::to_string(result_.messages) + " messages were read";
        done_ = true;
        return false;
      default: skip(len);  // indexes, attachments, metadata, statistics, future opcodes
    }
    return false;
  }

  void finish_data() {
    done_ = true;
    if (!seen_header_) fail(at(sizeof kMagic, "Header record"), "no Header record before the Footer");
    // The spec ends every data section with DataEnd; without it a corrupt opcode
    // could hide the data-section CRC.
    if (!in_summary_) fail(at(end_, "Footer record"), "no DataEnd record before the Footer");
    read_footer();
  }

  void read_footer() {
    const std::uint64_t start = pos_;
    std::uint8_t tail[kPrefix + kFooterBody];
    read(tail, sizeof tail);
    const std::uint64_t summary_start = le(tail + kPrefix, 8);
    const std::uint64_t summary_offset_start = le(tail + kPrefix + 8, 8);
    const auto expected = static_cast<std::uint32_t>(le(tail + kPrefix + 16, 4));
    if (summary_start > start || summary_offset_start > start)
      fail(at_record(start, kFooter), "summary_start " + std::to_string(summary_start) + " or summary_offset_start " +
                                          std::to_string(summary_offset_start) + " lies past the Footer");
    result_.has_summary = summary_start != 0;
    if (expected == 0) return;
    // The summary CRC runs from the summary section (or, without one, from the end
    // of DataEnd) through the Footer's summary_offset_start field.
    const std::uint64_t begin = summary_start != 0 ? summary_start : summary_begin_ != 0 ? summary_begin_ : start;
    const std::uint64_t end = start + kPrefix + 16;
    std::uint32_t crc = 0;
    seek(begin);
    skip(end - begin, &crc);
    if (crc != expected)
      fail(at_record(start, kFooter), "summary CRC mismatch: Footer says " + hex32(expected) + ", bytes " +
                                          std::to_string(begin) + ".." + std::to_string(end) + " give " + hex32(crc));
  }

  void declare_schema(const std::uint8_t* p, std::uint64_t n, const Where& where) {
    Fields f(p, n);
    const auto id = static_cast<std::uint16_t>(f.uint(2));
    std::string name = f.str(), encoding = f.str();
    f.skip_prefixed();
    if (!f.ok()) fail(where, "Schema record too short for its fields");
    if (id == 0) fail(where, "Schema id 0 is reserved for \"no schema\"");
    const auto it = schemas_.find(id);
    if (it == schemas_.end()) {
      schemas_.emplace(id, std::make_pair(std::move(name), std::move(encoding)));
    } else if (it->second.first != name || it->second.second != encoding) {
      fail(where, "Schema " + std::to_string(id) + " redeclared as " + quote_token(name) + " (was " +
                      quote_token(it->second.first) + ")");
    }
  }

  void declare_channel(const std::uint8_t* p, std::uint64_t n, const Where& where) {
    Fields f(p, n);
    Channel c;
    c.id = static_cast<std::uint16_t>(f.uint(2));
    c.schema_id = static_cast<std::uint16_t>(f.uint(2));
    c.topic = f.str();
    c.message_encoding = f.str();
    f.skip_prefixed();
    if (!f.ok()) fail(where, "Channel record too short for its fields");
    if (c.schema_id != 0) {
      const auto s = schemas_.find(c.schema_id);
      if (s == schemas_.end())
        fail(where, "Channel " + std::to_string(c.id) + " (topic " + quote_token(c.topic) + ") names schema " +
                        std::to_string(c.schema_id) + ", which no earlier Schema record declares");
      c.schema_name = s->second.first;
      c.schema_encoding = s->second.second;
    }
    const auto it = channel_index_.find(c.id);
    if (it != channel_index_.end()) {
      const Channel& old = result_.channels[it->second];
      // Writers repeat channels in the summary and in every chunk that uses them.
      if (old.topic != c.topic || old.schema_id != c.schema_id || old.message_encoding != c.message_encoding)
        fail(where, "Channel " + std::to_string(c.id) + " redeclared as topic " + quote_token(c.topic) + " (was " +
                        quote_token(old.topic) + ")");
      return;
    }
    channel_index_.emplace(c.id, result_.channels.size());
    wanted_flags_.push_back(!wanted_ || wanted_(c));
    result_.channels.push_back(std::move(c));
  }

  // Returns the channel's index, or fails when no Channel record came first.
  std::size_t channel_of(std::uint16_t id, const Where& where) const {
    const auto it = channel_index_.find(id);
    if (it == channel_index_.end())
      fail(where, "Message on channel " + std::to_string(id) + ", which no earlier Channel record declares");
    return it->second;
  }

  void deliver(std::size_t channel, const std::uint8_t* fixed, const std::uint8_t* data, std::uint64_t size,
               std::uint64_t record_offset, std::uint64_t chunk_offset, MessageRef& m) {
    m.channel = &result_.channels[channel];
    m.sequence = static_cast<std::uint32_t>(le(fixed + 2, 4));
    m.log_time_ns = le(fixed + 6, 8);
    m.publish_time_ns = le(fixed + 14, 8);
    m.data = data;
    m.size = static_cast<std::size_t>(size);
    m.record_offset = record_offset;
    m.chunk_offset = chunk_offset;
  }

  bool read_file_message(std::uint64_t start, std::uint64_t len, MessageRef& m) {
    if (len < kMessageFixed) fail(at_record(start, kMessage), "record too short for its fields");
    std::uint8_t fixed[kMessageFixed];
    read(fixed, kMessageFixed);
    const std::size_t channel = channel_of(static_cast<std::uint16_t>(le(fixed, 2)), at_record(start, kMessage));
    ++result_.messages;
    const std::uint64_t size = len - kMessageFixed;
    if (!wanted_flags_[channel]) {
      skip(size);
      return false;
    }
    const std::uint8_t* data = read_body(size, start, kMessage);
    deliver(channel, fixed, data, size, start, 0, m);
    return true;
  }

  void read_chunk(std::uint64_t start, std::uint64_t len) {
    const Where where = at_record(start, kChunk);
    if (len < kChunkFixed + 8) fail(where, "record too short for its fields");
    std::uint8_t fixed[kChunkFixed];
    read(fixed, kChunkFixed);
    const std::uint64_t uncompressed_size = le(fixed + 16, 8);
    const auto expected_crc = static_cast<std::uint32_t>(le(fixed + 24, 4));
    const std::uint64_t name_len = le(fixed + 28, 4);
    if (name_len > len - kChunkFixed - 8)
      fail(where, "compression name of " + std::to_string(name_len) + " bytes overruns the record");
    std::string compression(name_len, '\0');
    read(reinterpret_cast<std::uint8_t*>(compression.data()), name_len);
    std::uint8_t records_len_bytes[8];
    read(records_len_bytes, 8);
    const std::uint64_t records_len = le(records_len_bytes, 8);
    const std::uint64_t spare = len - kChunkFixed - name_len - 8;
    if (records_len > spare) fail(where, "records length " + std::to_string(records_len) + " overruns the record");
    if (!compression.empty() && compression != "zstd" && compression != "lz4")
      fail(where,
           "unsupported chunk compression " + quote_token(compression) + " (supported: none, \"lz4\", \"zstd\")");
    if (uncompressed_size > kMaxRecordBytes)
      fail(where, "uncompressed_size " + std::to_string(uncompressed_size) + " exceeds the " +
                      std::to_string(kMaxRecordBytes) + "-byte limit");
    if (compression.empty() && uncompressed_size != records_len)
      fail(where, "uncompressed chunk holds " + std::to_string(records_len) + " bytes but uncompressed_size says " +
                      std::to_string(uncompressed_size));
    const std::uint64_t produced = decompress(compression, records_len, uncompressed_size, where);
    if (produced != uncompressed_size)
      fail(where, compression + " data decompresses to " +
                      (produced > uncompressed_size ? "more than" : std::to_string(produced)) +
                      " bytes, uncompressed_size says " + std::to_string(uncompressed_size));
    skip(spare - records_len);  // fields added by later spec revisions
    if (expected_crc != 0) {
      const std::uint32_t crc = crc32_update(0, records_.data(), uncompressed_size);
      if (crc != expected_crc)
        fail(where, "chunk CRC mismatch: uncompressed_crc says " + hex32(expected_crc) +
                        ", the decompressed records give " + hex32(crc));
    }
    chunk_start_ = start;
    chunk_size_ = uncompressed_size;
    chunk_pos_ = 0;
    in_chunk_ = true;
  }

  // Decompresses into records_, growing it only as output actually arrives, so
  // that a corrupt uncompressed_size cannot trigger a huge allocation. Room for
  // one byte more than declared detects data that decompresses to too much.
  std::uint64_t decompress(const std::string& compression, std::uint64_t in_len, std::uint64_t declared,
                           const Where& where) {
    if (compression.empty()) {
      grow(records_, declared);
      read(records_.data(), declared);
      return declared;
    }
    const bool zstd = compression == "zstd";
    if (zstd && !zstd_) zstd_.reset(ZSTD_createDCtx());
    if (!zstd && !lz4_) {
      LZ4F_dctx* ctx = nullptr;
      if (!LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) lz4_.reset(ctx);
    }
    if (zstd ? !zstd_ : !lz4_) fail(where, "cannot create a " + compression + " decoder");
    if (zstd)
      ZSTD_DCtx_reset(zstd_.get(), ZSTD_reset_session_only);
    else
      LZ4F_resetDecompressionContext(lz4_.get());
    const std::uint64_t limit = declared + 1;
    const std::uint64_t first = std::min<std::uint64_t>(limit, std::max<std::uint64_t>(4 * in_len, kReadBlock));
    grow(records_, first);
    packed_.resize(kReadBlock);
    std::uint64_t produced = 0, left = in_len;
    std::size_t in_pos = 0, in_end = 0, pending = 1;  // pending == 0: the frame is complete
    while (true) {
      if (in_pos == in_end && left > 0) {
        in_end = static_cast<std::size_t>(std::min<std::uint64_t>(left, packed_.size()));
        read(packed_.data(), in_end);
        left -= in_end;
        in_pos = 0;
      }
      if (produced == records_.size() && produced < limit) grow(records_, std::min(limit, 2 * produced));
      const std::uint64_t room = std::min<std::uint64_t>(limit, records_.size()) - produced;
      if (room == 0) break;
      std::size_t wrote = 0;
      if (zstd) {
        ZSTD_inBuffer ib{packed_.data(), in_end, in_pos};
        ZSTD_outBuffer ob{records_.data() + produced, static_cast<std::size_t>(room), 0};
        pending = ZSTD_decompressStream(zstd_.get(), &ob, &ib);
        if (ZSTD_isError(pending)) fail(where, std::string("zstd decompression failed: ") + ZSTD_getErrorName(pending));
        in_pos = ib.pos;
        wrote = ob.pos;
      } else {
        std::size_t dst = static_cast<std::size_t>(room), src = in_end - in_pos;
        pending = LZ4F_decompress(lz4_.get(), records_.data() + produced, &dst, packed_.data() + in_pos, &src, nullptr);
        if (LZ4F_isError(pending)) fail(where, std::string("lz4 decompression failed: ") + LZ4F_getErrorName(pending));
        in_pos += src;
        wrote = dst;
      }
      produced += wrote;
      // The decoder stops short of the room it had only when it needs more input.
      if (in_pos == in_end && left == 0 && wrote < room) break;
    }
    if (produced <= declared && pending != 0)
      fail(where, compression + " data ends before the end of its frame (truncated or corrupt chunk)");
    return produced;
  }

  // The chunk's records from chunk_pos_ up to its next message of a wanted channel.
  bool next_in_chunk(MessageRef& m) {
    const std::uint64_t size = chunk_size_, chunk = chunk_start_;
    while (chunk_pos_ < size) {
      const std::uint64_t p = chunk_pos_;
      const std::uint8_t op = records_[p];
      const Where where{p, op, true, chunk};
      if (size - p < kPrefix) fail(where, "record header cut by the end of the chunk");
      const std::uint64_t len = le(&records_[p + 1], 8);
      if (len > size - p - kPrefix)
        fail(where, "record length " + std::to_string(len) + " runs past the end of the chunk");
      const std::uint8_t* body = records_.data() + p + kPrefix;
      chunk_pos_ = p + kPrefix + len;
      if (op == kSchema) {
        declare_schema(body, len, where);
      } else if (op == kChannel) {
        declare_channel(body, len, where);
      } else if (op == kMessage) {
        if (len < kMessageFixed) fail(where, "record too short for its fields");
        const std::size_t channel = channel_of(static_cast<std::uint16_t>(le(body, 2)), where);
        ++result_.messages;
        if (wanted_flags_[channel]) {
          deliver(channel, body, body + kMessageFixed, len - kMessageFixed, p, chunk, m);
          return true;
        }
      }
    }
    return false;
  }

  std::string path_;
  std::function<bool(const Channel&)> wanted_;
  std::ifstream in_;
  std::uint64_t size_ = 0, pos_ = 0;
  std::uint64_t end_ = 0;  // where records must end: the Footer, or the end of a cut file
  bool complete_ = false;  // the file ends with Footer + magic
  bool data_crc_on_ = true;
  std::uint32_t data_crc_ = 0;
  std::uint64_t summary_begin_ = 0;  // first byte after DataEnd
  bool seen_header_ = false, in_summary_ = false, done_ = false, in_chunk_ = false;
  // The decompressed chunk being read: its offset in the file, size, and the next record.
  std::uint64_t chunk_start_ = 0, chunk_size_ = 0, chunk_pos_ = 0;
  ReadResult result_;
  std::unordered_map<std::uint16_t, std::pair<std::string, std::string>> schemas_;  // name, encoding
  std::unordered_map<std::uint16_t, std::size_t> channel_index_;
  std::vector<bool> wanted_flags_;
  std::vector<std::uint8_t> records_, packed_, body_, block_;  // reused across records
  std::unique_ptr<ZSTD_DCtx, ZstdFree> zstd_;
  std::unique_ptr<LZ4F_dctx, Lz4Free> lz4_;
};

Cursor::Cursor(const std::filesystem::path& path, std::function<bool(const Channel&)> wanted)
    : reader_(std::make_unique<Reader>(path, std::move(wanted))) {}
Cursor::~Cursor() = default;
Cursor::Cursor(Cursor&&) noexcept = default;
bool Cursor::next(MessageRef& message) { return reader_->next(message); }
const ReadResult& Cursor::result() const { return reader_->result(); }

ReadResult read_mcap(const std::filesystem::path& path, const std::function<bool(const Channel&)>& wanted,
                     const std::function<void(const MessageRef&)>& on_message) {
  Cursor cursor(path, wanted);
  MessageRef m;
  while (cursor.next(m))
    if (on_message) on_message(m);
  return cursor.result();
}

}  // namespace rcm::mcap
