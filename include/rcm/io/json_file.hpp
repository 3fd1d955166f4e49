#pragma once
// JSON files crossing the disk: parse with located errors, write atomically
// (rcm/io/atomic_file.hpp).

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "rcm/common/text_file.hpp"  // read_text_file
#include "rcm/io/atomic_file.hpp"

namespace rcm {

// Parses a JSON file; a syntax error is reported as "file:line: column c: ...".
nlohmann::json load_json_file(const std::filesystem::path& path);

// Pretty-printed JSON (2-space indent, trailing newline), atomically.
void save_json_file(const std::filesystem::path& path, const nlohmann::json& value);

}  // namespace rcm
