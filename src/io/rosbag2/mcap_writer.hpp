#pragma once
// Internal to io (the bag writer): an MCAP storage file (mcap.dev/spec,
// version 0) as rosbag2 writes it, chunked or not, compressed with zstd or lz4,
// with or without its summary and message indexes. The record layout (magic,
// opcodes) and the CRC-32 are the reader's (mcap_records.hpp).

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/rosbag2/mcap_records.hpp"
#include "io/rosbag2/message_definitions.hpp"
#include "rcm/io/rosbag2_writer.hpp"

namespace rcm::rosbag2::detail {

using mcap::detail::kMagic;
using namespace mcap::detail;  // the opcodes

// The CRC-32 of a byte stream fed in pieces.
class Crc32 {
 public:
  void update(const std::uint8_t* p, std::size_t n) { c_ = mcap::detail::crc32_update(c_, p, n); }
  std::uint32_t value() const { return c_; }

 private:
  std::uint32_t c_ = 0;
};

inline std::uint32_t crc32_of(const Bytes& b) { return mcap::detail::crc32_update(0, b.data(), b.size()); }

inline void put(Bytes& b, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void put_string(Bytes& b, const std::string& s) {
  put(b, s.size(), 4);
  b.insert(b.end(), s.begin(), s.end());
}
inline void put_record(Bytes& out, std::uint8_t op, const Bytes& body) {
  out.push_back(op);
  put(out, body.size(), 8);
  out.insert(out.end(), body.begin(), body.end());
}

inline Bytes compress(const std::string& compression, const Bytes& in) {
  Bytes out;
  if (compression == "zstd") {
    out.resize(ZSTD_compressBound(in.size()));
    const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 3);
    if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    out.resize(n);
  } else if (compression == "lz4") {
    // The LZ4 frame format (not the raw block format): MCAP's "lz4".
    LZ4F_preferences_t prefs{};
    prefs.frameInfo.contentSize = in.size();
    out.resize(LZ4F_compressFrameBound(in.size(), &prefs));
    const std::size_t n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
    if (LZ4F_isError(n)) throw std::runtime_error(std::string("lz4 compression failed: ") + LZ4F_getErrorName(n));
    out.resize(n);
  } else {
    out = in;
  }
  return out;
}

class McapFile {
 public:
  McapFile(const fs::path& path, const Rosbag2WriteOptions& o)
      : path_(path),
        compression_(o.mcap_chunked ? o.mcap_compression : ""),
        chunked_(o.mcap_chunked),
        chunk_bytes_(o.mcap_chunk_bytes),
        summary_(o.mcap_summary),
        message_indexes_(o.mcap_message_indexes) {
    out_.open(path, std::ios::binary | std::ios::trunc);
    if (!out_) throw std::runtime_error(path.string() + ": cannot create the file");
    emit(kMagic, sizeof kMagic);
    Bytes header, body;
    put_string(body, "ros2");
    put_string(body, "rcm");
    put_record(header, kHeader, body);
    emit(header);
  }

  // Channel ids count from 1 in the order of registration; one schema per type.
  std::uint16_t add_channel(const std::string& topic, const std::string& type) {
    std::uint16_t schema_id = 0;
    for (const Schema& s : schemas_)
      if (s.name == type) schema_id = s.id;
    if (schema_id == 0) {
      schema_id = static_cast<std::uint16_t>(schemas_.size() + 1);
      schemas_.push_back({schema_id, type, message_definition(type)});
    }
    const auto id = static_cast<std::uint16_t>(channels_.size() + 1);
    channels_.push_back({id, schema_id, topic, 0});
    return id;
  }

