// The rcm-session/1 manifest (load_session). The recordings a manifest may
// name exist beside it (free_space.csv, calibration.csv, trial_N.csv,
// static_N.csv, N = 1..3) so that inputs get past the file checks; only
// their existence is read. An accepted manifest is saved and read back.
#include "fuzz_support.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"

namespace {

void make_recording_files() {
  static const bool done = [] {
    for (const char* f : {"free_space.csv", "calibration.csv"}) rcm::fuzz::write_input(f, std::string());
    for (int i = 1; i <= 3; ++i) {
      rcm::fuzz::write_input("trial_" + std::to_string(i) + ".csv", std::string());
      rcm::fuzz::write_input("static_" + std::to_string(i) + ".csv", std::string());
    }
    return true;
  }();
  (void)done;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  make_recording_files();
  const auto path = fuzz::write_input("session.json", data, size);
  Session s;
  if (!fuzz::accepts([&] { s = load_session(path); })) return 0;
  RCM_FUZZ_CHECK(!s.free_space.empty());
  RCM_FUZZ_CHECK(s.q0.allFinite());
  const RecordingReadOptions read = get_read_options(s, {});
  RCM_FUZZ_CHECK(read.joint_topic == s.joint_topic);

  const auto again = fuzz::scratch_dir() / "session_saved.json";
  save_session(again, s);
  Session back;
  if (!fuzz::accepts([&] { back = load_session(again); })) fuzz::fail_property("a saved session reads back");
  RCM_FUZZ_CHECK(back.robot == s.robot);
  RCM_FUZZ_CHECK(back.q0 == s.q0);
  RCM_FUZZ_CHECK(back.free_space.size() == s.free_space.size());
  RCM_FUZZ_CHECK(back.trials.size() == s.trials.size());
  RCM_FUZZ_CHECK(back.calibration.has_value() == s.calibration.has_value());
  RCM_FUZZ_CHECK(back.joint_topic == s.joint_topic && back.force_topic == s.force_topic);
  return 0;
}
