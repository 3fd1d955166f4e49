#pragma once
// What a caller does with a recording the CSV reader accepted, checked on
// every accepted input: the invariants validate_recording states hold, the
// summary is finite, and saving then reading it back gives the same numbers.

#include <cmath>
#include <string>

#include "fuzz_support.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/recording_reader.hpp"

namespace rcm::fuzz {

inline void check_accepted_recording(const Recording& rec) {
  // validate_recording wants the 3 joints of the estimator; the targets also
  // read with min_joints = 1, so fewer joints get the same checks by hand.
  if (rec.num_joints() >= 3) {
    try {
      validate_recording(rec);
    } catch (const InputError& e) {
      std::fprintf(stderr, "accepted recording fails validation: %s\n", e.what());
      fail_property("validate_recording(accepted recording)");
    }
  } else {
    RCM_FUZZ_CHECK(rec.num_joints() >= 1 && rec.num_samples() >= 1);
    RCM_FUZZ_CHECK(rec.time.allFinite() && rec.position.allFinite() && rec.velocity.allFinite() &&
                   rec.effort.allFinite());
    for (Eigen::Index t = 1; t < rec.time.size(); ++t) RCM_FUZZ_CHECK(rec.time[t] > rec.time[t - 1]);
  }
  // Message recordings have no lines; a text recording numbers every sample.
  RCM_FUZZ_CHECK(rec.line.empty() || rec.line.size() == rec.num_samples());
  const RecordingSummary s = summarize_recording(rec);
  RCM_FUZZ_CHECK(s.samples == rec.num_samples());
  RCM_FUZZ_CHECK(!(s.dt_min_s < 0.0));

  // save_recording holds what it writes to validate_recording's 3 joints.
  if (rec.num_joints() < 3) return;
  const auto path = scratch_dir() / "roundtrip.csv";
  save_recording(path, rec);
  RecordingReadOptions again;
  again.min_joints = 1;
  const Recording back = load_recording(path, again);
  RCM_FUZZ_CHECK(back.time == rec.time);
  RCM_FUZZ_CHECK(back.position == rec.position);
  RCM_FUZZ_CHECK(back.velocity == rec.velocity);
  RCM_FUZZ_CHECK(back.effort == rec.effort);
  RCM_FUZZ_CHECK(back.has_force() == rec.has_force());
  if (rec.has_force()) RCM_FUZZ_CHECK(*back.force == *rec.force);
}

// The same read in small chunks (io/recording_reader.hpp) gives the same
// recording, or fails with the same message: every check that spans rows
// holds across chunk boundaries. `whole` reads it at once, `open_chunked`
// opens it with chunks of a few rows.
template <class Whole, class Chunked>
void check_chunked_read(Whole&& whole, Chunked&& open_chunked) {
  Recording a, b;
  std::string error_a, error_b;
  try {
    a = whole();
  } catch (const InputError& e) {
    error_a = e.what();
  }
  try {
    const auto reader = open_chunked();
    b = read_whole_recording(*reader);
  } catch (const InputError& e) {
    error_b = e.what();
  }
  if (error_a != error_b) std::fprintf(stderr, "whole: %s\nchunked: %s\n", error_a.c_str(), error_b.c_str());
  RCM_FUZZ_CHECK(error_a == error_b);
  if (!error_a.empty()) return;
  RCM_FUZZ_CHECK(a.time == b.time && a.position == b.position && a.velocity == b.velocity && a.effort == b.effort);
  RCM_FUZZ_CHECK(a.has_force() == b.has_force() && (!a.has_force() || *a.force == *b.force));
  RCM_FUZZ_CHECK(a.line == b.line && a.repeated_rows == b.repeated_rows);
}

// Reads `text` as the CSV reader would read the file, first with the default
// options, then as `--dedupe --rate 100` with one joint allowed.
inline void fuzz_csv(const std::uint8_t* data, std::size_t size, const char* name,
                     bool expect_rostopic_layout_when_percent_time) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  RecordingReadOptions options[2];
  options[1].dedupe = true;
  options[1].assumed_rate_hz = 100.0;
  options[1].min_joints = 1;
  for (const RecordingReadOptions& o : options) {
    check_chunked_read([&] { return parse_recording(text, name, o); },
                       [&] { return open_recording_text(text, name, o, 2); });
    Recording rec;
    if (!accepts([&] { rec = parse_recording(text, name, o); })) continue;
    if (expect_rostopic_layout_when_percent_time && text.rfind("%time", 0) == 0)
      RCM_FUZZ_CHECK(rec.layout == RecordingLayout::rostopic_csv);
    RCM_FUZZ_CHECK(rec.line.size() == rec.num_samples());
    check_accepted_recording(rec);
  }
}

}  // namespace rcm::fuzz
