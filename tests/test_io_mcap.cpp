// The MCAP reader against files written by the reference implementation
// (@mcap/core, see tests/data/rosbag2/README.md), and against hostile copies of
// them: cut, bit-flipped, with absurd sizes. Cut files must read as truncated
// prefixes (a crashed recorder), corrupt complete files must fail with the byte
// offset, and nothing may crash or allocate what the file cannot back.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <new>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "io/rosbag2/mcap_reader.hpp"
#include "rcm/common/error.hpp"

// Largest single allocation and allocation count, to prove that corrupt sizes
// are not allocated and that the per-message path allocates nothing.
#include "counting_new.hpp"
using rcm::test::g_allocations;
using rcm::test::g_largest_allocation;

namespace {

namespace fs = std::filesystem;
using rcm::mcap::MessageRef;
using rcm::mcap::ReadResult;
using Bytes = std::vector<std::uint8_t>;

constexpr const char* kJointTopic = "/PSM1/measured_js";
constexpr const char* kWrenchTopic = "/PSM1/body/measured_cf";
constexpr std::uint64_t kT0 = 1'700'000'000'000'000'000ull;
constexpr std::size_t kJointStateBytes = 332;  // CDR of 7 named joints, empty frame_id
constexpr std::size_t kWrenchBytes = 76;       // CDR with frame_id "PSM1"

const char* const kFixtures[] = {"joint_states_unchunked.mcap", "joint_states_zstd.mcap", "joint_states_lz4.mcap",
                                 "joint_states_none.mcap", "joint_states_no_summary.mcap",
                                 "joint_states_unindexed.mcap"};

fs::path fixture(const std::string& name) { return fs::path(RCM_SOURCE_DIR) / "tests/data/rosbag2" / name; }

Bytes load(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::uint64_t le(const Bytes& b, std::size_t at, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | b.at(at + i);
  return v;
}
void put_le(Bytes& b, std::size_t at, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b.at(at + i) = static_cast<std::uint8_t>(v >> (8 * i));
}

struct Message {
  std::uint32_t sequence;
  std::uint64_t log_time, publish_time, record_offset, chunk_offset;
  Bytes data;
  bool operator==(const Message& o) const {
    return sequence == o.sequence && log_time == o.log_time && publish_time == o.publish_time && data == o.data;
  }
};

struct Read {
  ReadResult result;
  std::vector<Message> messages;
  int wanted_calls = 0;
};

Read read_topic(const fs::path& path, const std::string& topic) {
  Read r;
  r.result = rcm::mcap::read_mcap(
      path,
      [&](const rcm::mcap::Channel& c) {
        ++r.wanted_calls;
        return c.topic == topic;
      },
      [&](const MessageRef& m) {
        EXPECT_EQ(m.channel->topic, topic);
        r.messages.push_back({m.sequence, m.log_time_ns, m.publish_time_ns, m.record_offset, m.chunk_offset,
                              Bytes(m.data, m.data + m.size)});
      });
  return r;
}

// A scratch directory per test process, removed at exit.
class TempDir {
 public:
  TempDir() : dir_(fs::temp_directory_path() / ("rcm_test_io_mcap_" + std::to_string(::getpid()))) {
    fs::create_directories(dir_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path write(const std::string& name, const Bytes& bytes) const {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    return p;
  }

 private:
  fs::path dir_;
};

const TempDir& temp() {
  static const TempDir dir;
  return dir;
}

std::string error_of(const fs::path& path) {
  try {
    read_topic(path, kJointTopic);
  } catch (const rcm::InputError& e) {
    EXPECT_EQ(e.where().file, path.string());
    return e.what();
  }
  return "no error";
}

// Offset of the first Chunk record, read from where its messages say they are.
std::uint64_t first_chunk(const char* name) {
  const Read r = read_topic(fixture(name), kJointTopic);
  return r.messages.at(0).chunk_offset;
}

TEST(McapReader, EveryFixtureHoldsTheFiftyJointStatesInOrder) {
  for (const char* name : kFixtures) {
    SCOPED_TRACE(name);
    const Read r = read_topic(fixture(name), kJointTopic);
    EXPECT_EQ(r.result.profile, "ros2");
    EXPECT_FALSE(r.result.truncated) << r.result.truncation;
    EXPECT_EQ(r.result.messages, 70u);
    EXPECT_EQ(r.wanted_calls, 2);  // channels repeated in chunks and summary are declared once
    ASSERT_EQ(r.result.channels.size(), 2u);
    for (const auto& c : r.result.channels) {
      EXPECT_EQ(c.message_encoding, "cdr");
      EXPECT_EQ(c.schema_encoding, "ros2msg");
      EXPECT_EQ(c.schema_name,
                c.topic == kJointTopic ? "sensor_msgs/msg/JointState" : "geometry_msgs/msg/WrenchStamped");
    }
    const bool chunked = std::string(name) != "joint_states_unchunked.mcap";
    EXPECT_EQ(r.result.chunks > 1, chunked);
    EXPECT_EQ(r.result.has_summary, std::string(name) != "joint_states_no_summary.mcap");
    ASSERT_EQ(r.messages.size(), 50u);
    for (std::size_t k = 0; k < r.messages.size(); ++k) {
      const Message& m = r.messages[k];
      const std::uint64_t t = kT0 + k * 10'000'000ull;
      EXPECT_EQ(m.sequence, k);
      EXPECT_EQ(m.log_time, t);
      EXPECT_EQ(m.publish_time, t);
      EXPECT_EQ(m.chunk_offset != 0, chunked);
      ASSERT_EQ(m.data.size(), kJointStateBytes);
      EXPECT_EQ(Bytes(m.data.begin(), m.data.begin() + 4), (Bytes{0x00, 0x01, 0x00, 0x00}));
      // Decoding the stamp and one position checks the CDR layout written by the fixture tool.
      EXPECT_EQ(le(m.data, 4, 4), t / 1'000'000'000ull);
      EXPECT_EQ(le(m.data, 8, 4), t % 1'000'000'000ull);
      double position_2 = 0;
      const std::uint64_t bits = le(m.data, 4 + 144 + 16, 8);
      std::memcpy(&position_2, &bits, 8);
      EXPECT_NEAR(position_2, 0.3 + 0.001 * k, 1e-12);
    }
  }
}

TEST(McapReader, AllFixturesCarryIdenticalPayloads) {
  const Read reference = read_topic(fixture(kFixtures[0]), kJointTopic);
  for (const char* name : kFixtures) {
    SCOPED_TRACE(name);
    EXPECT_EQ(read_topic(fixture(name), kJointTopic).messages, reference.messages);
  }
}

TEST(McapReader, FilterSelectsTheWrenchTopic) {
  for (const char* name : kFixtures) {
    SCOPED_TRACE(name);
    const Read r = read_topic(fixture(name), kWrenchTopic);
    ASSERT_EQ(r.messages.size(), 20u);
    for (std::size_t k = 0; k < r.messages.size(); ++k) {
      EXPECT_EQ(r.messages[k].log_time, kT0 + k * 25'000'000ull);
      ASSERT_EQ(r.messages[k].data.size(), kWrenchBytes);
      EXPECT_EQ(std::string(r.messages[k].data.begin() + 16, r.messages[k].data.begin() + 21),
                std::string("PSM1\0", 5));
    }
  }
}

TEST(McapReader, PerMessagePathDoesNotAllocate) {
  for (const char* name : kFixtures) {
    SCOPED_TRACE(name);
    std::vector<long> counts;
    std::vector<std::uint64_t> chunks;
    counts.reserve(100);
    chunks.reserve(100);
    rcm::mcap::read_mcap(
        fixture(name), [](const rcm::mcap::Channel& c) { return c.topic == kJointTopic; },
        [&](const MessageRef& m) {
          counts.push_back(g_allocations.load());
          chunks.push_back(m.chunk_offset);
        });
    ASSERT_EQ(counts.size(), 50u);
    for (std::size_t k = 1; k < counts.size(); ++k) {
      if (chunks[k] == chunks[k - 1]) {
        EXPECT_EQ(counts[k] - counts[k - 1], 0) << "message " << k;
      }
    }
    EXPECT_LE(counts.back() - counts.front(), 2);  // buffers growing for a larger chunk
  }
}

TEST(McapReader, RejectsFilesThatAreNotMcap) {
  EXPECT_NE(error_of(temp().write("empty.mcap", {})).find("empty file"), std::string::npos);
  Bytes csv = {'t', ',', 'q', '0', '\n', '0', ',', '1', '\n', '1', ',', '2', '\n'};
  EXPECT_NE(error_of(temp().write("csv.mcap", csv)).find("not an MCAP file"), std::string::npos);
  Bytes v1 = load(fixture("joint_states_zstd.mcap"));
  v1[5] = '1';
  EXPECT_NE(error_of(temp().write("v1.mcap", v1)).find("unsupported MCAP version '1'"), std::string::npos);
}

// Every cut of a file is what a crashed recorder may leave: it must read as a
// prefix of the full recording, never fail past the magic, never invent data.
TEST(McapReader, EveryTruncationReadsAPrefix) {
  for (const char* name : kFixtures) {
    SCOPED_TRACE(name);
    const Bytes full = load(fixture(name));
    const std::vector<Message> all = read_topic(fixture(name), kJointTopic).messages;
    std::size_t previous = 0;
    std::vector<std::size_t> cuts;
    for (std::size_t cut = 0; cut < full.size(); cut += 97) cuts.push_back(cut);
    for (std::size_t back = 1; back <= 40; ++back) cuts.push_back(full.size() - back);
    for (const std::size_t cut : cuts) {
      SCOPED_TRACE("cut at " + std::to_string(cut));
      const fs::path p = temp().write("cut.mcap", Bytes(full.begin(), full.begin() + cut));
      if (cut < 8) {
        EXPECT_THROW(read_topic(p, kJointTopic), rcm::InputError);
        continue;
      }
      Read r;
      ASSERT_NO_THROW(r = read_topic(p, kJointTopic));
      EXPECT_TRUE(r.result.truncated);
      EXPECT_FALSE(r.result.truncation.empty());
      ASSERT_LE(r.messages.size(), all.size());
      EXPECT_TRUE(std::equal(r.messages.begin(), r.messages.end(), all.begin()));
      if (cut + 40 < full.size()) {
        EXPECT_GE(r.messages.size(), previous);  // more file, never fewer messages
      }
      previous = r.messages.size();
    }
  }
}

TEST(McapReader, CutFileKeepsTheCompleteChunks) {
  const Bytes full = load(fixture("joint_states_zstd.mcap"));
  const std::vector<Message> all = read_topic(fixture("joint_states_zstd.mcap"), kJointTopic).messages;
  std::vector<std::uint64_t> chunks;
  for (const Message& m : all)
    if (chunks.empty() || chunks.back() != m.chunk_offset) chunks.push_back(m.chunk_offset);
  ASSERT_GE(chunks.size(), 3u);

  // Footer cut: every chunk is complete.
  Read r = read_topic(temp().write("no_footer.mcap", Bytes(full.begin(), full.end() - 12)), kJointTopic);
  EXPECT_TRUE(r.result.truncated);
  EXPECT_EQ(r.messages.size(), 50u);

  // Cut in the middle of the third chunk: the first two chunks only.
  const std::size_t cut = chunks[2] + 100;
  r = read_topic(temp().write("mid_chunk.mcap", Bytes(full.begin(), full.begin() + cut)), kJointTopic);
  EXPECT_TRUE(r.result.truncated);
  EXPECT_EQ(r.result.chunks, 2u);
  std::size_t in_first_two = 0;
  for (const Message& m : all) in_first_two += m.chunk_offset < chunks[2];
  EXPECT_EQ(r.messages.size(), in_first_two);
  EXPECT_NE(r.result.truncation.find("Chunk record starting at byte " + std::to_string(chunks[2])), std::string::npos)
      << r.result.truncation;
}

TEST(McapReader, FlippedChunkDataIsAnErrorAtTheChunk) {
  for (const char* name : {"joint_states_zstd.mcap", "joint_states_lz4.mcap", "joint_states_none.mcap"}) {
    SCOPED_TRACE(name);
    const std::uint64_t chunk = first_chunk(name);
    Bytes bytes = load(fixture(name));
    const std::uint64_t data = chunk + 9 + 32 + le(bytes, chunk + 9 + 28, 4) + 8;
    bytes[data + 40] ^= 0x5a;
    const std::string error = error_of(temp().write("flipped.mcap", bytes));
    EXPECT_NE(error.find("byte " + std::to_string(chunk) + " (Chunk record)"), std::string::npos) << error;
  }
}

TEST(McapReader, FlippedChunkCrcIsACrcError) {
  const std::uint64_t chunk = first_chunk("joint_states_lz4.mcap");
  Bytes bytes = load(fixture("joint_states_lz4.mcap"));
  bytes[chunk + 9 + 24] ^= 0x01;
  const std::string error = error_of(temp().write("crc.mcap", bytes));
  EXPECT_NE(error.find("chunk CRC mismatch"), std::string::npos) << error;
  EXPECT_NE(error.find("byte " + std::to_string(chunk)), std::string::npos) << error;
}

TEST(McapReader, UnknownCompressionIsNamed) {
  const std::uint64_t chunk = first_chunk("joint_states_zstd.mcap");
  Bytes bytes = load(fixture("joint_states_zstd.mcap"));
  std::memcpy(&bytes[chunk + 9 + 32], "brot", 4);
  const std::string error = error_of(temp().write("brot.mcap", bytes));
  EXPECT_NE(error.find("unsupported chunk compression 'brot'"), std::string::npos) << error;
}

TEST(McapReader, AbsurdSizesFailWithoutGiantAllocations) {
  const std::uint64_t chunk = first_chunk("joint_states_zstd.mcap");
  const Bytes original = load(fixture("joint_states_zstd.mcap"));
  const auto error_and_peak = [](const Bytes& bytes) {
    const fs::path p = temp().write("absurd.mcap", bytes);
    g_largest_allocation = 0;
    const std::string error = error_of(p);
    return std::make_pair(error, g_largest_allocation.load());
  };

  Bytes huge_record = original;
  put_le(huge_record, chunk + 1, 0xfffffffffffff000ull, 8);
  auto [error, peak] = error_and_peak(huge_record);
  EXPECT_NE(error.find("runs past the Footer"), std::string::npos) << error;
  EXPECT_LT(peak, 1u << 20);

  Bytes huge_chunk = original;
  put_le(huge_chunk, chunk + 9 + 16, std::uint64_t{1} << 40, 8);
  std::tie(error, peak) = error_and_peak(huge_chunk);
  EXPECT_NE(error.find("exceeds"), std::string::npos) << error;
  EXPECT_LT(peak, 1u << 20);

  // Below the limit but far above what the data decompresses to: output buffers
  // grow only as data arrives.
  Bytes lying_chunk = original;
  put_le(lying_chunk, chunk + 9 + 16, 900u << 20, 8);
  std::tie(error, peak) = error_and_peak(lying_chunk);
  EXPECT_NE(error.find("uncompressed_size says 943718400"), std::string::npos) << error;
  EXPECT_LT(peak, 1u << 20);

  Bytes long_string = load(fixture("joint_states_unchunked.mcap"));
  put_le(long_string, 8 + 9, 0xfffffff0u, 4);  // Header profile length
  std::tie(error, peak) = error_and_peak(long_string);
  EXPECT_NE(error.find("byte 8 (Header record)"), std::string::npos) << error;
  EXPECT_LT(peak, 1u << 20);
}

TEST(McapReader, DataAndSummaryCrcsAreChecked) {
  const fs::path unchunked = fixture("joint_states_unchunked.mcap");
  const Read r = read_topic(unchunked, kJointTopic);
  Bytes payload = load(unchunked);
  payload[r.messages[10].record_offset + 9 + 22 + 200] ^= 0x10;
  std::string error = error_of(temp().write("payload.mcap", payload));
  EXPECT_NE(error.find("data section CRC mismatch"), std::string::npos) << error;

  Bytes summary = load(unchunked);
  summary[summary.size() - 38] ^= 0x01;  // last byte of the last SummaryOffset record
  error = error_of(temp().write("summary.mcap", summary));
  EXPECT_NE(error.find("summary CRC mismatch"), std::string::npos) << error;
}

TEST(McapReader, UndeclaredChannelsAndSchemasAreErrors) {
  const fs::path unchunked = fixture("joint_states_unchunked.mcap");
  const Read r = read_topic(unchunked, kJointTopic);
  Bytes channel = load(unchunked);
  put_le(channel, r.messages[0].record_offset + 9, 77, 2);
  std::string error = error_of(temp().write("channel.mcap", channel));
  EXPECT_NE(error.find("Message on channel 77"), std::string::npos) << error;
  EXPECT_NE(error.find("byte " + std::to_string(r.messages[0].record_offset) + " (Message record)"), std::string::npos);

  Bytes schema = load(unchunked);
  const std::string topic = kJointTopic;
  const auto at = std::search(schema.begin(), schema.end(), topic.begin(), topic.end()) - schema.begin();
  put_le(schema, at - 4 - 2, 99, 2);
  error = error_of(temp().write("schema.mcap", schema));
  EXPECT_NE(error.find("names schema 99"), std::string::npos) << error;
}

TEST(McapReader, SkipsRecordsOfUnknownOpcode) {
  const Bytes original = load(fixture("joint_states_no_summary.mcap"));
  const std::size_t after_header = 8 + 9 + le(original, 9, 8);
  Bytes bytes(original.begin(), original.begin() + after_header);
  const Bytes unknown = {0x80, 5, 0, 0, 0, 0, 0, 0, 0, 'h', 'e', 'l', 'l', 'o'};
  bytes.insert(bytes.end(), unknown.begin(), unknown.end());
  bytes.insert(bytes.end(), original.begin() + after_header, original.end());
  // Without a summary the DataEnd record sits right before the Footer; its CRC
  // no longer matches the spliced data section, so declare it absent.
  const std::size_t data_end = bytes.size() - 37 - 13;
  ASSERT_EQ(bytes[data_end], 0x0f);
  put_le(bytes, data_end + 9, 0, 4);
  const Read r = read_topic(temp().write("unknown_opcode.mcap", bytes), kJointTopic);
  EXPECT_EQ(r.messages.size(), 50u);
  EXPECT_FALSE(r.result.truncated);
}

// A record longer than the fields this reader knows (a later spec version may
// append fields): the extra bytes are skipped, as the spec requires.
TEST(McapReader, ReadsRecordsPaddedBeyondTheirKnownFields) {
  const Bytes original = load(fixture("joint_states_no_summary.mcap"));
  ASSERT_EQ(original[8], 0x01);  // the Header record
  const std::uint64_t header_length = le(original, 9, 8);
  const std::size_t after_header = 8 + 9 + header_length;
  Bytes bytes(original.begin(), original.begin() + after_header);
  bytes.insert(bytes.end(), {0xde, 0xad, 0xbe, 0xef});
  put_le(bytes, 9, header_length + 4, 8);
  bytes.insert(bytes.end(), original.begin() + after_header, original.end());
  const std::size_t data_end = bytes.size() - 37 - 13;
  ASSERT_EQ(bytes[data_end], 0x0f);
  put_le(bytes, data_end + 9, 0, 4);  // the data CRC no longer matches: declared absent
  const Read r = read_topic(temp().write("padded.mcap", bytes), kJointTopic);
  EXPECT_EQ(r.messages.size(), 50u);
  EXPECT_EQ(r.messages, read_topic(fixture("joint_states_no_summary.mcap"), kJointTopic).messages);
  EXPECT_FALSE(r.result.truncated);
}

// Single-byte flips anywhere: a clean error or a correct (possibly shorter)
// read; with the sanitizers on, also no memory error.
TEST(McapReader, RandomByteFlipsNeverYieldGarbage) {
  std::mt19937 rng(20240611);
  for (const char* name : kFixtures) {
    SCOPED_TRACE(name);
    const Bytes original = load(fixture(name));
    const std::vector<Message> all = read_topic(fixture(name), kJointTopic).messages;
    for (int trial = 0; trial < 80; ++trial) {
      Bytes bytes = original;
      const std::size_t at = rng() % bytes.size();
      bytes[at] ^= static_cast<std::uint8_t>(1 + rng() % 255);
      SCOPED_TRACE("flip at " + std::to_string(at));
      const fs::path p = temp().write("flip.mcap", bytes);
      try {
        const Read r = read_topic(p, kJointTopic);
        ASSERT_LE(r.messages.size(), all.size());
        EXPECT_TRUE(std::equal(r.messages.begin(), r.messages.end(), all.begin()));
      } catch (const rcm::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("byte "), std::string::npos) << e.what();
      }
    }
  }
}

}  // namespace
