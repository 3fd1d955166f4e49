#pragma once
// What the tests of the networks share (test_dynamics_kernels.cpp,
// test_dynamics_models.cpp, test_dynamics_features.cpp): random networks, a
// three-joint model's info and normalization, and a plain double LSTM written
// from the equations of torch.nn.LSTM.

#include <Eigen/Core>
#include <cmath>
#include <random>
#include <vector>

#include "rcm/dynamics/networks.hpp"
#include "rcm/dynamics/torque_model.hpp"

namespace rcm::test {

using namespace rcm::dynamics;

inline Eigen::MatrixXf random_matrix(int r, int c, std::mt19937& rng, float scale = 0.3f) {
  std::normal_distribution<float> g(0.0f, scale);
  Eigen::MatrixXf m(r, c);
  for (int i = 0; i < r; ++i)
    for (int j = 0; j < c; ++j) m(i, j) = g(rng);
  return m;
}

inline LstmNetwork random_lstm(int in, int H, int L, int head, int out, unsigned seed) {
  return make_random_lstm_network(in, H, L, head, out, seed);
}

// Three joints, three outputs at 200 Hz, and a normalization with these input scales.
inline TorqueModelInfo info3() {
  TorqueModelInfo info;
  info.num_joints = 3;
  info.num_outputs = 3;
  info.sample_period_s = 0.005;
  return info;
}
Normalization norm3(const Eigen::VectorXf& input_scale) {
  Normalization norm;
  norm.input_mean = Eigen::VectorXf::LinSpaced(6, -0.1f, 0.2f);
  norm.input_scale = input_scale;
  norm.output_mean = Eigen::VectorXf::Constant(3, 0.01f);
  norm.output_scale = Eigen::VectorXf::Constant(3, 0.3f);
  return norm;
}

// Plain double LSTM step written from the equations of torch.nn.LSTM.
struct ReferenceLstm {
  const LstmNetwork& n;
  std::vector<Eigen::VectorXd> h, c;
  explicit ReferenceLstm(const LstmNetwork& net) : n(net) {
    for (std::size_t k = 0; k < n.layers.size(); ++k) {
      h.push_back(Eigen::VectorXd::Zero(n.hidden_size()));
      c.push_back(Eigen::VectorXd::Zero(n.hidden_size()));
    }
  }
  Eigen::VectorXd step(const Eigen::VectorXd& x) {
    auto sig = [](double v) { return 1.0 / (1.0 + std::exp(-v)); };
    Eigen::VectorXd in = x;
    const int H = n.hidden_size();
    for (std::size_t k = 0; k < n.layers.size(); ++k) {
      const auto& l = n.layers[k];
      Eigen::VectorXd g = l.weight_ih.cast<double>() * in + l.weight_hh.cast<double>() * h[k] +
                          l.bias_ih.cast<double>() + l.bias_hh.cast<double>();
      for (int i = 0; i < H; ++i) {
        const double ig = sig(g(i)), fg = sig(g(H + i)), gg = std::tanh(g(2 * H + i)), og = sig(g(3 * H + i));
        c[k](i) = fg * c[k](i) + ig * gg;
        h[k](i) = og * std::tanh(c[k](i));
      }
      in = h[k];
    }
    for (const auto& l : n.head.layers) {
      in = l.weight.cast<double>() * in + l.bias.cast<double>();
      if (l.activation == Activation::tanh) in = in.array().tanh();
      if (l.activation == Activation::relu) in = in.cwiseMax(0.0);
    }
    return in;
  }
};

inline std::vector<KernelIsa> available_isas() {
  std::vector<KernelIsa> isas{KernelIsa::portable};
  if (kernel_isa_available(KernelIsa::avx2_fma)) isas.push_back(KernelIsa::avx2_fma);
  return isas;
}

}  // namespace rcm::test
