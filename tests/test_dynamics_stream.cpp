// Whole-recording torque predictions over a recording given in chunks
// (TorqueSequencePredictor, RecordingTorqueStream): every model kind, batch
// and streaming, gives bit for bit the rows of predict_torque over the whole
// recording, whatever the chunk size; the samples come out with their rows.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/networks.hpp"
#include "rcm/io/recording_reader.hpp"
#include "test_dynamics_networks.hpp"
#include "test_dynamics_synthetic.hpp"

using namespace rcm::dynamics;
using namespace rcm::test;

namespace {

LinearTorqueParameters linear_parameters(bool zero_phase, bool live) {
  LinearTorqueParameters p;
  p.gravity = Eigen::VectorXd::LinSpaced(LinearTorqueModel::kGravityTerms, -0.2, 0.3);
  p.armature = Eigen::Vector3d(0.15, 0.2, 0.8);
  p.viscous = Eigen::Vector3d(0.05, 0.1, 1.0);
  p.coulomb = Eigen::Vector3d(0.1, 0.12, 0.4);
  p.offset = Eigen::Vector3d::Zero();
  p.dahl_displacement = Eigen::Vector3d(0.01, 0.01, 0.002);
  if (zero_phase) p.batch_acceleration_window_s = Eigen::Vector3d(0.1, 0.0, 0.2);
  if (live) p.batch_acceleration_window_s = Eigen::Vector3d(0.1, 0.15, 0.2);
  p.live_zero_phase = live;
  return p;
}

std::vector<std::shared_ptr<const TorqueModel>> make_models() {
  const TorqueModelInfo info = info3();
  const Normalization norm = norm3(Eigen::VectorXf::LinSpaced(6, 0.5f, 2.0f));
  std::vector<std::shared_ptr<const TorqueModel>> models;
  models.push_back(std::make_shared<LstmTorqueModel>(info, random_lstm(6, 8, 1, 4, 3, 1), norm));
  models.push_back(std::make_shared<LstmTorqueModel>(info, random_lstm(6, 8, 1, 4, 3, 2), norm, 7));  // trails 7 steps
  std::vector<DenseStack> stacks;
  std::mt19937 rng(9);
  for (int j = 0; j < 3; ++j) {
    DenseStack s;
    s.layers.push_back({random_matrix(10, 6, rng), random_matrix(10, 1, rng).col(0), Activation::tanh});
    s.layers.push_back({random_matrix(1, 10, rng), random_matrix(1, 1, rng).col(0), Activation::identity});
    stacks.push_back(s);
  }
  models.push_back(std::make_shared<MlpTorqueModel>(info, stacks, norm));
  models.push_back(std::make_shared<LinearTorqueModel>(info, linear_parameters(false, false)));
  auto zero_phase = std::make_shared<const LinearTorqueModel>(info, linear_parameters(true, false));
  models.push_back(zero_phase);
  models.push_back(std::make_shared<LinearTorqueModel>(info, linear_parameters(true, true)));
  models.push_back(std::make_shared<HybridTorqueModel>(info, zero_phase, random_lstm(6, 8, 1, 4, 3, 3), norm));
  return models;
}

// A recording with jittered stamps and a gap, so that pairing and windows meet uneven spacing.
rcm::Recording make_recording() {
  SyntheticArmOptions o;
  o.duration_s = 6;
  rcm::Recording rec = make_synthetic_free_space(o);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> jitter(-4e-4, 4e-4);
  for (Eigen::Index t = 1; t + 1 < rec.time.size(); ++t) rec.time[t] += jitter(rng);
  rec.time.tail(300).array() += 0.3;
  return rec;
}

TEST(TorqueStream, ChunksGiveTheWholeRecordingsRowsForEveryModel) {
  const rcm::Recording rec = make_recording();
  for (const auto& model : make_models()) {
    for (PredictionMode mode : {PredictionMode::batch, PredictionMode::streaming}) {
      const Eigen::MatrixXd whole = predict_torque(*model, rec, mode);
      ASSERT_EQ(whole.rows(), rec.time.size());
      for (Eigen::Index rows : {1, 37, 1000}) {
        SCOPED_TRACE(to_string(model->kind()) + " delay " + std::to_string(model->output_delay()) +
                     (mode == PredictionMode::batch ? " batch" : " streaming") + ", chunks of " + std::to_string(rows));
        RecordingTorqueStream stream(*model, mode);
        const auto reader = rcm::open_recording_rows(rec, static_cast<std::size_t>(rows));
        rcm::Recording chunk;
        Eigen::Index done = 0;
        auto check = [&] {
          const rcm::Recording& s = stream.get_samples();
          const Eigen::MatrixXd& tau = stream.get_torque();
          ASSERT_EQ(s.time.size(), tau.rows());
          for (Eigen::Index r = 0; r < tau.rows(); ++r) {
            ASSERT_EQ(s.time(r), rec.time(done + r));
            ASSERT_EQ(tau.row(r), whole.row(done + r)) << "sample " << done + r;
          }
          done += tau.rows();
        };
        while (reader->read_chunk(chunk)) {
          stream.add(chunk);
          check();
        }
        stream.finish();
        check();
        EXPECT_EQ(done, rec.time.size());
      }
    }
  }
}

TEST(TorqueStream, TheErrorsOfChunksAreTheWholeErrors) {
  const rcm::Recording rec = make_recording();
  const auto model = make_models()[4];
  const auto whole = evaluate_torque_model(*model, {rec});
  TorqueErrorAccumulator parts(3);
  const Eigen::MatrixXd p = predict_torque(*model, rec);
  for (Eigen::Index at = 0; at < rec.time.size(); at += 100) {
    const Eigen::Index n = std::min<Eigen::Index>(100, rec.time.size() - at);
    parts.add(rec.effort.middleRows(at, n), p.middleRows(at, n));
  }
  const auto chunked = parts.get_errors();
  for (std::size_t j = 0; j < 3; ++j) {
    EXPECT_EQ(whole[j].rmse, chunked[j].rmse);
    EXPECT_EQ(whole[j].range, chunked[j].range);
  }
}

}  // namespace