  void add_message(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                   std::uint64_t publish_time, const Bytes& data) {
    Channel& c = channels_.at(channel_id - 1);
    Bytes& out = chunked_ ? chunk_ : direct_;
    if (!chunked_) direct_.clear();
    // Every chunk declares what its messages use, so that a chunk reads on its
    // own (as the reference writers do); outside chunks, once per file.
    std::vector<bool>& declared = chunked_ ? chunk_declared_ : file_declared_;
    declared.resize(channels_.size() + 1);
    std::vector<bool>& schema_declared = chunked_ ? chunk_schema_declared_ : file_schema_declared_;
    schema_declared.resize(schemas_.size() + 1);
    if (!declared[channel_id]) {
      if (!schema_declared[c.schema_id]) {
        put_record(out, kSchema, schema_body(schemas_[c.schema_id - 1]));
        schema_declared[c.schema_id] = true;
      }
      put_record(out, kChannel, channel_body(c));
      declared[channel_id] = true;
    }
    const std::uint64_t offset = out.size();
    out.push_back(kMessage);
    put(out, 2 + 4 + 8 + 8 + data.size(), 8);
    put(out, channel_id, 2);
    put(out, sequence, 4);
    put(out, log_time, 8);
    put(out, publish_time, 8);
    out.insert(out.end(), data.begin(), data.end());

    ++c.messages;
    ++messages_;
    start_time_ = std::min(start_time_, log_time);
    end_time_ = std::max(end_time_, log_time);
    if (!chunked_) {
      emit(out);
      return;
    }
    chunk_start_ = std::min(chunk_start_, log_time);
    chunk_end_ = std::max(chunk_end_, log_time);
    chunk_index_[channel_id].push_back({log_time, offset});
    if (chunk_.size() >= chunk_bytes_) flush_chunk();
  }

  void finish() {
    if (chunked_ && !chunk_.empty()) flush_chunk();
    // DataEnd: CRC of every byte before it, leading magic included.
    Bytes data_end, body;
    put(body, crc_.value(), 4);
    put_record(data_end, kDataEnd, body);
    emit(data_end);

    // The summary CRC covers the summary and summary offset sections and the
    // Footer up to its summary_crc field.
    crc_ = Crc32{};
    std::uint64_t summary_start = 0, summary_offset_start = 0;
    if (summary_) {
      summary_start = pos_;
      struct Group {
        std::uint8_t op;
        std::uint64_t start, length;
      };
      std::vector<Group> groups;
      auto group = [&](std::uint8_t op, const std::vector<Bytes>& bodies) {
        if (bodies.empty()) return;
        const std::uint64_t start = pos_;
        Bytes records;
        for (const Bytes& b : bodies) put_record(records, op, b);
        emit(records);
        groups.push_back({op, start, pos_ - start});
      };
      std::vector<Bytes> bodies;
      for (const Schema& s : schemas_) bodies.push_back(schema_body(s));
      group(kSchema, bodies);
      bodies.clear();
      for (const Channel& c : channels_) bodies.push_back(channel_body(c));
      group(kChannel, bodies);
      group(kStatistics, {statistics_body()});
      group(kChunkIndex, chunk_indexes_);
      summary_offset_start = pos_;
      Bytes offsets;
      for (const Group& g : groups) {
        Bytes b;
        b.push_back(g.op);
        put(b, g.start, 8);
        put(b, g.length, 8);
        put_record(offsets, kSummaryOffset, b);
      }
      emit(offsets);
    }
    Bytes footer;
    footer.push_back(kFooter);
    put(footer, 8 + 8 + 4, 8);
    put(footer, summary_start, 8);
    put(footer, summary_offset_start, 8);
    emit(footer);
    Bytes tail;
    put(tail, crc_.value(), 4);
    tail.insert(tail.end(), kMagic, kMagic + sizeof kMagic);
    emit(tail);
    out_.close();
    if (!out_) throw std::runtime_error(path_.string() + ": write failed");
  }

 private:
  struct Schema {
    std::uint16_t id;
    std::string name, data;
  };
  struct Channel {
    std::uint16_t id, schema_id;
    std::string topic;
    std::uint64_t messages;
  };

