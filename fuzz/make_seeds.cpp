// Writes the binary seed corpora (MCAP, rosbag2 SQLite, CDR messages, ROS 1
// bags) and the network torque models from a short rcm recording, with rcm's
// own writers, so that every seed is what the readers meet in practice:
//
//   fuzz_make_seeds RECORDING.csv LINEAR_MODEL.json OUT_DIR STORAGE_DIR
//
// OUT_DIR gets one folder per target (mcap/, rosbag2_db3/, rosbag2_metadata/,
// cdr/, torque_model/, ros_bag/ when built with ROS); STORAGE_DIR the split
// bag's storage files that the metadata target's directory holds.
// fuzz/make_seeds.sh runs it.
#include <sqlite3.h>

#include <cstdio>
#include <fstream>
#include <iostream>

#include "io/rosbag2/cdr.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/networks.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/recording.hpp"
#include "support/rosbag2_writer.hpp"
#ifdef RCM_FUZZ_WITH_ROS
#include <geometry_msgs/WrenchStamped.h>
#include <rosbag/bag.h>
#include <sensor_msgs/JointState.h>
#endif

namespace {

namespace fs = std::filesystem;
using rcm::test::Rosbag2WriteOptions;

void write_bytes(const fs::path& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()),
                                              static_cast<std::streamsize>(bytes.size()));
}

// rosbag2 writes 4 KiB pages; 512-byte pages keep a seed of a few messages a few KiB.
void shrink_db3(const fs::path& path) {
  sqlite3* db = nullptr;
  if (sqlite3_open(path.c_str(), &db) != SQLITE_OK ||
      sqlite3_exec(db, "PRAGMA page_size = 512; VACUUM;", nullptr, nullptr, nullptr) != SQLITE_OK)
    throw std::runtime_error("cannot shrink " + path.string());
  sqlite3_close(db);
}

void write_mcap_seeds(const rcm::Recording& rec, const fs::path& dir) {
  struct Layout {
    const char* name;
    const char* compression;
    bool chunked, summary, indexes;
  };
  const Layout layouts[] = {{"zstd_chunked", "zstd", true, true, true},
                            {"lz4_chunked", "lz4", true, true, true},
                            {"uncompressed_chunked", "", true, true, true},
                            {"unchunked", "", false, true, false},
                            {"no_summary", "zstd", true, false, false}};
  for (const Layout& l : layouts) {
    Rosbag2WriteOptions o;
    o.storage = Rosbag2WriteOptions::Storage::mcap;
    o.mcap_compression = l.compression;
    o.mcap_chunked = l.chunked;
    o.mcap_summary = l.summary;
    o.mcap_message_indexes = l.indexes;
    o.mcap_chunk_bytes = 1024;  // several chunks even for a few messages
    rcm::test::write_rosbag2(dir / (std::string(l.name) + ".mcap"), rec, o);
  }
}

void write_db3_seeds(const rcm::Recording& rec, const fs::path& dir) {
  for (const int schema : {0, 3, 4}) {
    Rosbag2WriteOptions o;
    o.storage = Rosbag2WriteOptions::Storage::sqlite3;
    o.sqlite_schema = schema;
    const fs::path path = dir / ("schema" + std::to_string(schema) + ".db3");
    rcm::test::write_rosbag2(path, rec, o);
    shrink_db3(path);
  }
}

void write_cdr_seeds(const rcm::Recording& rec, const fs::path& dir) {
  rcm::cdr::JointState js;
  js.header.sec = 1700000000;
  js.header.nanosec = 123456789;
  js.header.frame_id = "PSM1_base";
  js.name = rcm::test::default_joint_names(rec.num_joints());
  for (int j = 0; j < rec.num_joints(); ++j) {
    js.position.push_back(rec.position(0, j));
    js.velocity.push_back(rec.velocity(0, j));
    js.effort.push_back(rec.effort(0, j));
  }
  rcm::cdr::WrenchStamped w;
  w.header = js.header;
  for (int a = 0; a < 3; ++a) w.force[a] = rec.force ? (*rec.force)(0, a) : 0.5 * a;
  for (const bool big : {false, true}) {
    const std::string order = big ? "be" : "le";
    write_bytes(dir / ("joint_state_" + order + ".cdr"), rcm::cdr::encode(js, big));
    write_bytes(dir / ("wrench_" + order + ".cdr"), rcm::cdr::encode(w, big));
  }
  js.name.clear();  // positional, as some drivers publish
  write_bytes(dir / "joint_state_no_names_le.cdr", rcm::cdr::encode(js, false));
}

