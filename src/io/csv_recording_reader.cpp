// The recording CSV layouts (the contract's and `rostopic echo -p`'s) read a
// line at a time: the file in blocks of 1 MB, one row parsed, checked and
// written into the chunk, and only the previous row kept for the checks that
// compare rows (repeated rows, time order).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <optional>

#include "csv_parts.hpp"
#include "io/csv_recording_reader.hpp"
#include "rcm/common/error.hpp"

namespace rcm::detail {
namespace {

// The lines of a text, from memory or from a file read in blocks; a line is a
// view valid until the next call.
class LineSource {
 public:
  explicit LineSource(std::string text) : buffer_(std::move(text)), end_(buffer_.size()), eof_(true) {}
  LineSource(const std::filesystem::path& path, const std::string& source) : source_(source) {
    InputLocation where;
    where.file = source;
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw InputError(where, "file not found");
    if (std::filesystem::is_directory(path, ec)) throw InputError(where, "is a directory, expected a file");
    file_.reset(std::fopen(path.c_str(), "rb"));
    if (!file_) throw InputError(where, "cannot be opened for reading");
    buffer_.resize(kBlock);
  }

  bool next(std::string_view& line, std::size_t& number) {
    while (true) {
      const char* base = buffer_.data();
      const void* nl = begin_ < end_ ? std::memchr(base + begin_, '\n', end_ - begin_) : nullptr;
      if (nl) {
        const std::size_t at = static_cast<std::size_t>(static_cast<const char*>(nl) - base);
        line = std::string_view(base + begin_, at - begin_);
        begin_ = at + 1;
        number = ++number_;
        return true;
      }
      if (eof_) {
        // The piece after the last newline is a line too (blank when the file ends with one).
        if (last_given_) return false;
        last_given_ = true;
        line = std::string_view(base + begin_, end_ - begin_);
        begin_ = end_;
        number = ++number_;
        return true;
      }
      refill();
    }
  }

 private:
  static constexpr std::size_t kBlock = std::size_t{1} << 20;
  struct Close {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };

  void refill() {
    // Keep the unfinished line, at the front; a line longer than the buffer grows it.
    const std::size_t keep = end_ - begin_;
    if (begin_ > 0) std::memmove(buffer_.data(), buffer_.data() + begin_, keep);
    begin_ = 0;
    end_ = keep;
    if (buffer_.size() - end_ < kBlock / 2) buffer_.resize(std::max(buffer_.size() * 2, end_ + kBlock));
    const std::size_t got = std::fread(buffer_.data() + end_, 1, buffer_.size() - end_, file_.get());
    end_ += got;
    if (got == 0) {
      if (std::ferror(file_.get())) {
        InputLocation where;
        where.file = source_;
        where.line = number_ + 1;
        throw InputError(where, "cannot be read (I/O error)");
      }
      eof_ = true;
    }
  }

