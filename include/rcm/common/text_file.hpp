#pragma once
// Reading a whole input file, with the error every reader reports the same way.
// Bottom layer: the robot description (kinematics) and every io reader use it.

#include <filesystem>
#include <string>

namespace rcm {

// Reads a whole text file; throws InputError when it is missing, a directory
// or cannot be opened.
std::string read_text_file(const std::filesystem::path& path);

}  // namespace rcm