void write_model_seeds(const rcm::Recording& rec, const fs::path& linear_path, const fs::path& dir) {
  using namespace rcm::dynamics;
  auto linear_any = load_torque_model(linear_path);
  const int N = linear_any->num_joints(), M = linear_any->num_outputs();
  TorqueModelInfo info = linear_any->info();
  info.training = nlohmann::json::object();
  Normalization norm;
  norm.input_mean = Eigen::VectorXf::Zero(2 * N);
  norm.input_scale = Eigen::VectorXf::Ones(2 * N);
  norm.output_mean = Eigen::VectorXf::Zero(M);
  norm.output_scale = Eigen::VectorXf::Ones(M);
  save_torque_model(dir / "mlp.json", MlpTorqueModel(info, make_random_mlp_stacks(2 * N, 4, M, 1), norm));
  save_torque_model(dir / "lstm.json", LstmTorqueModel(info, make_random_lstm_network(2 * N, 3, 1, 3, M, 2), norm));
  std::shared_ptr<const LinearTorqueModel> base(dynamic_cast<const LinearTorqueModel*>(linear_any.release()));
  LinearTorqueParameters with_profile = base->parameters();  // a Coulomb level along the travel
  with_profile.coulomb_profile = Eigen::MatrixXd::Zero(M, kCoulombProfileKnots);
  with_profile.coulomb_profile.col(1).setConstant(0.05);
  with_profile.coulomb_profile.col(kCoulombProfileKnots - 1).setConstant(0.08);
  with_profile.coulomb_profile_range = Eigen::MatrixXd(M, 2);
  with_profile.coulomb_profile_range.col(0).setConstant(-0.5);
  with_profile.coulomb_profile_range.col(1).setConstant(0.5);
  save_torque_model(dir / "linear_profile.json", LinearTorqueModel(info, with_profile));
  LinearTorqueParameters causal = base->parameters();  // the hybrid's base steps without delay
  causal.live_zero_phase = false;
  save_torque_model(dir / "hybrid.json",
                    HybridTorqueModel(info, std::make_shared<const LinearTorqueModel>(info, causal),
                                      make_random_lstm_network(2 * N, 3, 1, 3, M, 3), norm));
  (void)rec;
}

// metadata.yaml of split bag directories named "bag", as the metadata target's
// directory is, and their storage files (bag_0 and bag_1 of each kind) in `storage`.
void write_metadata_seeds(const rcm::Recording& rec, const fs::path& dir, const fs::path& storage) {
  const fs::path scratch = dir / "bag";
  for (const bool mcap : {true, false}) {
    Rosbag2WriteOptions o;
    o.storage = mcap ? Rosbag2WriteOptions::Storage::mcap : Rosbag2WriteOptions::Storage::sqlite3;
    o.metadata_version = mcap ? 9 : 5;
    o.split_every = static_cast<std::size_t>(rec.time.size() + 1) / 2;
    rcm::test::write_rosbag2(scratch, rec, o);
    fs::copy_file(scratch / "metadata.yaml", dir / (mcap ? "mcap_v9_split.yaml" : "sqlite3_v5_split.yaml"),
                  fs::copy_options::overwrite_existing);
    for (const char* f : {"bag_0", "bag_1"}) {
      const std::string name = std::string(f) + (mcap ? ".mcap" : ".db3");
      fs::copy_file(scratch / name, storage / name, fs::copy_options::overwrite_existing);
      if (!mcap) shrink_db3(storage / name);
    }
    fs::remove_all(scratch);
  }
}

#ifdef RCM_FUZZ_WITH_ROS
void write_ros_bag_seeds(const rcm::Recording& rec, const fs::path& dir) {
  const auto names = rcm::test::default_joint_names(rec.num_joints());
  for (const auto compression : {rosbag::compression::Uncompressed, rosbag::compression::LZ4,
                                 rosbag::compression::BZ2}) {
    const char* label = compression == rosbag::compression::LZ4   ? "lz4"
                        : compression == rosbag::compression::BZ2 ? "bz2"
                                                                  : "uncompressed";
    rosbag::Bag bag;
    bag.open((dir / (std::string(label) + ".bag")).string(), rosbag::bagmode::Write);
    bag.setCompression(compression);
    for (Eigen::Index k = 0; k < rec.time.size(); ++k) {
      sensor_msgs::JointState m;
      m.header.stamp.fromNSec(1700000000000000000ULL + static_cast<std::uint64_t>(std::llround(rec.time(k) * 1e9)));
      for (int j = 0; j < rec.num_joints(); ++j) {
        m.name.push_back(names[static_cast<std::size_t>(j)]);
        m.position.push_back(rec.position(k, j));
        m.velocity.push_back(rec.velocity(k, j));
        m.effort.push_back(rec.effort(k, j));
      }
      bag.write("/PSM1/measured_js", m.header.stamp + ros::Duration(0.0003), m);
      if (rec.force) {
        geometry_msgs::WrenchStamped w;
        w.header.stamp = m.header.stamp;
        w.header.frame_id = "PSM1_base";
        w.wrench.force.x = (*rec.force)(k, 0);
        w.wrench.force.y = (*rec.force)(k, 1);
        w.wrench.force.z = (*rec.force)(k, 2);
        bag.write("/PSM1/body/measured_cf", m.header.stamp + ros::Duration(0.0005), w);
      }
    }
    bag.close();
  }
}
#endif

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5) {
    std::cerr << "usage: fuzz_make_seeds RECORDING.csv LINEAR_MODEL.json OUT_DIR STORAGE_DIR\n";
    return 2;
  }
  try {
    rcm::RecordingReadOptions read;
    const rcm::Recording rec = rcm::load_recording(argv[1], read);
    const fs::path out = argv[3];
    for (const char* d : {"mcap", "rosbag2_db3", "rosbag2_metadata", "cdr", "torque_model", "ros_bag"}) fs::create_directories(out / d);
    write_mcap_seeds(rec, out / "mcap");
    write_db3_seeds(rec, out / "rosbag2_db3");
    fs::create_directories(argv[4]);
    write_metadata_seeds(rec, out / "rosbag2_metadata", argv[4]);
    write_cdr_seeds(rec, out / "cdr");
    write_model_seeds(rec, argv[2], out / "torque_model");
#ifdef RCM_FUZZ_WITH_ROS
    write_ros_bag_seeds(rec, out / "ros_bag");
#endif
  } catch (const std::exception& e) {
    std::cerr << "fuzz_make_seeds: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