  std::string source_;
  std::unique_ptr<std::FILE, Close> file_;
  std::string buffer_;
  std::size_t begin_ = 0, end_ = 0, number_ = 0;
  bool eof_ = false, last_given_ = false;
};

struct Layout {
  RecordingLayout kind = RecordingLayout::rcm_csv;
  std::optional<Column> time;
  bool time_in_ns = false;
  int joints = 0;
  std::vector<Column> position, velocity, effort, force;
  std::size_t header_fields = 0;
};

Layout parse_header(const std::vector<std::string_view>& fields, const std::string& source,
                    const RecordingReadOptions& options) {
  Layout layout;
  layout.header_fields = fields.size();
  std::map<std::string, std::size_t> by_name = index_header(fields, source);

  const bool rostopic = by_name.count("%time") || by_name.count("field.position0");
  std::string pos_prefix = "position_", vel_prefix = "velocity_", eff_prefix = "effort_";
  int first = 1;
  if (rostopic) {
    layout.kind = RecordingLayout::rostopic_csv;
    pos_prefix = "field.position";
    vel_prefix = "field.velocity";
    eff_prefix = "field.effort";
    first = 0;
    if (by_name.count("%time")) {
      layout.time = Column{by_name["%time"], "%time"};
      layout.time_in_ns = true;
    }
  } else if (by_name.count("time")) {
    layout.time = Column{by_name["time"], "time"};
  }
  if (!layout.time && !options.assumed_rate_hz) {
    throw InputError(locate(source, 1, ""),
                     std::string("no time column ('") + (rostopic ? "%time" : "time") +
                         "'); give the sampling rate explicitly (--rate HZ) to number the samples");
  }

  layout.position = find_series(by_name, pos_prefix, first, source);
  layout.velocity = find_series(by_name, vel_prefix, first, source);
  layout.effort = find_series(by_name, eff_prefix, first, source);
  const std::size_t n = std::max({layout.position.size(), layout.velocity.size(), layout.effort.size()});
  const std::string* prefixes[3] = {&pos_prefix, &vel_prefix, &eff_prefix};
  const std::vector<Column>* series[3] = {&layout.position, &layout.velocity, &layout.effort};
  for (int k = 0; k < 3; ++k) {
    if (series[k]->size() < n) {
      throw InputError(locate(source, 1, *prefixes[k] + std::to_string(first + static_cast<int>(series[k]->size()))),
                       "missing: position, velocity and effort must be given for the same " +
                           std::to_string(n) + " joints");
    }
  }
  if (static_cast<int>(n) < options.min_joints) {
    throw InputError(locate(source, 1, pos_prefix + std::to_string(first + static_cast<int>(n))),
                     "missing: too few joints (" + std::to_string(n) + "), at least " +
                         std::to_string(options.min_joints) + " are required");
  }
  layout.joints = static_cast<int>(n);

  if (!rostopic) {
    const char* axes[3] = {"force_x", "force_y", "force_z"};
    int present = 0;
    for (const char* a : axes) present += by_name.count(a) ? 1 : 0;
    if (present != 0 && present != 3) {
      for (const char* a : axes)
        if (!by_name.count(a))
          throw InputError(locate(source, 1, a), "missing: force columns come as force_x, force_y, force_z together");
    }
    if (present == 3)
      for (const char* a : axes) layout.force.push_back({by_name[a], a});
  }
  return layout;
}

class CsvRecordingReader final : public RecordingReader {
 public:
  CsvRecordingReader(LineSource lines, const std::string& source, const RecordingReadOptions& options,
                     std::size_t chunk_rows)
      : RecordingReader(source, RecordingLayout::rcm_csv, chunk_rows, options.dedupe),
        lines_(std::move(lines)),
        options_(options) {
    std::string_view line;
    std::size_t number = 0;
    bool any = false;
    while (lines_.next(line, number))
      if (!trim(line).empty()) {
        any = true;
        break;
      }
    if (!any) throw InputError(locate(source, 0, ""), "file is empty, expected a header row");
    if (number != 1) throw InputError(locate(source, 1, ""), "expected the header row on line 1, found a blank line");
    split_fields(line, fields_);
    layout_ = parse_header(fields_, source, options);
    set_layout(layout_.kind);
    set_shape(layout_.joints, !layout_.force.empty());
    set_time_from_rate(!layout_.time.has_value());
    set_has_lines(true);
    time_name_ = layout_.time ? layout_.time->name : "time";
    const std::size_t N = static_cast<std::size_t>(layout_.joints);
    row_.resize(3 * N);
    previous_.resize(3 * N);
    // The first data row, so that a file of a header alone fails on opening as on a whole read.
    if (!next_data_line(line, number)) throw InputError(locate(source, 1, ""), "header only, no data rows");
    pending_.assign(line);
    pending_number_ = number;
  }

 private:
  bool next_data_line(std::string_view& line, std::size_t& number) {
    while (lines_.next(line, number))
      if (!trim(line).empty()) return true;
    return false;
  }

  std::size_t fill_chunk(Recording& chunk, std::size_t filled) override {
    const std::size_t rows = chunk_rows();
    std::string_view line;
    std::size_t number = 0;
    while (filled < rows) {
      if (pending_number_ != 0) {
        line = pending_;
        number = pending_number_;
        pending_number_ = 0;
      } else if (!next_data_line(line, number)) {
        end_of_data_ = true;
        break;
      }
      if (take_row(line, number, chunk, static_cast<Eigen::Index>(filled))) ++filled;
    }
    return filled;
  }

