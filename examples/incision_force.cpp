// The force at the incision over a whole recording (paper Eq. 6):
//
//   f_inc_base = J_D^-T (tau - tau_fs)
//
//   incision_force SESSION.json MODEL.json OUT.csv
//
// The recording is the session's calibration, whose coaxial offset D* is known
// (a phantom bench measures it); on a trial, use the D that estimate_offset
// found. MODEL.json is a saved free-space torque model (`rcm dynamics fit`).
// Writes OUT.csv (time, force_x, force_y, force_z in the base frame, N; theta,
// rad; the Jacobian's status) and, when the recording has force columns from a
// sensor, prints the RMSE per axis against them.
//
// The same as `rcm force --model MODEL.json --offset D* --q0 ... calibration.csv`;
// examples/incision_force.py is this program in Python.

#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <memory>
#include <string>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/torque_model.hpp"
#include "rcm/force/incision_force.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/session.hpp"
#include "rcm/kinematics/incision.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s SESSION.json MODEL.json OUT.csv\n", argv[0]);
    return 2;
  }
  try {
    const rcm::Session session = rcm::load_session(argv[1]);
    if (!session.calibration) {
      std::fprintf(stderr, "%s: the session has no calibration, so no recording with a known D\n", argv[1]);
      return 2;
    }
    const std::unique_ptr<rcm::dynamics::TorqueModel> model = rcm::dynamics::load_torque_model(argv[2]);
    const rcm::Recording recording = rcm::load_recording(session.calibration->recording);
    const double D = session.calibration->coaxial_offset_m;

    // A recurrent model learned per-sample dynamics at one rate: say so when
    // the recording was sampled at another.
    const std::string rate_warning = rcm::dynamics::check_sample_period(*model, recording);
    if (!rate_warning.empty()) std::fprintf(stderr, "warning: %s\n", rate_warning.c_str());

    // The model runs over the whole recording with its state carried, so the
    // friction the joints remember reaches every sample.
    const Eigen::MatrixXd tau_fs = rcm::dynamics::predict_torque(*model, recording);

    // The incision frame is that of DH frame 3 at the docking configuration q0.
    const rcm::IncisionFrame incision = rcm::make_incision_frame(session.q0);
    const rcm::IncisionForceSeries series = rcm::compute_incision_force_series(incision, recording, tau_fs, D);

    std::ofstream out(argv[3]);
    out.precision(17);
    out << "time,force_x,force_y,force_z,theta,status\n";
    for (Eigen::Index t = 0; t < series.f_inc_base.rows(); ++t)
      out << recording.time[t] << ',' << series.f_inc_base(t, 0) << ',' << series.f_inc_base(t, 1) << ','
          << series.f_inc_base(t, 2) << ',' << series.theta[t] << ','
          << rcm::to_string(series.status[static_cast<std::size_t>(t)]) << '\n';
    out.close();
    if (!out) {
      std::fprintf(stderr, "%s: cannot write\n", argv[3]);
      return 1;
    }

    std::printf("%s: %zu samples at D = %.1f mm, model %s; %zu ill-conditioned, %zu singular (NaN rows)\n",
                recording.source.c_str(), recording.num_samples(), 1e3 * D,
                rcm::dynamics::to_string(model->kind()).c_str(), series.num_ill_conditioned, series.num_singular);
    // Near the RCM (small D) or at large pivot angles J_D amplifies torque
    // noise: an ill-conditioned sample's force is computed but not to be trusted.
    if (recording.force && series.num_ill_conditioned + series.num_singular < recording.num_samples()) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      std::size_t n = 0;
      for (Eigen::Index t = 0; t < series.f_inc_base.rows(); ++t) {
        if (series.status[static_cast<std::size_t>(t)] != rcm::JacobianStatus::ok) continue;
        sum += (series.f_inc_base.row(t) - recording.force->row(t)).cwiseAbs2().transpose();
        ++n;
      }
      const Eigen::Vector3d rmse = (sum / static_cast<double>(n)).cwiseSqrt();
      std::printf("RMSE against the force sensor over %zu well-conditioned samples: x %.2f, y %.2f, z %.2f N\n", n,
                  rmse[0], rmse[1], rmse[2]);
    }
    std::printf("wrote %s\n", argv[3]);
    return 0;
  } catch (const rcm::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
}