  static Bytes schema_body(const Schema& s) {
    Bytes b;
    put(b, s.id, 2);
    put_string(b, s.name);
    put_string(b, "ros2msg");
    put_string(b, s.data);  // uint32-length-prefixed bytes, like a string
    return b;
  }
  static Bytes channel_body(const Channel& c) {
    Bytes b, metadata;
    put(b, c.id, 2);
    put(b, c.schema_id, 2);
    put_string(b, c.topic);
    put_string(b, "cdr");
    put_string(metadata, "offered_qos_profiles");
    put_string(metadata, "");
    put(b, metadata.size(), 4);
    b.insert(b.end(), metadata.begin(), metadata.end());
    return b;
  }
  Bytes statistics_body() const {
    Bytes b, counts;
    put(b, messages_, 8);
    put(b, schemas_.size(), 2);
    put(b, channels_.size(), 4);
    put(b, 0, 4);  // attachments
    put(b, 0, 4);  // metadata
    put(b, chunk_indexes_.size(), 4);
    put(b, messages_ ? start_time_ : 0, 8);
    put(b, messages_ ? end_time_ : 0, 8);
    for (const Channel& c : channels_) {
      put(counts, c.id, 2);
      put(counts, c.messages, 8);
    }
    put(b, counts.size(), 4);
    b.insert(b.end(), counts.begin(), counts.end());
    return b;
  }

  void emit(const std::uint8_t* p, std::size_t n) {
    out_.write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(n));
    crc_.update(p, n);
    pos_ += n;
  }
  void emit(const Bytes& b) { emit(b.data(), b.size()); }

  void flush_chunk() {
    const Bytes packed = compress(compression_, chunk_);
    const std::uint64_t chunk_start = pos_;
    Bytes head;
    head.push_back(kChunk);
    put(head, 8 + 8 + 8 + 4 + 4 + compression_.size() + 8 + packed.size(), 8);
    put(head, chunk_start_, 8);
    put(head, chunk_end_, 8);
    put(head, chunk_.size(), 8);
    put(head, crc32_of(chunk_), 4);
    put_string(head, compression_);
    put(head, packed.size(), 8);
    emit(head);
    emit(packed);
    const std::uint64_t chunk_length = pos_ - chunk_start;

    Bytes offsets;  // message_index_offsets: channel id -> file offset of its MessageIndex
    const std::uint64_t index_start = pos_;
    if (message_indexes_) {
      for (const auto& [channel, entries] : chunk_index_) {
        put(offsets, channel, 2);
        put(offsets, pos_, 8);
        Bytes body, record;
        put(body, channel, 2);
        put(body, entries.size() * 16, 4);
        for (const auto& [log_time, offset] : entries) {
          put(body, log_time, 8);
          put(body, offset, 8);
        }
        put_record(record, kMessageIndex, body);
        emit(record);
      }
    }
    Bytes index;
    put(index, chunk_start_, 8);
    put(index, chunk_end_, 8);
    put(index, chunk_start, 8);
    put(index, chunk_length, 8);
    put(index, offsets.size(), 4);
    index.insert(index.end(), offsets.begin(), offsets.end());
    put(index, pos_ - index_start, 8);
    put_string(index, compression_);
    put(index, packed.size(), 8);
    put(index, chunk_.size(), 8);
    chunk_indexes_.push_back(std::move(index));

    chunk_.clear();
    chunk_index_.clear();
    chunk_declared_.assign(chunk_declared_.size(), false);
    chunk_schema_declared_.assign(chunk_schema_declared_.size(), false);
    chunk_start_ = UINT64_MAX;
    chunk_end_ = 0;
  }

  fs::path path_;
  std::string compression_;
  bool chunked_;
  std::size_t chunk_bytes_;
  bool summary_, message_indexes_;
  std::ofstream out_;
  std::uint64_t pos_ = 0;
  Crc32 crc_;  // of the data section, then of the summary
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::uint64_t messages_ = 0, start_time_ = UINT64_MAX, end_time_ = 0;
  std::vector<bool> file_declared_, file_schema_declared_;
  Bytes direct_;  // one record outside chunks
  // The open chunk: its records, times, and (log_time, offset) per channel.
  Bytes chunk_;
  std::vector<bool> chunk_declared_, chunk_schema_declared_;
  std::uint64_t chunk_start_ = UINT64_MAX, chunk_end_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::vector<Bytes> chunk_indexes_;  // ChunkIndex bodies for the summary
};

}  // namespace rcm::rosbag2::detail
