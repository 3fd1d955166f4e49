// TorchScript interop: an LSTM model exported as a TorchScript module with its
// normalization inside, and a TorchScript LSTM trained in PyTorch imported and
// checked against the module's own forward (layout: docs/formats.md).

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <filesystem>

#include "rcm/common/error.hpp"
#include "rcm/dynamics/training.hpp"
#include "rcm/io/atomic_file.hpp"
#include "torch_parts.hpp"

namespace rcm::dynamics {

using namespace torch_detail;

namespace {

const char* activation_name(Activation a) {
  return a == Activation::tanh ? "tanh" : a == Activation::relu ? "relu" : "identity";
}

[[noreturn]] void import_error(const std::filesystem::path& path, const std::string& field, const std::string& what) {
  InputLocation where;
  where.file = path.string();
  where.field = field;
  throw InputError(where, what);
}

}  // namespace

void export_torchscript(const LstmTorqueModel& model, const std::filesystem::path& path) {
  const auto& net = model.network();
  const auto& norm = model.normalization();
  torch::jit::Module m("rcm_torque_lstm");
  const int L = static_cast<int>(net.layers.size());
  std::string params = "[";
  for (int k = 0; k < L; ++k) {
    const auto& l = net.layers[k];
    m.register_parameter(fmt::format("lstm_weight_ih_l{}", k), tensor_of(l.weight_ih), false);
    m.register_parameter(fmt::format("lstm_weight_hh_l{}", k), tensor_of(l.weight_hh), false);
    m.register_parameter(fmt::format("lstm_bias_ih_l{}", k), tensor_of(l.bias_ih), false);
    m.register_parameter(fmt::format("lstm_bias_hh_l{}", k), tensor_of(l.bias_hh), false);
    params += fmt::format("{0}self.lstm_weight_ih_l{1}, self.lstm_weight_hh_l{1}, self.lstm_bias_ih_l{1}, "
                          "self.lstm_bias_hh_l{1}",
                          k > 0 ? ", " : "", k);
  }
  params += "]";
  std::string head;
  c10::List<std::string> acts;
  for (std::size_t k = 0; k < net.head.layers.size(); ++k) {
    const auto& l = net.head.layers[k];
    m.register_parameter(fmt::format("head_weight_{}", k), tensor_of(l.weight), false);
    m.register_parameter(fmt::format("head_bias_{}", k), tensor_of(l.bias), false);
    head += fmt::format("        y = torch.matmul(y, self.head_weight_{0}.t()) + self.head_bias_{0}\n", k);
    if (l.activation == Activation::tanh) head += "        y = torch.tanh(y)\n";
    if (l.activation == Activation::relu) head += "        y = torch.relu(y)\n";
    acts.push_back(activation_name(l.activation));
  }
  m.register_buffer("input_mean", tensor_of(norm.input_mean));
  m.register_buffer("input_scale", tensor_of(norm.input_scale));
  m.register_buffer("output_mean", tensor_of(norm.output_mean));
  m.register_buffer("output_scale", tensor_of(norm.output_scale));
  const int N = static_cast<int>(norm.input_mean.size()) / 2;
  const int F = static_cast<int>(norm.velocity_tanh_scale.size()) / std::max(1, N);
  std::string features;
  if (F > 0) {
    m.register_buffer("velocity_tanh_scale", tensor_of(norm.velocity_tanh_scale));
    features = fmt::format("        qd = x[:, :, {}:{}]\n        xn = torch.cat([xn", N, 2 * N);
    for (int f = 0; f < F; ++f)
      features += fmt::format(", torch.tanh(qd / self.velocity_tanh_scale[{}:{}])", f * N, (f + 1) * N);
    features += "], 2)\n";
  }
  // Acceleration and Dahl features: the AccelerationFilter and DahlFilter of
  // networks.hpp (the former at the model's sample period), their state
  // z = [qdot_prev, a, q_prev, z_dahl] (the parts of the features present)
  // carried across calls like (h, c); z0 = None is the reset state.
  const int K = static_cast<int>(norm.acceleration_filter_s.size());
  const int D = static_cast<int>(norm.dahl_displacement.size()) / std::max(1, N);
  std::string signature = "x: Tensor, h0: Tensor, c0: Tensor) -> Tuple[Tensor, Tensor, Tensor]";
  std::string result = ", hn, cn";
  if (K > 0 || D > 0) {
    signature =
        "x: Tensor, h0: Tensor, c0: Tensor, z0: Optional[Tensor] = None) -> Tuple[Tensor, Tensor, Tensor, Tensor]";
    result = fmt::format(", hn, cn, torch.cat([{}], 1)", K > 0 && D > 0 ? "prev, a, qprev, zd"
                                                         : K > 0       ? "prev, a"
                                                                       : "qprev, zd");
  }
  if (K > 0) {
    if (!(model.info().sample_period_s > 0))
      throw std::invalid_argument("TorchScript export: acceleration features need the model's sample period");
    m.register_buffer("acceleration_filter_s", tensor_of(norm.acceleration_filter_s));
    m.register_buffer("acceleration_scale", tensor_of(norm.acceleration_scale));
    features += fmt::format(R"JIT(        qd = x[:, :, {0}:{1}]
        dt = self.sample_period_s
        if z0 is None:
            prev = qd[:, 0]
            a = torch.zeros(x.size(0), {2}, dtype=x.dtype)
        else:
            prev = z0[:, 0:{0}]
            a = z0[:, {0}:{4}]
        alpha = (dt / (self.acceleration_filter_s + dt)).repeat_interleave({0})
        acc: List[Tensor] = []
        for t in range(x.size(1)):
            a = a + alpha * (((qd[:, t] - prev) / dt).repeat(1, {3}) - a)
            acc.append(a)
            prev = qd[:, t]
        xn = torch.cat([xn, torch.stack(acc, 1) / self.acceleration_scale], 2)
)JIT",
                            N, 2 * N, K * N, K, N + K * N);
  }
  if (D > 0) {
    // In double, as DahlFilter: x_c can be a few micrometres on a joint whose
    // position is tenths of a metre, below float resolution of q differences.
    m.register_buffer("dahl_displacement", tensor_of(norm.dahl_displacement));
    const int o = K > 0 ? N + K * N : 0;
    features += fmt::format(R"JIT(        q = x[:, :, 0:{0}].double()
        if z0 is None:
            qprev = q[:, 0]
            zd = torch.zeros(x.size(0), {3}, dtype=x.dtype).double()
        else:
            qprev = z0[:, {1}:{2}].double()
            zd = z0[:, {2}:].double()
        xc = self.dahl_displacement.double()
        dahl: List[Tensor] = []
        for t in range(x.size(1)):
            dq = (q[:, t] - qprev).repeat(1, {4})
            sg = torch.sign(dq)
            zd = sg + (zd - sg) * torch.exp(-torch.abs(dq) / xc)
            dahl.append(zd)
            qprev = q[:, t]
        xn = torch.cat([xn, torch.stack(dahl, 1).to(x.dtype)], 2)
        qprev = qprev.to(x.dtype)
        zd = zd.to(x.dtype)
)JIT",
                            N, o, o + N, D * N, D);
  }
  m.register_attribute("head_activations", c10::ListType::ofStrings(), acts);
  m.register_attribute("sample_period_s", c10::FloatType::get(), model.info().sample_period_s);
  m.register_attribute("num_layers", c10::IntType::get(), static_cast<int64_t>(L));
  m.register_attribute("hidden_size", c10::IntType::get(), static_cast<int64_t>(net.hidden_size()));
  // forward's torque at step t is that of step t - output_delay_samples.
  m.register_attribute("output_delay_samples", c10::IntType::get(), static_cast<int64_t>(model.output_delay()));
  m.define(fmt::format(R"JIT(
    def forward(self, {4}:
        xn = (x - self.input_mean) / self.input_scale
{3}        out, hn, cn = torch.lstm(xn, [h0, c0], {0}, True, {1}, 0.0, False, False, True)
        y = out
{2}        return y * self.output_scale + self.output_mean{5}
  )JIT",
                       params, L, head, features, signature, result));
  // LibTorch writes by name: to a temporary renamed once whole (rcm/io/atomic_file.hpp).
  AtomicFile file(path);
  try {
    m.save(file.get_temp_path().string());
  } catch (const c10::Error& e) {
    InputLocation where;
    where.file = path.string();
    throw InputError(where, std::string("cannot be written: ") + e.what_without_backtrace());
  }
  file.commit();
}

