#pragma once
// The phases of rcm_procedure_dds (rcm_procedure_dds.cpp has the overview).

#include <dds/dds.h>

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "support/child_process.hpp"
#include "support/crtk_client.hpp"
#include "live_observer.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/session.hpp"
#include "rcm/live/trajectory_player.hpp"

namespace rcm::dds_node {

struct ProcedureOptions {
  std::filesystem::path out = "rcm-procedure";
  std::string arm = "PSM1", robot = "dvrk-psm-classic";
  int domain = -1;
  bool simulator = false, power = false, yes = false;
  Eigen::Vector3d q0 = Eigen::Vector3d(0.0, 0.0, 0.12);
  std::string excitation;
  double excite_duration_s = 120.0;
  unsigned seed = 1;
  double baseline_s = 10.0;
  double calibration_offset_m = 0.030, calibration_s = 30.0;
  std::string calibration_trajectory;
  std::vector<std::string> setup_args, excite_args;
  Eigen::Vector3d check_offset_m = Eigen::Vector3d(0.005, 0.010, 0.025);
  double check_s = 30.0;
  double live_s = 60.0;
  bool software_rcm = false;
  std::string incision_motion;
  double loop_s = 90.0;
  double jump_threshold = 4.0;
  std::optional<double> tolerance_m, compensate_limit_m, max_shift_rate_m_per_s;
  std::string max_tracking_error_text;
  PlayerOptions player;
  std::string rcm, monitor;  // programs; empty: beside this one
  // Both given: a setup made before (a session and its model); the procedure
  // goes straight to the live phase. With them, optionally, the tissue model
  // that setup saved (else the monitor identifies it on the calibration).
  std::string session, model_file, tissue_model_file;
  // Throws InputError at `flag(name)`; fills rcm, monitor and the players' limits.
  void check(const std::function<InputLocation(const std::string&)>& flag);
};

class Procedure {
 public:
  Procedure(const ProcedureOptions& options, std::function<bool()> interrupted);
  ~Procedure();
  // 0 every phase done; 3 the arm refused or setup found it not ready; 4 a
  // phase stopped (a safety stop, a monitor that did not come up).
  int run();

 private:
  int run_phases();
  int run_live_phase();
  void say(const std::string& line);
  // Plays or records one phase into out/`file` (empty: not kept); false when it did not finish.
  bool play(const std::string& name, TrajectoryPlayer& player, const std::string& file);
  bool move_to_q0();
  void sim_command(const std::string& text);
  bool confirm(const std::string& what);
  bool start_monitor(const std::string& segment, bool loop);
  int stop_monitor();
  void write_session();
  bool run_check();
  bool run_loop();
  bool run_live();

  ProcedureOptions o_;
  std::function<bool()> interrupted_;
  dds_entity_t participant_ = 0, incision_writer_ = 0;
  std::unique_ptr<CrtkClient> arm_;
  std::unique_ptr<LiveObserver> observer_;
  std::unique_ptr<Child> monitor_;
  std::string monitor_log_;
  Session session_;
  nlohmann::json report_;
  std::int64_t start_ns_ = 0;
  bool live_segment_ = false;
};

}  // namespace rcm::dds_node
