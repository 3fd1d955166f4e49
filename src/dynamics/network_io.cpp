// The networks' parameters in model files (docs/formats.md, "Free-space model"):
// dense stacks, LSTM layers and the input normalization, saved bit-exact and
// loaded with errors naming the file and the JSON field.
#include <fmt/format.h>

#include <cstdint>
#include <stdexcept>

#include "model_io.hpp"
#include "network_parts.hpp"
#include "rcm/common/error.hpp"
#include "rcm/dynamics/linear_model.hpp"
#include "rcm/dynamics/networks.hpp"

namespace rcm::dynamics {

namespace {

std::string to_string(Activation a) {
  switch (a) {
    case Activation::identity: return "identity";
    case Activation::tanh: return "tanh";
    case Activation::relu: return "relu";
  }
  return "identity";
}

Activation parse_activation(const nlohmann::json& j, const std::string& source, const std::string& field) {
  if (j.is_string()) {
    const auto s = j.get<std::string>();
    if (s == "identity") return Activation::identity;
    if (s == "tanh") return Activation::tanh;
    if (s == "relu") return Activation::relu;
  }
  detail::fail(source, field, "expected \"identity\", \"tanh\" or \"relu\"");
}

}  // namespace

nlohmann::json detail::save_stack(const DenseStack& s) {
  nlohmann::json layers = nlohmann::json::array();
  for (const auto& l : s.layers)
    layers.push_back({{"weight", detail::encode_array(l.weight)},
                      {"bias", detail::encode_vector(l.bias)},
                      {"activation", to_string(l.activation)}});
  return layers;
}

namespace {

DenseStack load_stack(const nlohmann::json& j, const std::string& source, const std::string& field) {
  if (!j.is_array()) detail::fail(source, field, "expected an array of layers");
  DenseStack s;
  for (std::size_t k = 0; k < j.size(); ++k) {
    const std::string f = fmt::format("{}[{}]", field, k);
    DenseLayer l;
    l.weight = detail::decode_array_f(detail::require(j[k], "weight", source, f), source, f + ".weight");
    l.bias = detail::decode_vector_f(detail::require(j[k], "bias", source, f), source, f + ".bias");
    l.activation = parse_activation(detail::require(j[k], "activation", source, f), source, f + ".activation");
    s.layers.push_back(std::move(l));
  }
  return s;
}

}  // namespace

nlohmann::json detail::save_lstm(const LstmNetwork& n) {
  nlohmann::json layers = nlohmann::json::array();
  for (const auto& l : n.layers)
    layers.push_back({{"weight_ih", detail::encode_array(l.weight_ih)},
                      {"weight_hh", detail::encode_array(l.weight_hh)},
                      {"bias_ih", detail::encode_vector(l.bias_ih)},
                      {"bias_hh", detail::encode_vector(l.bias_hh)}});
  return {{"hidden_size", n.hidden_size()}, {"num_layers", n.layers.size()}, {"layers", layers},
          {"head", save_stack(n.head)}};
}

namespace {

LstmNetwork load_lstm(const nlohmann::json& j, const std::string& source, const std::string& field) {
  LstmNetwork n;
  const auto& layers = detail::require(j, "layers", source, field);
  if (!layers.is_array() || layers.empty()) detail::fail(source, field + ".layers", "expected a non-empty array");
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const std::string f = fmt::format("{}.layers[{}]", field, k);
    LstmLayer l;
    l.weight_ih = detail::decode_array_f(detail::require(layers[k], "weight_ih", source, f), source, f + ".weight_ih");
    l.weight_hh = detail::decode_array_f(detail::require(layers[k], "weight_hh", source, f), source, f + ".weight_hh");
    l.bias_ih = detail::decode_vector_f(detail::require(layers[k], "bias_ih", source, f), source, f + ".bias_ih");
    l.bias_hh = detail::decode_vector_f(detail::require(layers[k], "bias_hh", source, f), source, f + ".bias_hh");
    n.layers.push_back(std::move(l));
  }
  n.head = load_stack(detail::require(j, "head", source, field), source, field + ".head");
  try {
    n.check();
  } catch (const std::invalid_argument& e) {
    detail::fail(source, field, e.what());
  }
  return n;
}

}  // namespace

nlohmann::json detail::save_normalization(const Normalization& n) {
  nlohmann::json j = {{"input_mean", detail::encode_vector(n.input_mean)},
                      {"input_scale", detail::encode_vector(n.input_scale)},
                      {"output_mean", detail::encode_vector(n.output_mean)},
                      {"output_scale", detail::encode_vector(n.output_scale)}};
  // Absent when empty, so that a model without direction features writes no such field.
  if (n.velocity_tanh_scale.size() > 0) j["velocity_tanh_scale"] = detail::encode_vector(n.velocity_tanh_scale);
  if (n.has_acceleration()) {
    j["acceleration_filter_s"] = detail::encode_vector(n.acceleration_filter_s);
    j["acceleration_scale"] = detail::encode_vector(n.acceleration_scale);
  }
  if (n.has_dahl()) j["dahl_displacement"] = detail::encode_vector(n.dahl_displacement);
  return j;
}

