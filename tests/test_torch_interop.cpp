// The LibTorch cross-checks: the Eigen LSTM kernel against torch::nn::LSTM,
// TorchScript export -> import, and a module scripted in PyTorch imported.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <tuple>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/training.hpp"
#include "test_dynamics_synthetic.hpp"
#include "temp_dir.hpp"

using namespace rcm::dynamics;

namespace {

const rcm::Recording& synthetic_minute() {
  static const rcm::Recording rec = [] {
    rcm::test::SyntheticArmOptions so;
    so.duration_s = 60;
    return rcm::test::make_synthetic_free_space(so);
  }();
  return rec;
}

}  // namespace

namespace {
LstmNetwork random_network(int in, int H, int L, int out, unsigned seed) {
  return make_random_lstm_network(in, H, L, 64, out, seed, 0.2f);
}
}  // namespace

TEST(LstmKernel, AgreesWithLibTorchWithin1e5) {
  const auto net = random_network(6, 128, 2, 3, 4);
  std::mt19937 rng(2);
  std::normal_distribution<float> g(0.0f, 1.0f);
  Eigen::MatrixXf x(400, 6);
  for (int i = 0; i < x.size(); ++i) x.data()[i] = g(rng);
  const Eigen::MatrixXf ref = run_lstm_with_libtorch(net, x);
  for (const KernelIsa isa : {KernelIsa::portable, KernelIsa::avx2_fma}) {
    if (!kernel_isa_available(isa)) continue;
    LstmKernel kernel(net, isa);
    auto state = kernel.create_state();
    double worst = 0;
    for (int t = 0; t < x.rows(); ++t) {
      Eigen::VectorXf xt = x.row(t).transpose(), y(3);
      kernel.step(state, xt.data(), y.data());
      worst = std::max(worst, static_cast<double>((y.transpose() - ref.row(t)).cwiseAbs().maxCoeff()));
    }
    EXPECT_LE(worst, 1e-5) << to_string(isa);
  }
  // The stepping LibTorch closure used by the benchmark agrees too.
  auto stepper = make_libtorch_lstm_stepper(net);
  Eigen::VectorXf y(3);
  for (int t = 0; t < 50; ++t) {
    Eigen::VectorXf xt = x.row(t).transpose();
    stepper(xt.data(), y.data());
  }
  EXPECT_LE((y.transpose() - ref.row(49)).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(TorchScript, ExportThenImportGivesTheSameModel) {
  TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  Normalization norm{Eigen::VectorXf::LinSpaced(6, -0.1f, 0.1f), Eigen::VectorXf::Constant(6, 0.5f),
                     Eigen::VectorXf::Constant(3, 0.2f), Eigen::VectorXf::Constant(3, 2.0f)};
  // Without and with direction features (two per joint), with direction and
  // acceleration features (two time constants), with direction and Dahl
  // features (two displacements), and with all three.
  for (const auto& [features, filters, dahl] :
       {std::tuple{0, 0, 0}, std::tuple{2, 0, 0}, std::tuple{1, 2, 0}, std::tuple{1, 0, 2}, std::tuple{1, 1, 2}}) {
    norm.velocity_tanh_scale = Eigen::VectorXf::LinSpaced(3 * features, 0.004f, 0.05f);
    norm.acceleration_filter_s = Eigen::VectorXf::LinSpaced(filters, 0.01f, 0.05f);
    norm.acceleration_scale = Eigen::VectorXf::LinSpaced(3 * filters, 0.5f, 2.0f);
    norm.dahl_displacement = Eigen::VectorXf::LinSpaced(3 * dahl, 2e-4f, 5e-3f);
    // One with an output delay, which the module carries as an attribute.
    const int delay = filters == 1 ? 4 : 0;
    LstmTorqueModel model(info, random_network(6 + 3 * (features + filters + dahl), 16, 2, 3, 8), norm, delay);
    const auto path = rcm::test::get_process_temp_dir() / "rcm_test_lstm.pt";
    export_torchscript(model, path);
    const auto imported = import_torchscript(path);  // checks the module's forward internally
    EXPECT_EQ(imported->output_delay(), delay);
    EXPECT_EQ(imported->normalization().velocity_tanh_scale, norm.velocity_tanh_scale);
    EXPECT_EQ(imported->normalization().acceleration_filter_s, norm.acceleration_filter_s);
    EXPECT_EQ(imported->normalization().acceleration_scale, norm.acceleration_scale);
    EXPECT_EQ(imported->normalization().dahl_displacement, norm.dahl_displacement);
    EXPECT_EQ(imported->num_joints(), 3);
    const auto& rec = synthetic_minute();
    const Eigen::MatrixXd a = predict_torque(model, rec).topRows(500), b = predict_torque(*imported, rec).topRows(500);
    EXPECT_EQ((a - b).cwiseAbs().maxCoeff(), 0.0) << features << " features";
    EXPECT_DOUBLE_EQ(imported->info().sample_period_s, 0.005);
    if ((filters > 0 || dahl > 0) && std::system("/usr/bin/python3 -c 'import torch' > /dev/null 2>&1") == 0) {
      // The exported forward carries z = [qdot_prev, a, q_prev, z_dahl] like
      // (h, c): in PyTorch, two calls over halves of the recording equal the
      // kernel over the whole.
      const int z_size = (filters > 0 ? 3 + 3 * filters : 0) + (dahl > 0 ? 3 + 3 * dahl : 0);
      const int T = 400;
      // forward returns the network's output step for step, whatever the delay.
      const Eigen::MatrixXd raw = predict_torque(LstmTorqueModel(info, model.network(), norm), rec).topRows(T);
      const auto csv = rcm::test::get_process_temp_dir() / "rcm_test_lstm_io.csv";
      {
        std::ofstream out(csv);
        out.precision(17);
        for (int t = 0; t < T; ++t) {
          for (int k = 0; k < 3; ++k) out << static_cast<float>(rec.position(t, k)) << ",";
          for (int k = 0; k < 3; ++k) out << static_cast<float>(rec.velocity(t, k)) << ",";
          out << raw(t, 0) << "," << raw(t, 1) << "," << raw(t, 2) << "\n";
        }
      }
      const std::string check = R"PY(
import sys, torch
m = torch.jit.load(sys.argv[1])
d = torch.tensor([[float(v) for v in line.split(',')] for line in open(sys.argv[2])])
x, ref = d[None, :, :6], d[:, 6:]
h = torch.zeros(2, 1, 16)
y1, h1, c1, z1 = m(x[:, :200], h, h)
y2, _, _, _ = m(x[:, 200:], h1, c1, z1)
err = (torch.cat([y1, y2], 1)[0].double() - ref).abs().max().item()
print('max difference', err)
sys.exit(0 if z1.shape == (1, int(sys.argv[3])) and err <= 1e-4 else 1)
)PY";
      const auto check_path = rcm::test::get_process_temp_dir() / "rcm_test_check_carry.py";
      { std::ofstream(check_path) << check; }
      EXPECT_EQ(std::system(("/usr/bin/python3 " + check_path.string() + " " + path.string() + " " + csv.string() +
                             " " + std::to_string(z_size))
                                .c_str()),
                0);
      std::filesystem::remove(csv);
      std::filesystem::remove(check_path);
    }
    std::filesystem::remove(path);
  }
  // Acceleration features are filtered at the model's sample period: a model
  // without one cannot be exported.
  TorqueModelInfo no_period = info;
  no_period.sample_period_s = 0.0;
  EXPECT_THROW(export_torchscript(LstmTorqueModel(no_period, random_network(6 + 3 + 6, 16, 2, 3, 8), norm),
                                  rcm::test::get_process_temp_dir() / "rcm_test_never.pt"),
               std::invalid_argument);
  EXPECT_THROW(import_torchscript(std::filesystem::temp_directory_path() / "no_such_rcm_model.pt"), rcm::InputError);
}

TEST(TorchScript, ImportsAModuleScriptedInPyTorch) {
  // The documented PyTorch layout, scripted by Debian's python3-torch.
  if (std::system("/usr/bin/python3 -c 'import torch' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "/usr/bin/python3 with torch not available";
  const auto path = rcm::test::get_process_temp_dir() / "rcm_test_pytorch_lstm.pt";
  const std::string script = R"PY(
import sys, torch
from typing import List, Optional
torch.manual_seed(3)
class TorqueLstm(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.lstm = torch.nn.LSTM(6, 20, 2, batch_first=True)
        self.head = torch.nn.Sequential(torch.nn.Linear(20, 10), torch.nn.ReLU(), torch.nn.Linear(10, 3))
        self.register_buffer("input_mean", torch.randn(6) * 0.1)
        self.register_buffer("input_scale", torch.rand(6) + 0.5)
        self.register_buffer("output_mean", torch.randn(3))
        self.register_buffer("output_scale", torch.rand(3) + 0.5)
        self.sample_period_s = 0.005
    def forward(self, x):
        out, _ = self.lstm((x - self.input_mean) / self.input_scale)
        return self.head(out) * self.output_scale + self.output_mean
class TorqueLstmWithDirection(TorqueLstm):
    # Two direction features per joint: tanh(qdot / velocity_tanh_scale), after [q, qdot].
    def __init__(self):
        super().__init__()
        self.lstm = torch.nn.LSTM(12, 20, 2, batch_first=True)
        self.register_buffer("velocity_tanh_scale", torch.rand(6) * 0.1 + 0.01)
    def forward(self, x):
        qd = x[:, :, 3:6]
        xn = torch.cat([(x - self.input_mean) / self.input_scale, torch.tanh(qd / self.velocity_tanh_scale[0:3]),
                        torch.tanh(qd / self.velocity_tanh_scale[3:6])], 2)
        out, _ = self.lstm(xn)
        return self.head(out) * self.output_scale + self.output_mean
class TorqueLstmWithAcceleration(TorqueLstm):
    # One acceleration feature per joint: qdot differences low-passed at the
    # module's sample period, state z = [qdot_prev, a] (None: the reset state).
    def __init__(self, alpha_of_tau: bool = True):
        super().__init__()
        self.lstm = torch.nn.LSTM(9, 20, 2, batch_first=True)
        self.register_buffer("acceleration_filter_s", torch.tensor([0.03]))
        self.register_buffer("acceleration_scale", torch.rand(3) + 0.5)
        self.alpha_of_tau = alpha_of_tau
    def forward(self, x, h0, c0, z0: Optional[torch.Tensor] = None):
        qd = x[:, :, 3:6]
        dt = self.sample_period_s
        if z0 is None:
            prev = qd[:, 0]
            a = torch.zeros(x.size(0), 3)
        else:
            prev = z0[:, 0:3]
            a = z0[:, 3:6]
        # The documented filter, or (alpha_of_tau False) one that is not it.
        alpha = dt / (self.acceleration_filter_s + dt) if self.alpha_of_tau else dt / self.acceleration_filter_s
        acc: List[torch.Tensor] = []
        for t in range(x.size(1)):
            a = a + alpha * ((qd[:, t] - prev) / dt - a)
            acc.append(a)
            prev = qd[:, t]
        xn = torch.cat([(x - self.input_mean) / self.input_scale, torch.stack(acc, 1) / self.acceleration_scale], 2)
        out, (hn, cn) = self.lstm(xn, (h0, c0))
        return self.head(out) * self.output_scale + self.output_mean, hn, cn, torch.cat([prev, a], 1)
kind = sys.argv[2] if len(sys.argv) > 2 else ""
m = {"direction": TorqueLstmWithDirection, "": TorqueLstm}.get(kind, None)
m = m() if m is not None else TorqueLstmWithAcceleration(kind == "acceleration")
torch.jit.script(m).save(sys.argv[1])
)PY";
  const auto script_path = rcm::test::get_process_temp_dir() / "rcm_test_make_pytorch_lstm.py";
  { std::ofstream(script_path) << script; }
  ASSERT_EQ(std::system(("/usr/bin/python3 " + script_path.string() + " " + path.string()).c_str()), 0);
  const auto model = import_torchscript(path);  // throws if its forward disagrees with the kernel
  EXPECT_EQ(model->num_joints(), 3);
  EXPECT_EQ(model->network().layers.size(), 2u);
  EXPECT_EQ(model->network().head.layers[0].activation, Activation::relu);
  EXPECT_DOUBLE_EQ(model->info().sample_period_s, 0.005);
  EXPECT_EQ(model->normalization().velocity_tanh_scale.size(), 0);
  ASSERT_EQ(
      std::system(("/usr/bin/python3 " + script_path.string() + " " + path.string() + " direction").c_str()), 0);
  const auto with_direction = import_torchscript(path);
  EXPECT_EQ(with_direction->num_joints(), 3);
  EXPECT_EQ(with_direction->network().input_size(), 12);
  EXPECT_EQ(with_direction->normalization().velocity_tanh_scale.size(), 6);
  ASSERT_EQ(
      std::system(("/usr/bin/python3 " + script_path.string() + " " + path.string() + " acceleration").c_str()), 0);
  const auto with_acceleration = import_torchscript(path);
  EXPECT_EQ(with_acceleration->network().input_size(), 9);
  EXPECT_EQ(with_acceleration->normalization().acceleration_scale.size(), 3);
  // A module whose filter is not the documented one is refused, not imported.
  ASSERT_EQ(
      std::system(("/usr/bin/python3 " + script_path.string() + " " + path.string() + " other-filter").c_str()), 0);
  try {
    import_torchscript(path);
    ADD_FAILURE() << "a module with another filter was imported";
  } catch (const rcm::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("disagrees"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
  std::filesystem::remove(script_path);
}

