#pragma once
// Internal to io: the CSV reader behind open_recording() and
// open_recording_text() (csv_recording_reader.cpp).

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include "rcm/io/recording_reader.hpp"

namespace rcm::detail {

std::unique_ptr<RecordingReader> open_csv_recording(const std::filesystem::path& path,
                                                    const RecordingReadOptions& options, std::size_t chunk_rows);
std::unique_ptr<RecordingReader> open_csv_text(std::string text, const std::string& source,
                                               const RecordingReadOptions& options, std::size_t chunk_rows);

}  // namespace rcm::detail
