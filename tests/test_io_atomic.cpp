// The one writer of every rcm output (rcm/io/atomic_file.hpp): whole or
// absent, a full disk a clear error that leaves the earlier file and no
// temporary, temporaries of killed processes removed by the next write.
// A full disk is stood in for by RLIMIT_FSIZE (writes beyond it fail with
// EFBIG, SIGXFSZ ignored), in a forked child so that the test process keeps
// its own limit.

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "output_checks.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/atomic_file.hpp"
#include "rcm/io/plot.hpp"
#include "temp_dir.hpp"

namespace {

using rcm::test::read_text;
using rcm::test::TempDir;

// Runs `write` in a child with a file-size limit; returns the message of the
// InputError it threw ("" when it threw none, "other: ..." for anything else).
template <typename Write>
std::string write_under_limit(rlim_t limit, Write write, const std::filesystem::path& message_file) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::signal(SIGXFSZ, SIG_IGN);
    const struct rlimit l{limit, limit};
    ::setrlimit(RLIMIT_FSIZE, &l);
    std::string message;
    try {
      write();
    } catch (const rcm::InputError& e) {
      message = e.what();
    } catch (const std::exception& e) {
      message = std::string("other: ") + e.what();
    }
    // The message is short: within the limit.
    const int fd = ::open(message_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      (void)!::write(fd, message.data(), message.size());
      ::close(fd);
    }
    ::_exit(0);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  return read_text(message_file);
}

TEST(AtomicFile, WritesWholeAndLeavesNoTemporary) {
  TempDir dir;
  const auto path = dir.path() / "results.json";
  rcm::write_file_atomic(path, "{\"a\": 1}\n");
  EXPECT_EQ(read_text(path), "{\"a\": 1}\n");
  rcm::write_file_atomic(path, "{\"a\": 2}\n");
  EXPECT_EQ(read_text(path), "{\"a\": 2}\n");
  EXPECT_TRUE(rcm::test::list_temporaries(dir.path()).empty());
  // A file written by name (LibTorch, gnuplot): only commit() makes it appear.
  {
    rcm::AtomicFile file(dir.path() / "model.pt");
    std::ofstream(file.get_temp_path(), std::ios::binary) << "bytes";
    EXPECT_FALSE(std::filesystem::exists(dir.path() / "model.pt"));
    file.commit();
  }
  EXPECT_EQ(read_text(dir.path() / "model.pt"), "bytes");
  {
    rcm::AtomicFile abandoned(dir.path() / "other.pt");
    std::ofstream(abandoned.get_temp_path(), std::ios::binary) << "half";
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "other.pt"));
  EXPECT_TRUE(rcm::test::list_temporaries(dir.path()).empty());
}