std::unique_ptr<LstmTorqueModel> import_torchscript(const std::filesystem::path& path) {
  torch::jit::Module m;
  try {
    m = torch::jit::load(path.string());
  } catch (const c10::Error& e) {
    import_error(path, "", std::string("not a loadable TorchScript file: ") + e.what_without_backtrace());
  }
  std::map<std::string, torch::Tensor> p;
  for (const auto& np : m.named_parameters(true)) p[np.name] = np.value;
  for (const auto& nb : m.named_buffers(true)) p[nb.name] = nb.value;
  auto get = [&](const std::string& name) -> torch::Tensor {
    auto it = p.find(name);
    if (it == p.end()) import_error(path, name, "missing parameter or buffer (see docs/formats.md for the layout)");
    return it->second;
  };
  LstmNetwork net;
  const bool rcm_layout = p.count("lstm_weight_ih_l0") > 0;
  const std::string pre = rcm_layout ? "lstm_" : "lstm.";
  for (int k = 0; p.count(fmt::format("{}weight_ih_l{}", pre, k)); ++k) {
    LstmLayer l;
    l.weight_ih = to_eigen(get(fmt::format("{}weight_ih_l{}", pre, k)));
    l.weight_hh = to_eigen(get(fmt::format("{}weight_hh_l{}", pre, k)));
    l.bias_ih = to_eigen_vector(get(fmt::format("{}bias_ih_l{}", pre, k)));
    l.bias_hh = to_eigen_vector(get(fmt::format("{}bias_hh_l{}", pre, k)));
    net.layers.push_back(std::move(l));
  }
  if (net.layers.empty()) import_error(path, "lstm.weight_ih_l0", "no LSTM layer found");
  if (rcm_layout) {
    auto acts = m.attr("head_activations").toListRef();
    for (std::size_t k = 0; k < acts.size(); ++k) {
      const auto a = acts[k].toStringRef();
      net.head.layers.push_back({to_eigen(get(fmt::format("head_weight_{}", k))),
                                 to_eigen_vector(get(fmt::format("head_bias_{}", k))),
                                 a == "tanh" ? Activation::tanh : a == "relu" ? Activation::relu : Activation::identity});
    }
  } else {
    // PyTorch layout: head = nn.Sequential(Linear, Tanh|ReLU, ..., Linear).
    if (!m.hasattr("head")) import_error(path, "head", "missing submodule (nn.Sequential of Linear and Tanh/ReLU)");
    for (const auto& child : m.attr("head").toModule().named_children()) {
      const std::string type = child.value.type()->name() ? child.value.type()->name()->qualifiedName() : "";
      if (type.find("Linear") != std::string::npos) {
        net.head.layers.push_back({to_eigen(get("head." + child.name + ".weight")),
                                   to_eigen_vector(get("head." + child.name + ".bias")), Activation::identity});
      } else if (type.find("Tanh") != std::string::npos || type.find("ReLU") != std::string::npos) {
        if (net.head.layers.empty()) import_error(path, "head." + child.name, "an activation before any Linear");
        net.head.layers.back().activation =
            type.find("Tanh") != std::string::npos ? Activation::tanh : Activation::relu;
      } else {
        import_error(path, "head." + child.name, "unsupported layer type " + type + " (Linear, Tanh, ReLU only)");
      }
    }
  }
  Normalization norm;
  norm.input_mean = to_eigen_vector(get("input_mean"));
  norm.input_scale = to_eigen_vector(get("input_scale"));
  norm.output_mean = to_eigen_vector(get("output_mean"));
  norm.output_scale = to_eigen_vector(get("output_scale"));
  if (p.count("velocity_tanh_scale")) norm.velocity_tanh_scale = to_eigen_vector(p["velocity_tanh_scale"]);
  if (p.count("acceleration_filter_s") || p.count("acceleration_scale")) {
    norm.acceleration_filter_s = to_eigen_vector(get("acceleration_filter_s"));
    norm.acceleration_scale = to_eigen_vector(get("acceleration_scale"));
  }
  if (p.count("dahl_displacement")) norm.dahl_displacement = to_eigen_vector(p["dahl_displacement"]);
  try {
    net.check();
  } catch (const std::invalid_argument& e) {
    import_error(path, "", e.what());
  }
  TorqueModelInfo info;
  if (norm.input_mean.size() % 2 != 0 || norm.input_mean.size() == 0)
    import_error(path, "input_mean", "expected 2 x joints values ([q, qdot])");
  info.num_joints = static_cast<int>(norm.input_mean.size()) / 2;
  info.num_outputs = net.output_size();
  info.sample_period_s = m.hasattr("sample_period_s") ? m.attr("sample_period_s").toDouble() : 0.0;
  if (norm.has_acceleration() && !(info.sample_period_s > 0))
    import_error(path, "sample_period_s", "acceleration features need the module's sample period (s), a float attribute");
  info.training = {{"imported_from", path.string()}};
  int delay = 0;
  if (m.hasattr("output_delay_samples")) {
    const auto d = m.attr("output_delay_samples");
    if (!d.isInt() || d.toInt() < 0 || d.toInt() > 100000)
      import_error(path, "output_delay_samples", "expected an int attribute in [0, 100000] (samples)");
    delay = static_cast<int>(d.toInt());
  }
  std::unique_ptr<LstmTorqueModel> model, undelayed;
  try {
    model = std::make_unique<LstmTorqueModel>(info, net, norm, delay);
    // The check below compares the network step for step, as forward returns it.
    undelayed = std::make_unique<LstmTorqueModel>(info, net, norm, 0);
  } catch (const std::invalid_argument& e) {
    import_error(path, "", e.what());
  }
  // The module's own forward on a random sequence must agree with the kernel.
  torch::NoGradGuard guard;
  torch::manual_seed(0);
  const int64_t T = 50, I = 2 * info.num_joints, H = net.hidden_size(), L = static_cast<int64_t>(net.layers.size());
  // A random walk rather than white noise: white qdot would make accelerations
  // that saturate every gate and hide a filter that differs from the documented one.
  // Its steps span four decades so that some are comparable to any Dahl
  // displacement (else every Dahl state would sit at +-1, whatever its x_c).
  auto walk = torch::randn({1, T, I}) * 0.05 * torch::pow(10.0, -4.0 * torch::rand({1, T, 1}));
  walk.select(1, 0).copy_(torch::randn({1, I}));
  auto x = walk.cumsum(1) * torch::from_blob(norm.input_scale.data(), {I}).clone() +
           torch::from_blob(norm.input_mean.data(), {I}).clone();
  const auto nargs = m.get_method("forward").function().getSchema().arguments().size();
  torch::Tensor y;
  if (nargs == 2) {
    auto out = m.forward({x});
    y = out.isTuple() ? out.toTuple()->elements()[0].toTensor() : out.toTensor();
  } else if (nargs == 4) {
    y = m.forward({x, torch::zeros({L, 1, H}), torch::zeros({L, 1, H})}).toTuple()->elements()[0].toTensor();
  } else if (nargs == 5) {  // forward(x, h0, c0, z0) with z0 = None: the reset state
    y = m.forward({x, torch::zeros({L, 1, H}), torch::zeros({L, 1, H}), torch::jit::IValue()})
            .toTuple()
            ->elements()[0]
            .toTensor();
  } else {
    import_error(path, "forward", "expected forward(x), forward(x, h0, c0) or forward(x, h0, c0, z0)");
  }
  Eigen::MatrixXd xd = to_eigen(x[0]).cast<double>();
  // At the module's own sample period: what its acceleration features assume.
  const double dt = info.sample_period_s > 0 ? info.sample_period_s : 1.0;
  const Eigen::MatrixXd mine = predict_torque(*undelayed, Eigen::VectorXd::LinSpaced(T, 0, dt * (T - 1)),
                                              xd.leftCols(I / 2), xd.rightCols(I / 2));
  const Eigen::MatrixXd theirs = to_eigen(y[0]).cast<double>();
  const double scale = std::max(1.0, theirs.cwiseAbs().maxCoeff());
  if ((mine - theirs).cwiseAbs().maxCoeff() > 1e-4 * scale)
    import_error(path, "forward",
                 fmt::format("the module's forward disagrees with its parameters read as the documented layout "
                             "(max difference {:.3g}); is the layout as in docs/formats.md?",
                             (mine - theirs).cwiseAbs().maxCoeff()));
  return model;
}

}  // namespace rcm::dynamics
