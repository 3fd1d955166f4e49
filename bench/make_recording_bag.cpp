// A recording CSV tiled to a given number of samples and written as a
// rosbag2 file (.mcap or .db3), for bench/stream_memory.py: the same samples
// as the tiled CSV the script writes, so that every command is measured on
// both. Not a product command: the writer is the tests' (tests/support).
//
//   make_recording_bag IN.csv ROWS OUT.mcap|OUT.db3
//
// Copy k of the input starts one median interval after copy k - 1 ends.

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "rcm/io/recording_reader.hpp"
#include "support/rosbag2_writer.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: make_recording_bag IN.csv ROWS OUT.mcap|OUT.db3\n");
    return 2;
  }
  try {
    const rcm::Recording in = rcm::load_recording(argv[1]);
    const auto rows = static_cast<Eigen::Index>(std::atoll(argv[2]));
    const Eigen::Index T = in.time.size();
    const rcm::RecordingSummary s = rcm::summarize_recording(in);
    const double span = in.time[T - 1] - in.time[0] + s.dt_median_s;
    rcm::Recording out;
    out.source = in.source;
    out.time.resize(rows);
    out.position.resize(rows, in.num_joints());
    out.velocity.resize(rows, in.num_joints());
    out.effort.resize(rows, in.num_joints());
    if (in.force) out.force = Eigen::MatrixXd(rows, 3);
    for (Eigen::Index k = 0; k < rows; ++k) {
      const Eigen::Index i = k % T, copy = k / T;
      out.time[k] = in.time[i] - in.time[0] + static_cast<double>(copy) * span;
      out.position.row(k) = in.position.row(i);
      out.velocity.row(k) = in.velocity.row(i);
      out.effort.row(k) = in.effort.row(i);
      if (in.force) out.force->row(k) = in.force->row(i);
    }
    rcm::test::Rosbag2WriteOptions o;
    const std::string path = argv[3];
    if (path.size() > 4 && path.substr(path.size() - 4) == ".db3") o.storage = rcm::test::Rosbag2WriteOptions::Storage::sqlite3;
    rcm::test::write_rosbag2(path, out, o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "make_recording_bag: %s\n", e.what());
    return 1;
  }
  return 0;
}