TEST(AtomicFile, MissingDirectoryNamesTheFile) {
  TempDir dir;
  const auto path = dir.path() / "no" / "such" / "report.md";
  try {
    rcm::write_file_atomic(path, "text");
    FAIL() << "no error";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
}

TEST(AtomicFile, FullDiskKeepsTheEarlierFileAndNamesTheReason) {
  TempDir dir;
  const auto path = dir.path() / "free_space_model.json";
  rcm::write_file_atomic(path, "earlier version\n");
  const std::string big(256 * 1024, 'x');
  const std::string message =
      write_under_limit(64 * 1024, [&] { rcm::write_file_atomic(path, big); }, dir.path() / ".message");
  EXPECT_NE(message.find(path.string() + ": cannot be written: "), std::string::npos) << message;
  EXPECT_NE(message.find(std::strerror(EFBIG)), std::string::npos) << message;
  EXPECT_EQ(read_text(path), "earlier version\n");
  EXPECT_TRUE(rcm::test::list_temporaries(dir.path()).empty());
}

TEST(AtomicFile, FullDiskWhileGnuplotDrawsLeavesNoFigure) {
  // gnuplot is a dependency (make deps installs gnuplot-nox): without it this is a broken install.
  ASSERT_TRUE(rcm::is_gnuplot_available()) << "gnuplot is not installed";
  TempDir dir;
  rcm::PlotSpec spec;
  spec.title = "limit";
  rcm::PlotSeries s;
  for (int i = 0; i < 2000; ++i) {
    s.x.push_back(i);
    s.y.push_back((i * 7919) % 101);
  }
  spec.series.push_back(s);
  const auto stem = dir.path() / "figure";
  rcm::save_plot(spec, stem);  // the earlier version
  const std::string earlier_png = read_text(dir.path() / "figure.png");
  ASSERT_EQ(rcm::test::find_defect(dir.path() / "figure.png"), "");
  // The script (about 20 kB) fits, the figures do not.
  spec.width_px = 3000;
  spec.height_px = 2000;
  const std::string message =
      write_under_limit(40 * 1024, [&] { rcm::save_plot(spec, stem); }, dir.path() / ".message");
  EXPECT_NE(message.find("figure."), std::string::npos) << message;
  EXPECT_EQ(read_text(dir.path() / "figure.png"), earlier_png);
  for (const auto& f : rcm::test::list_outputs(dir.path()))
    EXPECT_EQ(rcm::test::find_defect(f), "") << f;
  EXPECT_TRUE(rcm::test::list_temporaries(dir.path()).empty());
}

TEST(AtomicFile, TemporaryOfAKilledProcessIsRemovedByTheNextWrite) {
  TempDir dir;
  const pid_t dead = ::fork();
  if (dead == 0) ::_exit(0);
  ::waitpid(dead, nullptr, 0);
  const auto stale = dir.write(".results.json.rcm-tmp." + std::to_string(dead) + ".0", "half");
  // A live process's temporary may still be being written: kept.
  const auto live = dir.write(".results.json.rcm-tmp." + std::to_string(::getppid()) + ".0", "being written");
  const auto other = dir.write(".report.md.rcm-tmp." + std::to_string(dead) + ".0", "another file's");
  rcm::write_file_atomic(dir.path() / "results.json", "{}\n");
  EXPECT_FALSE(std::filesystem::exists(stale));
  EXPECT_TRUE(std::filesystem::exists(live));
  EXPECT_TRUE(std::filesystem::exists(other));
}

// The CLI end to end: a simulated session that does not fit stops with exit
// status 2 and the file and reason named; the session written before is intact.
TEST(AtomicFile, FullDiskStopsSimulateWithTheFileNamed) {
  TempDir dir;
  const auto out = dir.path() / "session";
  const std::vector<std::string> args{"simulate", "--quick", "--seed", "1", "--threads", "1", "--out", out.string()};
  const rcm::test::Exit first = rcm::test::run_cli(args, dir.path() / "first.log");
  ASSERT_EQ(first.code, 0) << first.log;
  std::map<std::filesystem::path, std::string> earlier;
  for (const auto& f : rcm::test::list_outputs(out)) earlier[f] = read_text(f);

  std::vector<std::string> again = args;
  again[3] = "2";
  const rcm::test::Exit full = rcm::test::run_cli(again, dir.path() / "full.log", 100 * 1024);
  EXPECT_EQ(full.code, 2) << full.log;
  EXPECT_NE(full.log.find(".csv: cannot be written: " + std::string(std::strerror(EFBIG))), std::string::npos)
      << full.log;
  EXPECT_NE(full.log.find(out.string()), std::string::npos) << full.log;
  // Every recording is larger than the limit: each is still the earlier one.
  for (const auto& [path, text] : earlier)
    if (path.extension() == ".csv") EXPECT_EQ(read_text(path), text) << path;
  for (const auto& f : rcm::test::list_outputs(out)) EXPECT_EQ(rcm::test::find_defect(f), "") << f;
  EXPECT_TRUE(rcm::test::list_temporaries(out).empty());
}

}  // namespace
