#pragma once
// A check of a ROS 1 bag's structure (format 2.0) before rosbag_storage reads
// it. rosbag_storage trusts the file: it allocates whatever a record's length
// field says (4 GB for a flipped bit), decompresses a chunk into the size its
// header declares, and reads records at index offsets without checking them
// against the chunk. So before it opens a bag, every length is checked against
// the bytes it describes, every chunk is decompressed (growing the output only
// as data arrives) and must give exactly its declared size, and every position
// rosbag will seek to (index_pos, chunk_pos, message offsets in chunks) must
// be the start of a record of the kind it expects there.
#include <cstdint>
#include <filesystem>

namespace rcm::ros1 {

// Largest decompressed chunk accepted (rosbag writes chunks of 768 KiB; one
// message larger than that makes its chunk as large as the message).
inline constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{1} << 30;

// Throws InputError naming the file and the byte offset of the first defect.
void check_bag_structure(const std::filesystem::path& path);

}  // namespace rcm::ros1
