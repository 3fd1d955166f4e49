// A saved free-space torque model run on a recording: whole, as offline
// analysis does, and one sample at a time, as a live robot does.
//
//   free_space_model MODEL.json RECORDING.csv OUT.csv
//
// MODEL.json is any kind of model (linear, mlp, lstm, hybrid) saved by `rcm
// dynamics fit` or dynamics::save_torque_model; running one needs only
// rcm::core. RECORDING.csv should be free of tissue contact (the model predicts
// the torque of the arm moving in free space). Prints the model, how much of
// the recording lies beyond what the model was fitted on, and the per-joint
// error against the measured effort; writes OUT.csv with the offline
// prediction (time, tau_fs_1..M).
//
// `rcm dynamics eval` prints the same errors; examples/free_space_model.py is
// this program in Python.

#include <cstdio>
#include <exception>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/regime.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/io/recording.hpp"

namespace {

void print_errors(const char* what, const std::vector<rcm::dynamics::JointTorqueError>& errors) {
  std::printf("%-36s", what);
  for (const rcm::dynamics::JointTorqueError& e : errors)
    std::printf("  joint %d %.4f (%.2f %%)", e.index, e.rmse, e.nrmse_percent);
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s MODEL.json RECORDING.csv OUT.csv\n", argv[0]);
    return 2;
  }
  try {
    // The model is immutable; anything that changes while it runs lives in a
    // workspace, so one model serves any number of streams.
    const std::unique_ptr<rcm::dynamics::TorqueModel> model = rcm::dynamics::load_torque_model(argv[1]);
    const rcm::Recording recording = rcm::load_recording(argv[2]);
    const int m = model->num_outputs();
    std::printf("model: %s, reads %d joints, predicts %d, fitted at %.1f Hz, output delay %d samples\n",
                rcm::dynamics::to_string(model->kind()).c_str(), model->num_joints(), m,
                1.0 / model->info().sample_period_s, model->output_delay());

    const std::string rate_warning = rcm::dynamics::check_sample_period(*model, recording);
    if (!rate_warning.empty()) std::fprintf(stderr, "warning: %s\n", rate_warning.c_str());
    // A prediction beyond the positions, speeds and accelerations the model
    // was fitted on is an extrapolation; the model file says what it saw.
    const rcm::dynamics::RegimeMonitor regime(model->info().regime);
    std::printf("regime: %s\n", rcm::dynamics::compute_regime_summary(regime, recording).to_text().c_str());

    // Offline: the whole recording at once. The linear and hybrid models then
    // estimate the acceleration zero-phase, from later samples too.
    const Eigen::MatrixXd offline = rcm::dynamics::predict_torque(*model, recording);

    // Live: one compute_step per sample, causal, allocation-free. A model whose
    // output trails its input by d samples gives sample t's torque at call t + d.
    const Eigen::Index T = recording.time.size(), d = model->output_delay();
    std::unique_ptr<rcm::dynamics::TorqueModelWorkspace> workspace = model->create_workspace();
    Eigen::MatrixXd live(T - d, m);
    Eigen::VectorXd q(recording.num_joints()), qd(recording.num_joints()), tau(m);
    for (Eigen::Index t = 0; t < T; ++t) {
      q = recording.position.row(t).transpose();
      qd = recording.velocity.row(t).transpose();
      model->compute_step(*workspace, recording.time[t], q.data(), qd.data(), tau.data());
      if (t >= d) live.row(t - d) = tau.transpose();
    }

    const Eigen::MatrixXd measured = recording.effort.leftCols(m);
    print_errors("RMSE (NRMSE), offline", rcm::dynamics::compute_torque_errors(measured, offline));
    print_errors("RMSE (NRMSE), live", rcm::dynamics::compute_torque_errors(measured.topRows(T - d), live));

    std::ofstream out(argv[3]);
    out.precision(17);
    out << "time";
    for (int j = 1; j <= m; ++j) out << ",tau_fs_" << j;
    out << '\n';
    for (Eigen::Index t = 0; t < T; ++t) {
      out << recording.time[t];
      for (int j = 0; j < m; ++j) out << ',' << offline(t, j);
      out << '\n';
    }
    out.close();
    if (!out) {
      std::fprintf(stderr, "%s: cannot write\n", argv[3]);
      return 1;
    }
    std::printf("wrote %s (%lld samples)\n", argv[3], static_cast<long long>(T));
    return 0;
  } catch (const rcm::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
}
