#pragma once
// JSON files crossing the disk: parse with located errors, write atomically.

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

namespace rcm {

// Parses a JSON file; a syntax error is reported as "file:line: column c: ...".
nlohmann::json load_json_file(const std::filesystem::path& path);

// Writes `text` to `path` through a temporary file in the same directory and a
// rename, so that a reader never sees a half-written file.
void write_file_atomic(const std::filesystem::path& path, const std::string& text);

// Pretty-printed JSON (2-space indent, trailing newline), atomically.
void save_json_file(const std::filesystem::path& path, const nlohmann::json& value);

// Reads a whole text file; throws InputError when it cannot be opened.
std::string read_text_file(const std::filesystem::path& path);

}  // namespace rcm
