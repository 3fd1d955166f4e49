#pragma once
// Internal to io: the pieces of the CSV reader (src/io/recording.cpp) that
// every CSV layout rcm reads shares, so that a joint trajectory file
// (joint_trajectory.cpp) keeps the recording's rules and error wording:
// header on line 1, blank lines skipped, quoted fields, a located error for
// every cell that is not a finite number.

#include <cstddef>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "rcm/common/error.hpp"

namespace rcm::detail {

struct Column {
  std::size_t index = 0;  // field index in a row
  std::string name;
};

// Spaces, tabs and carriage returns off both ends.
std::string_view trim(std::string_view s);
// One CSV line into fields (views into `line`, quotes kept); quoted fields may hold commas.
void split_fields(std::string_view line, std::vector<std::string_view>& fields);
// The non-blank lines of `text` with their 1-based numbers.
std::vector<std::pair<std::size_t, std::string_view>> split_lines(std::string_view text);
// file:line: column `field`.
InputLocation locate(const std::string& source, std::size_t line, const std::string& field);
// Column name -> field index of a header row; a duplicate name is an InputError.
std::map<std::string, std::size_t> index_header(const std::vector<std::string_view>& fields,
                                                const std::string& source);
// prefix{first}, prefix{first + 1}, ... as far as they go; a later index
// without its predecessor is an InputError.
std::vector<Column> find_series(const std::map<std::string, std::size_t>& by_name, const std::string& prefix,
                                int first, const std::string& source);
// A finite number, or an InputError naming the line and column.
double parse_cell(std::string_view cell, const std::string& source, std::size_t line, const std::string& column);

}  // namespace rcm::detail
