#include "rcm/common/error.hpp"

#include <cstdio>

namespace rcm {

std::string InputLocation::to_string() const {
  std::string out = file.empty() ? std::string("<input>") : file;
  if (line > 0) out += ":" + std::to_string(line);
  if (!field.empty()) {
    // JSON paths read naturally after "field"; CSV columns after "column".
    const bool looks_json = kind == Kind::json_field ||
                            (kind == Kind::auto_detect && field.find_first_of(".[") != std::string::npos);
    out += kind == Kind::plain ? ": " : looks_json ? ": field " : ": column ";
    out += field;
  }
  if (column > 0 && field.empty()) out += ": column " + std::to_string(column);
  return out;
}

InputError::InputError(InputLocation where, const std::string& what_expected)
    : std::runtime_error(where.to_string() + ": " + what_expected),
      where_(std::move(where)),
      reason_(what_expected) {}

std::string quote_token(const std::string& token, std::size_t max_chars) {
  std::string out = "'";
  std::size_t shown = 0;
  for (unsigned char c : token) {
    if (shown == max_chars) {
      out += "...";
      break;
    }
    if (c >= 0x20 && c < 0x7f && c != '\'') {
      out += static_cast<char>(c);
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    }
    ++shown;
  }
  out += "'";
  if (token.size() > max_chars) out += " (" + std::to_string(token.size()) + " bytes)";
  return out;
}

}  // namespace rcm
