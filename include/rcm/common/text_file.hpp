#pragma once
// Reading a whole input file, with the error every reader reports the same way.
// Bottom layer: the robot description (kinematics) and every io reader use it.

#include <filesystem>
#include <string>

namespace rcm {

// Reads a whole text file; throws InputError when it is missing, a directory
// or cannot be opened.
std::string read_text_file(const std::filesystem::path& path);

// "fnv1a64:<16 hex digits>" of a file's bytes, or of a folder's regular files
// (their relative names and bytes, in name order: a rosbag2 folder). Tells
// whether a file a result was made from is still the same one; not a
// cryptographic hash. Throws InputError as read_text_file does.
std::string get_file_digest(const std::filesystem::path& path);

}  // namespace rcm
