// `make soak`: ten million joint-state messages (by default) with faults through
// the live nodes' per-message path, against the same stream without faults
// (tests/support/faulty_stream.hpp). Prints the report; --json writes it for
// bench/soak_report.py. Exits 1 when a rule is broken: an exception, a verdict
// or count unlike the prediction, an estimate not back within 1 mm within 5 s
// of a fault (of a silence: the estimator's max_drift_gap_s, 10 s), or the
// resident memory growing by 1 MB or more after the first minute of sample
// time.
//
//   soak_live --session S/session.json --model M.json --recording S/D30_r10_15.csv
//             [--messages N] [--seed K] [--ros1] [--json FILE]

#include <cstdio>
#include <cstdlib>
#include <string>

#include <nlohmann/json.hpp>

#include "rcm/io/json_file.hpp"
#include "rcm/io/recording.hpp"
#include "support/faulty_stream.hpp"

namespace {

int usage(const char* why) {
  std::fprintf(stderr,
               "soak_live: %s\nusage: soak_live --session FILE --model FILE --recording FILE [--messages N] "
               "[--seed K] [--ros1] [--json FILE]\n",
               why);
  return 2;
}

nlohmann::json to_json(const rcm::LiveMonitor::Counters& c) {
  return {{"accepted", c.accepted},     {"duplicate_stamp", c.duplicate_stamp}, {"out_of_order", c.out_of_order},
          {"time_jump", c.time_jump},   {"zero_stamp", c.bad_stamp},            {"malformed", c.malformed},
          {"too_few_joints", c.too_few_joints}, {"retimed", c.retimed},              {"missing", c.missing},
          {"gaps", c.gaps}};
}

}  // namespace

int main(int argc, char** argv) {
  rcm::MonitorNodeParameters parameters;
  parameters.status_period_s = 3600.0;
  rcm::test::SoakOptions options;
  options.messages = 10000000;
  std::string recording, json;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--session" && has_value) parameters.session = argv[++i];
    else if (a == "--model" && has_value) parameters.model_file = argv[++i];
    else if (a == "--recording" && has_value) recording = argv[++i];
    else if (a == "--messages" && has_value) options.messages = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--seed" && has_value) options.seed = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--json" && has_value) json = argv[++i];
    else if (a == "--ros1") options.zero_stamp = rcm::LiveMonitor::ZeroStamp::receive_time_when_unstamped;
    else return usage(("unknown or incomplete argument " + a).c_str());
  }
  if (parameters.session.empty() || parameters.model_file.empty() || recording.empty())
    return usage("--session, --model and --recording are required");
  if (options.messages == 0) return usage("--messages must be positive");

  try {
    const rcm::test::SoakReport r = rcm::test::run_soak(rcm::load_recording(recording), parameters, options);
    std::printf("%s", r.to_text().c_str());
    const long growth_kb = r.rss_peak_after_kb - r.rss_baseline_kb;
    const bool ok = r.counts_match() && r.get_unrecovered() == 0 && growth_kb < 1024;
    if (!json.empty()) {
      nlohmann::json j;
      j["clean_samples"] = r.clean_samples;
      j["messages"] = r.messages_sent;
      j["sample_time_s"] = r.sample_time_s;
      j["wall_s"] = r.wall_s;
      j["counters"] = to_json(r.counters);
      j["predicted"] = to_json(r.expected);
      j["exceptions"] = r.exceptions;
      j["verdict_mismatches"] = r.verdict_mismatches;
      j["faults"] = nlohmann::json::array();
      for (int k = 0; k < rcm::test::kNumStreamFaults; ++k) {
        std::uint64_t samples = 0;
        double recovery = 0.0, deviation = 0.0, window = 0.0;
        for (const auto& f : r.faults) {
          if (static_cast<int>(f.kind) != k) continue;
          samples += f.messages;
          recovery = std::max(recovery, f.recovery_s);
          deviation = std::max(deviation, f.max_deviation_m);
          window = f.window_s;
        }
        j["faults"].push_back({{"kind", rcm::test::to_string(static_cast<rcm::test::StreamFault>(k))},
                               {"injected", r.injected[static_cast<std::size_t>(k)]},
                               {"samples", samples},
                               {"max_recovery_s", recovery},
                               {"recovery_window_s", window},
                               {"max_deviation_m", deviation}});
      }
      j["unrecovered"] = r.get_unrecovered();
      j["rss_kb"] = {{"baseline", r.rss_baseline_kb}, {"peak_after", r.rss_peak_after_kb}, {"end", r.rss_end_kb}};
      j["final_deviation_m"] = r.final_deviation_m;
      j["passed"] = ok;
      rcm::save_json_file(json, j);
    }
    if (!ok) std::fprintf(stderr, "soak_live: FAILED (see the report above)\n");
    return ok ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "soak_live: %s\n", e.what());
    return 1;
  }
}