  // Parses and checks the data row on line `number`; writes it at row `t` of
  // the chunk and returns true unless --dedupe drops it.
  bool take_row(std::string_view line, std::size_t number, Recording& chunk, Eigen::Index t) {
    const std::string& src = source();
    split_fields(line, fields_);
    if (fields_.size() != layout_.header_fields) {
      throw InputError(locate(src, number, ""),
                       "expected " + std::to_string(layout_.header_fields) +
                           " comma-separated fields as in the header, found " + std::to_string(fields_.size()) +
                           (fields_.size() < layout_.header_fields ? " (truncated row?)" : ""));
    }
    double time;
    if (layout_.time) {
      const double v = parse_cell(fields_[layout_.time->index], src, number, layout_.time->name);
      time = layout_.time_in_ns ? v * 1e-9 : v;
    } else {
      time = static_cast<double>(rows_written_) / *options_.assumed_rate_hz;
    }
    ++rows_written_;
    const int N = layout_.joints;
    for (int j = 0; j < N; ++j) {
      row_[j] = parse_cell(fields_[layout_.position[j].index], src, number, layout_.position[j].name);
      row_[N + j] = parse_cell(fields_[layout_.velocity[j].index], src, number, layout_.velocity[j].name);
      row_[2 * N + j] = parse_cell(fields_[layout_.effort[j].index], src, number, layout_.effort[j].name);
    }
    double force[3] = {0, 0, 0};
    for (std::size_t k = 0; k < layout_.force.size(); ++k)
      force[k] = parse_cell(fields_[layout_.force[k].index], src, number, layout_.force[k].name);

    // Repeated samples: the logger wrote the same joint message again.
    const bool repeated = have_previous_ && row_ == previous_;
    std::swap(row_, previous_);
    have_previous_ = true;
    if (repeated) {
      count_repeated_row();
      if (options_.dedupe) {
        if (time_from_rate()) {
          // Time was numbered from the rate over the rows as written; dropping rows
          // would leave gaps that the rate no longer describes.
          throw InputError(locate(src, 0, ""),
                           "cannot drop repeated rows of a file without a time column (the rate numbers the rows as "
                           "written)");
        }
        return false;
      }
    }
    if (have_kept_ && !(time > kept_time_)) {
      throw InputError(locate(src, number, time_name_),
                       "time must increase strictly: " + std::to_string(time) + " s after " +
                           std::to_string(kept_time_) + " s on line " + std::to_string(kept_line_) +
                           (repeated && !options_.dedupe
                                ? " (this row repeats the previous sample; --dedupe drops repeated rows)"
                                : ""));
    }
    have_kept_ = true;
    kept_time_ = time;
    kept_line_ = number;
    chunk.time[t] = time;
    for (int j = 0; j < N; ++j) {
      chunk.position(t, j) = previous_[j];
      chunk.velocity(t, j) = previous_[N + j];
      chunk.effort(t, j) = previous_[2 * N + j];
    }
    if (chunk.force)
      for (int k = 0; k < 3; ++k) (*chunk.force)(t, k) = force[k];
    chunk.line[static_cast<std::size_t>(t)] = number;
    return true;
  }

  LineSource lines_;
  RecordingReadOptions options_;
  Layout layout_;
  std::string time_name_;
  std::vector<std::string_view> fields_;
  std::string pending_;
  std::size_t pending_number_ = 0;
  std::vector<double> row_, previous_;  // position, velocity, effort of this row and the one before
  bool have_previous_ = false, have_kept_ = false;
  double kept_time_ = 0.0;
  std::size_t kept_line_ = 0;
  std::size_t rows_written_ = 0;  // data rows as written, numbered by --rate
};

void check_rate(const std::string& source, const RecordingReadOptions& options) {
  if (options.assumed_rate_hz && !(*options.assumed_rate_hz > 0.0 && std::isfinite(*options.assumed_rate_hz)))
    throw InputError(locate(source, 0, ""), "the assumed sampling rate must be a positive number of Hz");
}

}  // namespace

std::unique_ptr<RecordingReader> open_csv_recording(const std::filesystem::path& path,
                                                    const RecordingReadOptions& options, std::size_t chunk_rows) {
  LineSource lines(path, path.string());
  check_rate(path.string(), options);
  return std::make_unique<CsvRecordingReader>(std::move(lines), path.string(), options, chunk_rows);
}

std::unique_ptr<RecordingReader> open_csv_text(std::string text, const std::string& source,
                                               const RecordingReadOptions& options, std::size_t chunk_rows) {
  check_rate(source, options);
  return std::make_unique<CsvRecordingReader>(LineSource(std::move(text)), source, options, chunk_rows);
}

}  // namespace rcm::detail
