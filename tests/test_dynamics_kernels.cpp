// The networks' kernels against a plain double reference: the LSTM kernel on
// every instruction set, the dense stack with every activation.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/fit.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/metrics.hpp"
#include "rcm/dynamics/networks.hpp"
#include "test_dynamics_networks.hpp"
#include "test_dynamics_synthetic.hpp"

using namespace rcm::dynamics;
using namespace rcm::test;

TEST(LstmKernel, MatchesDoubleReferenceOverManySteps) {
  // H = 24 pads to two 16-unit panels; head rows 16 and 3 pad to 8-row blocks.
  for (const KernelIsa isa : available_isas())
    for (int layers : {1, 2}) {
      const auto net = random_lstm(6, 24, layers, 16, 3, 11 + layers);
      LstmKernel kernel(net, isa);
      EXPECT_EQ(kernel.isa(), isa);
      auto state = kernel.create_state();
      ReferenceLstm ref(net);
      std::mt19937 rng(5);
      std::normal_distribution<double> g(0.0, 1.5);
      double worst = 0.0;
      for (int t = 0; t < 300; ++t) {
        Eigen::VectorXd x(6);
        for (int i = 0; i < 6; ++i) x(i) = g(rng);
        const Eigen::VectorXf xf = x.cast<float>();
        Eigen::VectorXf y(3);
        kernel.step(state, xf.data(), y.data());
        const Eigen::VectorXd yr = ref.step(xf.cast<double>());
        worst = std::max(worst, (y.cast<double>() - yr).cwiseAbs().maxCoeff());
      }
      EXPECT_LT(worst, 1e-5) << layers << " layers, " << to_string(isa);
    }
}

// The AVX2/FMA kernels (chosen at run time) and the portable ones compute the
// same steps: the default 1 x 128 architecture, two layers, and sizes that are
// not multiples of the panel blocks (H = 20, head 10 -> 7 outputs).
TEST(LstmKernel, Avx2AndPortableKernelsAgree) {
  if (!kernel_isa_available(KernelIsa::avx2_fma)) GTEST_SKIP() << "this CPU has no AVX2/FMA";
  struct Shape {
    int in, H, L, head, out;
  };
  for (const Shape sh : {Shape{12, 128, 1, 64, 6}, Shape{12, 128, 2, 64, 6}, Shape{5, 20, 2, 10, 7}}) {
    const auto net = make_random_lstm_network(sh.in, sh.H, sh.L, sh.head, sh.out, 21, 0.2f);
    const LstmKernel fast(net, KernelIsa::avx2_fma), portable(net, KernelIsa::portable);
    auto sf = fast.create_state(), sp = portable.create_state();
    std::mt19937 rng(9);
    std::normal_distribution<float> g(0.0f, 1.5f);
    Eigen::VectorXf x(sh.in), yf(sh.out), yp(sh.out);
    double worst = 0.0, largest = 0.0;
    for (int t = 0; t < 1000; ++t) {
      for (int i = 0; i < sh.in; ++i) x[i] = g(rng);
      fast.step(sf, x.data(), yf.data());
      portable.step(sp, x.data(), yp.data());
      worst = std::max(worst, static_cast<double>((yf - yp).cwiseAbs().maxCoeff()));
      largest = std::max(largest, static_cast<double>(yp.cwiseAbs().maxCoeff()));
    }
    EXPECT_LT(worst, 1e-5) << sh.H << " hidden, " << sh.L << " layers";
    EXPECT_GT(largest, 0.1);  // the outputs are not trivially zero
  }
}

TEST(DenseForward, MatchesReferenceWithEveryActivation) {
  std::mt19937 rng(3);
  DenseStack s;
  s.layers.push_back({random_matrix(7, 5, rng), random_matrix(7, 1, rng).col(0), Activation::relu});
  s.layers.push_back({random_matrix(9, 7, rng), random_matrix(9, 1, rng).col(0), Activation::tanh});
  s.layers.push_back({random_matrix(2, 9, rng), random_matrix(2, 1, rng).col(0), Activation::identity});
  Eigen::VectorXf x = random_matrix(5, 1, rng, 2.0f).col(0), y(2), a(s.max_width()), b(s.max_width());
  compute_dense_forward(s, x.data(), y.data(), a.data(), b.data());
  Eigen::VectorXd r = x.cast<double>();
  r = (s.layers[0].weight.cast<double>() * r + s.layers[0].bias.cast<double>()).cwiseMax(0.0);
  r = (s.layers[1].weight.cast<double>() * r + s.layers[1].bias.cast<double>()).array().tanh();
  r = s.layers[2].weight.cast<double>() * r + s.layers[2].bias.cast<double>();
  EXPECT_LT((y.cast<double>() - r).cwiseAbs().maxCoeff(), 1e-5);
}
