#pragma once
// What the output tests share: a check that a file rcm wrote is whole (by its
// kind), the hidden temporaries of the atomic writer left in a folder, a small
// simulated session, and running the CLI to its end with a file-size limit.

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "child_process.hpp"
#include "rcm/io/recording.hpp"

namespace rcm::test {

// Empty when `path` is a whole file of its kind, else what is wrong with it.
// JSON parses; a CSV reads back through rcm's reader (recordings) or has as many
// cells in every row as in its header (other tables); PNG has its signature and
// IEND as last chunk; SVG ends with </svg>; a gnuplot script with its last
// command; anything else is non-empty.
inline std::string find_defect(const std::filesystem::path& path) {
  const std::string text = read_text(path);
  const std::string ext = path.extension().string();
  if (text.empty()) return "empty";
  if (ext == ".json") {
    try {
      const nlohmann::json parsed = nlohmann::json::parse(text);
      (void)parsed;
    } catch (const std::exception& e) {
      return std::string("JSON does not parse: ") + e.what();
    }
  } else if (ext == ".csv") {
    if (text.rfind("time,", 0) == 0) {
      try {
        const rcm::Recording recording = rcm::load_recording(path);
        (void)recording;
      } catch (const std::exception& e) {
        return std::string("recording does not read back: ") + e.what();
      }
    } else {
      if (text.back() != '\n') return "last row not ended";
      std::size_t line_start = 0, header_cells = 0;
      for (std::size_t row = 0; line_start < text.size(); ++row) {
        const std::size_t end = text.find('\n', line_start);
        const std::string line = text.substr(line_start, end - line_start);
        const std::size_t cells = static_cast<std::size_t>(std::count(line.begin(), line.end(), ',')) + 1;
        if (row == 0) header_cells = cells;
        else if (cells != header_cells) return "row " + std::to_string(row + 1) + " has " + std::to_string(cells) + " cells";
        line_start = end + 1;
      }
    }
  } else if (ext == ".png") {
    if (text.compare(0, 8, std::string("\x89PNG\r\n\x1a\n", 8)) != 0) return "no PNG signature";
    if (text.size() < 20 || text.compare(text.size() - 8, 4, "IEND") != 0) return "PNG does not end with IEND";
  } else if (ext == ".svg") {
    const std::size_t end = text.find_last_not_of(" \r\n\t");
    if (end == std::string::npos || end < 5 || text.compare(end - 5, 6, "</svg>") != 0) return "SVG not closed";
  } else if (ext == ".gp") {
    if (text.size() < 13 || text.compare(text.size() - 13, 13, "unset output\n") != 0) return "script cut short";
  }
  return "";
}

// Every regular file under `dir` (recursively) whose name does not start with '.'.
inline std::vector<std::filesystem::path> list_outputs(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> out;
  if (!std::filesystem::exists(dir)) return out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') out.push_back(e.path());
  return out;
}

// The atomic writer's temporaries under `dir` (recursively).
inline std::vector<std::filesystem::path> list_temporaries(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> out;
  if (!std::filesystem::exists(dir)) return out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.path().filename().string().find(".rcm-tmp.") != std::string::npos) out.push_back(e.path());
  return out;
}

struct Exit {
  int code = -1;  // exit status, or -signal
  std::string log;
};

// Runs the CLI to its end with stdout and stderr in `log`; file_size_limit > 0
// sets RLIMIT_FSIZE with SIGXFSZ ignored, so that writes beyond it fail with
// EFBIG as on a full disk.
inline Exit run_cli(const std::vector<std::string>& args, const std::filesystem::path& log,
                    rlim_t file_size_limit = 0) {
  std::vector<std::string> full{RCM_CLI_PATH};
  full.insert(full.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : full) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string log_path = log.string();
  const pid_t pid = ::fork();
  if (pid == 0) {  // only async-signal-safe calls until exec
    const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    if (file_size_limit > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      const struct rlimit limit{file_size_limit, file_size_limit};
      ::setrlimit(RLIMIT_FSIZE, &limit);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status), read_text(log)};
}

// A small simulated session in dir/session (4 trials of 8 s at 200 Hz: D = 30
// and 40 mm, pure coaxial and with a radial offset, so that every figure of the
// report is drawn) and a linear free-space model fitted on it, dir/model.json;
// empty when both worked, else the log. About 3 s.
inline std::string make_small_session(const std::filesystem::path& dir) {
  const std::filesystem::path config = dir / "small_session.json";
  {
    std::ofstream(config) << R"({"protocol": {"coaxial_offsets_m": [0.03, 0.04]}})";
  }
  const Exit sim = run_cli({"simulate", "--quick", "--seed", "1", "--config", config.string(), "--trial-s", "8",
                            "--calibration-s", "15", "--free-space-s", "60", "--out", (dir / "session").string()},
                           dir / "simulate.log");
  if (sim.code != 0) return sim.log;
  const Exit fit = run_cli({"dynamics", "fit", "--model", "linear", "--out", (dir / "model.json").string(),
                            (dir / "session" / "free_space.csv").string()},
                           dir / "fit.log");
  return fit.code == 0 ? std::string() : fit.log;
}

}  // namespace rcm::test
