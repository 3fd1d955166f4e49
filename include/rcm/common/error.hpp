#pragma once
// Bad user input is reported with the exact place it came from, so that a user
// can open the file at that line: "free_space.csv:1204: column effort_2:
// expected a number, got 'nan'". Library code throws; only apps/ decide exit codes.

#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>

namespace rcm {

// Where a piece of input came from. Every member is optional: line 0 and empty
// strings mean "not known / not applicable".
struct InputLocation {
  std::string file;    // path as the user gave it
  std::size_t line = 0;    // 1-based line in a text file
  std::size_t column = 0;  // 1-based column number (character or CSV field), 0 if unknown
  std::string field;   // CSV column name or JSON field path, e.g. "trials[2].recording"
  // How `field` is introduced in the message ("column effort_2" / "field q0[1]").
  // auto_detect: a name with '.' or '[' is a JSON path, anything else a CSV column;
  // plain: printed as is (a command-line flag such as --q).
  enum class Kind { auto_detect, csv_column, json_field, plain } kind = Kind::auto_detect;

  std::string to_string() const;  // "file:line: column effort_2" / "file: field q0[1]"

  // A place named in words: `field` printed as given ("/PSM1/measured_js message 4: effort[2]", "--topic").
  static InputLocation plain(std::string file, std::string field) {
    InputLocation where;
    where.file = std::move(file);
    where.field = std::move(field);
    where.kind = Kind::plain;
    return where;
  }
};

// Thrown for every malformed, inconsistent or missing user input.
class InputError : public std::runtime_error {
 public:
  InputError(InputLocation where, const std::string& what_expected);
  const InputLocation& where() const noexcept { return where_; }
  const std::string& reason() const noexcept { return reason_; }

 private:
  InputLocation where_;
  std::string reason_;
};

// Quote a user-supplied token for an error message: printable, bounded length,
// so that binary garbage or a 10^5-character cell cannot flood the terminal.
std::string quote_token(const std::string& token, std::size_t max_chars = 40);

}  // namespace rcm