namespace {

Normalization load_normalization(const nlohmann::json& j, const std::string& source, const std::string& field,
                                 int inputs, int outputs) {
  Normalization n;
  auto get = [&](const char* key, int size) {
    Eigen::VectorXf v =
        detail::decode_vector_f(detail::require(j, key, source, field), source, field + "." + key, size);
    return v;
  };
  n.input_mean = get("input_mean", inputs);
  n.input_scale = get("input_scale", inputs);
  n.output_mean = get("output_mean", outputs);
  n.output_scale = get("output_scale", outputs);
  if ((n.input_scale.array() <= 0).any() || (n.output_scale.array() <= 0).any())
    detail::fail(source, field, "scales must be positive");
  if (j.contains("velocity_tanh_scale")) {
    const std::string f = field + ".velocity_tanh_scale";
    n.velocity_tanh_scale = detail::decode_vector_f(j["velocity_tanh_scale"], source, f, -1);
    if (n.velocity_tanh_scale.size() % (inputs / 2) != 0)
      detail::fail(source, f, fmt::format("expected a multiple of {} values (features x joints), got {}", inputs / 2,
                                          n.velocity_tanh_scale.size()));
    if (!(n.velocity_tanh_scale.array() > 0).all()) detail::fail(source, f, "scales must be positive");
  }
  if (j.contains("acceleration_filter_s") || j.contains("acceleration_scale")) {
    // One without the other would shift every later input: both or neither.
    const std::string ff = field + ".acceleration_filter_s", fs = field + ".acceleration_scale";
    n.acceleration_filter_s =
        detail::decode_vector_f(detail::require(j, "acceleration_filter_s", source, field), source, ff, -1);
    if (n.acceleration_filter_s.size() == 0) detail::fail(source, ff, "expected at least one time constant");
    if (!(n.acceleration_filter_s.array() > 0).all()) detail::fail(source, ff, "time constants must be positive");
    n.acceleration_scale = detail::decode_vector_f(detail::require(j, "acceleration_scale", source, field), source, fs,
                                                   static_cast<int>(n.acceleration_filter_s.size()) * (inputs / 2));
    if (!(n.acceleration_scale.array() > 0).all()) detail::fail(source, fs, "scales must be positive");
  }
  if (j.contains("dahl_displacement")) {
    const std::string f = field + ".dahl_displacement";
    n.dahl_displacement = detail::decode_vector_f(j["dahl_displacement"], source, f, -1);
    if (n.dahl_displacement.size() == 0 || n.dahl_displacement.size() % (inputs / 2) != 0)
      detail::fail(source, f, fmt::format("expected a positive multiple of {} values (features x joints), got {}",
                                          inputs / 2, n.dahl_displacement.size()));
    if (!(n.dahl_displacement.array() > 0).all() || !n.dahl_displacement.allFinite())
      detail::fail(source, f, "displacements must be positive and finite");
  }
  return n;
}

}  // namespace

std::unique_ptr<TorqueModel> detail::load_network_parameters(TorqueModelInfo info, int kind_int,
                                                             const nlohmann::json& p, const std::string& source) {
  const auto kind = static_cast<TorqueModelKind>(kind_int);
  const int N = info.num_joints, M = info.num_outputs;
  try {
    if (kind == TorqueModelKind::lstm) {
      auto net = load_lstm(require(p, "lstm", source, "parameters"), source, "parameters.lstm");
      auto norm = load_normalization(require(p, "normalization", source, "parameters"), source,
                                     "parameters.normalization", 2 * N, M);
      int delay = 0;
      if (p.contains("output_delay_samples")) {
        const auto& d = p["output_delay_samples"];
        if (!d.is_number_integer() || d.get<std::int64_t>() < 0 || d.get<std::int64_t>() > 100000)
          fail(source, "parameters.output_delay_samples", "expected an integer number of samples in [0, 100000]");
        delay = d.get<int>();
      }
      return std::make_unique<LstmTorqueModel>(std::move(info), std::move(net), std::move(norm), delay);
    }
    if (kind == TorqueModelKind::mlp) {
      const auto& nets = require(p, "networks", source, "parameters");
      if (!nets.is_array()) fail(source, "parameters.networks", "expected an array");
      std::vector<DenseStack> stacks;
      for (std::size_t k = 0; k < nets.size(); ++k)
        stacks.push_back(load_stack(nets[k], source, fmt::format("parameters.networks[{}]", k)));
      auto norm = load_normalization(require(p, "normalization", source, "parameters"), source,
                                     "parameters.normalization", 2 * N, M);
      return std::make_unique<MlpTorqueModel>(std::move(info), std::move(stacks), std::move(norm));
    }
    TorqueModelInfo base_info = info;
    base_info.training = nlohmann::json::object();
    std::shared_ptr<const TorqueModel> base =
        load_linear_parameters(base_info, require(p, "base", source, "parameters"), source);
    auto linear = std::dynamic_pointer_cast<const LinearTorqueModel>(base);
    if (linear->output_delay() != 0)
      fail(source, "parameters.base.live_zero_phase",
           "the hybrid's model-based part steps beside its network without delay: expected false or absent");
    auto net = load_lstm(require(p, "residual", source, "parameters"), source, "parameters.residual");
    auto norm = load_normalization(require(p, "normalization", source, "parameters"), source,
                                   "parameters.normalization", 2 * N, M);
    return std::make_unique<HybridTorqueModel>(std::move(info), linear, std::move(net), std::move(norm));
  } catch (const std::invalid_argument& e) {
    fail(source, "parameters", e.what());
  }
}

}  // namespace rcm::dynamics
