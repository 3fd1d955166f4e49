// Saved free-space torque models (rcm-torque-model/1, load_torque_model):
// every kind rcm::core loads (linear, mlp, lstm, hybrid). An accepted model is
// run as a caller runs it (compute_step over a short trajectory, then the
// batch prediction) and saved and loaded again.
#include <cmath>
#include <vector>

#include "fuzz_support.hpp"
#include "rcm/dynamics/torque_model.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  const auto path = fuzz::write_input("model.json", data, size);
  std::unique_ptr<dynamics::TorqueModel> model;
  if (!fuzz::accepts([&] { model = dynamics::load_torque_model(path); })) return 0;
  RCM_FUZZ_CHECK(model);
  const int N = model->num_joints(), M = model->num_outputs();
  RCM_FUZZ_CHECK(N >= 1 && M >= 1 && M <= N);
  // The model has the sizes its file states, not a wrapped or rounded form of them.
  auto doc = nlohmann::json::parse(data, data + size, nullptr, false);
  RCM_FUZZ_CHECK(doc.is_object() && doc["num_joints"] == N && doc["num_outputs"] == M);

  // Four samples of a slow motion, enough for every model's filters and delay line.
  constexpr int T = 4;
  Recording rec;
  rec.source = "fuzz trajectory";
  rec.time.resize(T);
  rec.position.resize(T, N);
  rec.velocity.resize(T, N);
  rec.effort.setZero(T, N);
  for (int t = 0; t < T; ++t) {
    rec.time[t] = 0.001 * t;
    for (int j = 0; j < N; ++j) {
      rec.position(t, j) = 0.1 * std::sin(0.3 * t + j);
      rec.velocity(t, j) = 0.05 * std::cos(0.3 * t + j);
    }
  }
  auto ws = model->create_workspace();
  std::vector<double> tau(static_cast<std::size_t>(M));
  for (int t = 0; t < T; ++t) {
    const Eigen::VectorXd q = rec.position.row(t).transpose(), qd = rec.velocity.row(t).transpose();
    model->compute_step(*ws, rec.time[t], q.data(), qd.data(), tau.data());
  }
  model->reset_state(*ws);
  const Eigen::MatrixXd predicted = dynamics::predict_torque(*model, rec);
  RCM_FUZZ_CHECK(predicted.rows() == T && predicted.cols() == M);

  const nlohmann::json saved = dynamics::torque_model_to_json(*model);
  std::unique_ptr<dynamics::TorqueModel> back;
  if (!fuzz::accepts([&] { back = dynamics::torque_model_from_json(saved, "saved"); }))
    fuzz::fail_property("a saved model loads again");
  RCM_FUZZ_CHECK(back->kind() == model->kind());
  RCM_FUZZ_CHECK(back->num_joints() == N && back->num_outputs() == M);
  return 0;
}
