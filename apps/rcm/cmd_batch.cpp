// rcm batch: many sessions as `rcm run` runs one, on Dask (docs/howto-batch.md).
// The work is the Python package's (rcm.batch, python/rcm/batch.py): this
// command checks its flags and options as `rcm run` does, then replaces itself
// with `PYTHON -m rcm.batch`, whose exit status and output are the command's.
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "cli_util.hpp"
#include "command_registry.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/fit.hpp"
#include "study_cli.hpp"

// Set by python/CMakeLists.txt: the interpreter the package was built for and
// where the package lies relative to this program's folder, installed and in
// the build tree. A build without the Python package knows neither.
#ifndef RCM_PYTHON_EXECUTABLE
#define RCM_PYTHON_EXECUTABLE "/usr/bin/python3"
#endif
#ifndef RCM_PYTHON_PACKAGE_RELATIVE
#define RCM_PYTHON_PACKAGE_RELATIVE ""
#endif
#ifndef RCM_PYTHON_BUILD_RELATIVE
#define RCM_PYTHON_BUILD_RELATIVE ""
#endif

namespace {
namespace cmd_batch {

struct Options {
  std::vector<std::string> sessions;
  std::string out = "rcm-batch", scheduler, options_file;
  int workers = 0;
  rcm::cli::OptionFlags<rcm::StudyOptions> study;
  bool json = false;
};

std::string get_python() {
  const char* python = std::getenv("RCM_PYTHON");
  return python != nullptr && *python != '\0' ? python : RCM_PYTHON_EXECUTABLE;
}

// The folder holding this rcm's package `rcm` (with batch.py): installed beside
// this program, or in its build tree; empty when neither holds it (the
// interpreter's own path is then searched).
std::filesystem::path find_package_dir() {
  std::error_code ec;
  const auto program = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  for (const char* relative : {RCM_PYTHON_PACKAGE_RELATIVE, RCM_PYTHON_BUILD_RELATIVE}) {
    if (*relative == '\0') continue;
    const auto dir = (program.parent_path() / relative).lexically_normal();
    if (std::filesystem::is_regular_file(dir / "rcm" / "batch.py", ec)) return dir;
  }
  return {};
}

[[noreturn]] void run(const Options& o) {
  // The options as `rcm run` makes them (defaults, file, flags; each checked),
  // handed to the workers as one JSON object.
  const rcm::StudyOptions options = rcm::cli::make_study_options(o.study, o.options_file);
  if (options.model_kind && *options.model_kind != rcm::dynamics::TorqueModelKind::linear && !options.model_file)
    throw rcm::InputError(rcm::cli::flag_location("--model"),
                          "rcm batch fits the linear model only (its workers run the Python package, which has no "
                          "LibTorch): fit the network once with `rcm dynamics fit --model " +
                              rcm::dynamics::to_string(*options.model_kind) + "` and pass it with --model-file");
  for (const auto& session : o.sessions)
    if (!std::filesystem::is_regular_file(session))
      throw rcm::InputError(rcm::cli::flag_location("SESSIONS"), session + ": no such session manifest");
  const std::string python = get_python();
  if (access(python.c_str(), X_OK) != 0)
    throw std::runtime_error("rcm batch runs its sessions with Python: " + python +
                             " is not an executable (set RCM_PYTHON to Debian's /usr/bin/python3, with "
                             "python3-dask and python3-distributed)");

  std::vector<std::string> args = {python, "-m", "rcm.batch", "--out", o.out,
                                   "--options-json", rcm::options_to_json(options).dump()};
  if (!o.scheduler.empty()) args.insert(args.end(), {"--scheduler", o.scheduler});
  if (o.workers > 0) args.insert(args.end(), {"--workers", std::to_string(o.workers)});
  if (o.json) args.emplace_back("--json");
  args.emplace_back("--");
  args.insert(args.end(), o.sessions.begin(), o.sessions.end());

  if (const auto dir = find_package_dir(); !dir.empty()) {
    const char* old = std::getenv("PYTHONPATH");
    const std::string path = dir.string() + (old != nullptr && *old != '\0' ? ":" + std::string(old) : "");
    setenv("PYTHONPATH", path.c_str(), 1);
  }
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::cout.flush();
  execv(python.c_str(), argv.data());
  throw std::runtime_error("rcm batch: cannot run " + python + ": " + std::strerror(errno));
}

const bool registered = rcm::cli::register_command({"batch", 65, [](CLI::App& app) {
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "batch",
      "Many sessions as `rcm run` runs one, side by side on Dask: OUT/<session folder>/ each, and a summary "
      "across them; exit 2 when some failed on bad input, 1 on another failure (each one listed)");
  cmd->add_option("SESSIONS", o->sessions,
                  "rcm-session/1 manifests; each one's results go to OUT/<the folder holding it>/, so those folders' "
                  "names must differ")
      ->required();
  cmd->add_option("--out", o->out, "output folder (default rcm-batch)");
  auto* scheduler = cmd->add_option("--scheduler", o->scheduler,
                                    "address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local "
                                    "cluster on 127.0.0.1)");
  cmd->add_option("--workers", o->workers,
                  "worker processes of the local cluster, one thread each (default: one per core)")
      ->check(CLI::PositiveNumber)
      ->excludes(scheduler);
  o->study.add(cmd, "--method", {"method"});
  o->study.add(cmd, "--static-step", {"static_step"});
  // rcm run's free-space flags but --max-train-minutes: the workers fit the linear model only.
  o->study.add(cmd, "--model", {"model_kind"},
               "free-space model to fit: linear (the workers have no LibTorch; fit a network once with `rcm dynamics "
               "fit` and give it with --model-file)");
  o->study.add(cmd, "--model-file", {"model_file"},
               "use a saved free-space model of any kind (e.g. free_space_model.json of `rcm run`) for every session");
  o->study.add(cmd, "--seed", {"fit.seed", "joint.seed"}, "seed of the model fit and of the joint method's bootstrap");
  o->study.add(cmd, "--dedupe", {"read.dedupe"}, "drop repeated rows of every recording");
  o->study.add(cmd, "--D0", {"three_step.D_initial"}, "initial guess of D (unset: the middle of its bounds)");
  rcm::cli::add_options_file_flag(cmd, o->options_file);
  cmd->add_flag("--json", o->json, "print summary.json on stdout instead of summary.md");
  cmd->footer(std::string("Python: RCM_PYTHON, else the one rcm was built for, with python3-dask and "
                          "python3-distributed. Workers read the sessions at their absolute paths.\n") +
              cmd->get_footer());
  cmd->callback([o] { run(*o); });
}});

}  // namespace cmd_batch
}  // namespace
