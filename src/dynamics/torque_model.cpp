#include "rcm/dynamics/torque_model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <stdexcept>
#include <utility>

#include "model_io.hpp"
#include "rcm/common/options.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/json_file.hpp"

namespace rcm::dynamics {

namespace {
constexpr const char* kFormat = "rcm-torque-model/1";
constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string base64_encode(const unsigned char* data, std::size_t n) {
  std::string out;
  out.reserve((n + 2) / 3 * 4);
  for (std::size_t i = 0; i < n; i += 3) {
    const std::uint32_t b0 = data[i];
    const std::uint32_t b1 = i + 1 < n ? data[i + 1] : 0;
    const std::uint32_t b2 = i + 2 < n ? data[i + 2] : 0;
    const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kBase64[(v >> 18) & 63];
    out += kBase64[(v >> 12) & 63];
    out += i + 1 < n ? kBase64[(v >> 6) & 63] : '=';
    out += i + 2 < n ? kBase64[v & 63] : '=';
  }
  return out;
}

bool base64_decode(const std::string& text, std::vector<unsigned char>& out) {
  if (text.size() % 4 != 0) return false;
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  out.clear();
  out.reserve(text.size() / 4 * 3);
  for (std::size_t i = 0; i < text.size(); i += 4) {
    int v[4];
    int pad = 0;
    for (int k = 0; k < 4; ++k) {
      const char c = text[i + k];
      if (c == '=' && i + 4 == text.size() && k >= 2) {
        v[k] = 0;
        ++pad;
      } else {
        if (pad) return false;
        v[k] = value(c);
        if (v[k] < 0) return false;
      }
    }
    const std::uint32_t w = (v[0] << 18) | (v[1] << 12) | (v[2] << 6) | v[3];
    out.push_back(static_cast<unsigned char>((w >> 16) & 255));
    if (pad < 2) out.push_back(static_cast<unsigned char>((w >> 8) & 255));
    if (pad < 1) out.push_back(static_cast<unsigned char>(w & 255));
  }
  return true;
}

static_assert(sizeof(float) == 4 && sizeof(double) == 8, "IEEE sizes expected");

bool host_is_little_endian() {
  const std::uint16_t x = 1;
  unsigned char b;
  std::memcpy(&b, &x, 1);
  return b == 1;
}

template <typename Scalar>
nlohmann::json encode(const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& m,
                      bool is_vector) {
  if (!host_is_little_endian()) throw std::runtime_error("model files need a little-endian host");
  nlohmann::json j;
  if (is_vector) {
    j["shape"] = {m.size()};
  } else {
    j["shape"] = {m.rows(), m.cols()};
  }
  j["dtype"] = sizeof(Scalar) == 4 ? "f32" : "f64";
  j["data"] = base64_encode(reinterpret_cast<const unsigned char*>(m.data()), sizeof(Scalar) * m.size());
  return j;
}

template <typename Scalar>
Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> decode(const nlohmann::json& j, const std::string& source,
                                                             const std::string& field, bool is_vector) {
  using detail::fail;
  if (!j.is_object()) fail(source, field, "expected an array object {shape, dtype, data}");
  const auto& shape = detail::require(j, "shape", source, field);
  const auto& dtype = detail::require(j, "dtype", source, field);
  const auto& data = detail::require(j, "data", source, field);
  const char* want = sizeof(Scalar) == 4 ? "f32" : "f64";
  if (!dtype.is_string() || dtype.get<std::string>() != want)
    fail(source, field + ".dtype", fmt::format("expected \"{}\"", want));
  if (!shape.is_array() || shape.size() != (is_vector ? 1u : 2u))
    fail(source, field + ".shape", is_vector ? "expected [n]" : "expected [rows, cols]");
  for (const auto& s : shape)
    if (!s.is_number_integer() || s.get<long long>() < 0 || s.get<long long>() > (1LL << 28))
      fail(source, field + ".shape", "expected non-negative integers");
  const Eigen::Index rows = is_vector ? shape[0].get<Eigen::Index>() : shape[0].get<Eigen::Index>();
  const Eigen::Index cols = is_vector ? 1 : shape[1].get<Eigen::Index>();
  if (!data.is_string()) fail(source, field + ".data", "expected a base64 string");
  std::vector<unsigned char> bytes;
  if (!base64_decode(data.get<std::string>(), bytes)) fail(source, field + ".data", "not valid base64");
  if (bytes.size() != static_cast<std::size_t>(rows * cols) * sizeof(Scalar))
    fail(source, field + ".data",
         fmt::format("expected {} values for shape, got {} bytes", rows * cols, bytes.size()));
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> m(rows, cols);
  if (!bytes.empty()) std::memcpy(m.data(), bytes.data(), bytes.size());
  if (!m.allFinite()) fail(source, field, "contains NaN or infinity");
  return m;
}
}  // namespace

namespace detail {

void fail(const std::string& source, const std::string& field, const std::string& what) {
  InputLocation where;
  where.file = source;
  where.field = field;
  where.kind = InputLocation::Kind::json_field;  // model files are JSON
  throw InputError(where, what);
}

const nlohmann::json& require(const nlohmann::json& j, const char* key, const std::string& source,
                              const std::string& field) {
  if (!j.is_object() || !j.contains(key))
    fail(source, field.empty() ? key : field + "." + key, "missing");
  return j.at(key);
}

nlohmann::json encode_array(const Eigen::MatrixXf& m) {
  return encode<float>(m, false);
}
nlohmann::json encode_array(const Eigen::MatrixXd& m) {
  return encode<double>(m, false);
}
nlohmann::json encode_vector(const Eigen::VectorXf& v) {
  return encode<float>(v.transpose(), true);
}
nlohmann::json encode_vector(const Eigen::VectorXd& v) {
  return encode<double>(v.transpose(), true);
}
Eigen::MatrixXf decode_array_f(const nlohmann::json& j, const std::string& source, const std::string& field) {
  return decode<float>(j, source, field, false);
}
Eigen::MatrixXd decode_array_d(const nlohmann::json& j, const std::string& source, const std::string& field) {
  return decode<double>(j, source, field, false);
}
Eigen::VectorXf decode_vector_f(const nlohmann::json& j, const std::string& source, const std::string& field,
                                Eigen::Index expected_size) {
  Eigen::VectorXf v = decode<float>(j, source, field, true).col(0);
  if (expected_size >= 0 && v.size() != expected_size)
    fail(source, field, fmt::format("expected {} values, got {}", expected_size, v.size()));
  return v;
}
Eigen::VectorXd decode_vector_d(const nlohmann::json& j, const std::string& source, const std::string& field,
                                Eigen::Index expected_size) {
  Eigen::VectorXd v = decode<double>(j, source, field, true).col(0);
  if (expected_size >= 0 && v.size() != expected_size)
    fail(source, field, fmt::format("expected {} values, got {}", expected_size, v.size()));
  return v;
}

}  // namespace detail

std::string to_string(TorqueModelKind kind) {
  switch (kind) {
    case TorqueModelKind::lstm: return "lstm";
    case TorqueModelKind::mlp: return "mlp";
    case TorqueModelKind::linear: return "linear";
    case TorqueModelKind::hybrid: return "hybrid";
  }
  return "unknown";
}

TorqueModelKind parse_torque_model_kind(const std::string& text, const std::string& what) {
  for (auto k : {TorqueModelKind::lstm, TorqueModelKind::mlp, TorqueModelKind::linear, TorqueModelKind::hybrid})
    if (text == to_string(k)) return k;
  InputLocation where;
  where.file = "command line";
  where.field = what;
  where.kind = InputLocation::Kind::plain;
  throw InputError(where, "expected lstm, mlp, linear or hybrid, got " + quote_token(text));
}

namespace {
void check_sizes(const TorqueModel& model, const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                 const Eigen::MatrixXd& velocity) {
  const Eigen::Index T = time.size();
  if (position.rows() != T || velocity.rows() != T || position.cols() != velocity.cols())
    throw std::invalid_argument("predict_torque: time, position and velocity sizes differ");
  if (position.cols() < model.num_joints())
    throw std::invalid_argument("predict_torque: fewer joints than the model reads");
}
}  // namespace

Eigen::MatrixXd predict_torque(const TorqueModel& model, const Eigen::VectorXd& time,
                               const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity) {
  check_sizes(model, time, position, velocity);
  return model.predict_sequence(time, position, velocity);
}

namespace {

// compute_step() on every sample, each row paired with the call whose torque
// is for it: what a live caller gets. The times of the samples from the last
// paired row on are kept for find_delayed_sample's walk.
class StreamingPredictor final : public TorqueSequencePredictor {
 public:
  explicit StreamingPredictor(const TorqueModel& model)
      : model_(model),
        ws_(model.create_workspace()),
        N_(model.num_joints()),
        M_(model.num_outputs()),
        q_(N_),
        qd_(N_),
        tau_(M_),
        delay_s_(model.get_output_delay_s()) {}

  void add(const Eigen::VectorXd& time, const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity,
           Eigen::MatrixXd& out) override {
    rows_.clear();
    for (Eigen::Index i = 0; i < time.size(); ++i) {
      if (calls_ == 0) first_time_ = time(i);
      last_time_ = time(i);
      times_.push_back(time(i));
      q_ = position.row(i).head(N_).transpose();
      qd_ = velocity.row(i).head(N_).transpose();
      ++samples_;
      call(time(i));
    }
    give(out);
  }

  void finish(Eigen::MatrixXd& out) override {
    rows_.clear();
    const auto T = static_cast<Eigen::Index>(samples_);
    if (T > 0) {
      // The recording's period (the model's own when they agree within 1 %): the
      // step of the held last sample (a repeated stamp would be read as the same
      // sample).
      const double model_dt = model_.info().sample_period_s;
      double dt = T > 1 && last_time_ > first_time_ ? (last_time_ - first_time_) / static_cast<double>(T - 1)
                  : model_dt > 0                     ? model_dt
                                                     : 1.0;
      if (model_dt > 0 && std::abs(dt / model_dt - 1.0) < 0.01) dt = model_dt;
      dt_ = dt;
      ended_ = true;
      const Eigen::Index max_calls = T + static_cast<Eigen::Index>(std::ceil(delay_s_ / dt)) + 2;
      while (static_cast<Eigen::Index>(filled_) < T && static_cast<Eigen::Index>(calls_) < max_calls)
        call(time_of_call(static_cast<Eigen::Index>(calls_)));
      while (filled_ < samples_) emit();
    }
    give(out);
  }

 private:
  // Calls past the last sample repeat it, time advancing by dt_.
  double time_of_call(Eigen::Index k) const {
    const auto T = static_cast<Eigen::Index>(samples_);
    if (k < T) return times_[static_cast<std::size_t>(k - base_)];
    return last_time_ + static_cast<double>(k - T + 1) * dt_;
  }

  // One compute_step (call number calls_) and the rows it pairs.
  void call(double t) {
    const auto k = static_cast<Eigen::Index>(calls_++);
    model_.compute_step(*ws_, t, q_.data(), qd_.data(), tau_.data());
    const TorqueModel::StepRuns runs = model_.get_step_runs(*ws_);
    if (runs.count >= 0) {
      for (int i = 0; i < runs.count && filled_ < samples_; ++i)
        emit(runs.torque + static_cast<std::ptrdiff_t>(i) * M_);
      prune();
      return;
    }
    Eigen::Index row = k;
    if (delay_s_ > 0) {
      const int back = find_delayed_sample(
          static_cast<int>(k + 1), time_of_call(k) - delay_s_, [&](int b) { return time_of_call(k + 1 - b); },
          last_back_ + 1);
      if (back == 0) return;
      last_back_ = back;
      row = k + 1 - back;
      if (ended_) row = std::min(row, static_cast<Eigen::Index>(samples_) - 1);
    }
    while (static_cast<Eigen::Index>(filled_) <= row) emit();
    prune();
  }

  void emit(const double* tau = nullptr) {
    const double* v = tau ? tau : tau_.data();
    rows_.insert(rows_.end(), v, v + M_);
    ++filled_;
  }
  // Keeps the times from the last paired row on (the walk starts there).
  void prune() {
    const std::size_t keep_from = filled_ > 1 ? filled_ - 1 : 0;
    while (base_ < keep_from && !times_.empty()) {
      times_.pop_front();
      ++base_;
    }
  }
  void give(Eigen::MatrixXd& out) const {
    out.resize(static_cast<Eigen::Index>(rows_.size() / static_cast<std::size_t>(M_)), M_);
    for (Eigen::Index r = 0; r < out.rows(); ++r)
      for (int j = 0; j < M_; ++j) out(r, j) = rows_[static_cast<std::size_t>(r * M_ + j)];
  }

  const TorqueModel& model_;
  std::unique_ptr<TorqueModelWorkspace> ws_;
  int N_, M_;
  Eigen::VectorXd q_, qd_, tau_;
  double delay_s_;
  std::size_t calls_ = 0, samples_ = 0, filled_ = 0;
  int last_back_ = 0;  // the last pick's distance from the newest call (find_delayed_sample's hint)
  double first_time_ = 0.0, last_time_ = 0.0, dt_ = 1.0;
  bool ended_ = false;
  std::deque<double> times_;  // of samples base_, base_ + 1, ...
  std::size_t base_ = 0;
  std::vector<double> rows_;
};

}  // namespace

std::unique_ptr<TorqueSequencePredictor> TorqueModel::create_sequence_predictor() const {
  return std::make_unique<StreamingPredictor>(*this);
}

std::unique_ptr<TorqueSequencePredictor> create_torque_predictor(const TorqueModel& model, PredictionMode mode) {
  return mode == PredictionMode::streaming ? std::make_unique<StreamingPredictor>(model)
                                           : model.create_sequence_predictor();
}

Eigen::MatrixXd predict_torque_streaming(const TorqueModel& model, const Eigen::VectorXd& time,
                                         const Eigen::MatrixXd& position, const Eigen::MatrixXd& velocity) {
  check_sizes(model, time, position, velocity);
  StreamingPredictor predictor(model);
  Eigen::MatrixXd head, tail;
  predictor.add(time, position, velocity, head);
  predictor.finish(tail);
  Eigen::MatrixXd out(head.rows() + tail.rows(), model.num_outputs());
  out << head, tail;
  return out;
}

Eigen::MatrixXd TorqueModel::predict_sequence(const Eigen::VectorXd& time, const Eigen::MatrixXd& position,
                                              const Eigen::MatrixXd& velocity) const {
  return predict_torque_streaming(*this, time, position, velocity);
}

namespace {
void check_recording_joints(const TorqueModel& model, const Recording& recording) {
  if (recording.num_joints() < model.num_joints()) {
    InputLocation where;
    where.file = recording.source;
    throw InputError(where, fmt::format("the model reads {} joints, the recording has {}", model.num_joints(),
                                        recording.num_joints()));
  }
}
}  // namespace

Eigen::MatrixXd predict_torque(const TorqueModel& model, const Recording& recording) {
  check_recording_joints(model, recording);
  return predict_torque(model, recording.time, recording.position, recording.velocity);
}

Eigen::MatrixXd predict_torque_streaming(const TorqueModel& model, const Recording& recording) {
  check_recording_joints(model, recording);
  return predict_torque_streaming(model, recording.time, recording.position, recording.velocity);
}

Eigen::MatrixXd predict_torque(const TorqueModel& model, const Recording& recording, PredictionMode mode) {
  return mode == PredictionMode::streaming ? predict_torque_streaming(model, recording)
                                           : predict_torque(model, recording);
}

RecordingTorqueStream::RecordingTorqueStream(const TorqueModel& model, PredictionMode mode)
    : model_(model), predictor_(create_torque_predictor(model, mode)) {}

void RecordingTorqueStream::add(const Recording& chunk) {
  check_recording_joints(model_, chunk);
  predictor_->add(chunk.time, chunk.position, chunk.velocity, rows_);
  // The samples still waiting for their torque, then this chunk's.
  if (waiting_.time.size() == 0) {
    waiting_ = chunk;
  } else {
    const Eigen::Index a = waiting_.time.size(), b = chunk.time.size();
    Recording both = get_recording_rows(waiting_, 0, a);
    both.time.conservativeResize(a + b);
    both.time.tail(b) = chunk.time;
    for (auto [dst, src] : {std::pair{&both.position, &chunk.position}, std::pair{&both.velocity, &chunk.velocity},
                            std::pair{&both.effort, &chunk.effort}}) {
      dst->conservativeResize(a + b, Eigen::NoChange);
      dst->bottomRows(b) = *src;
    }
    if (both.force) {
      both.force->conservativeResize(a + b, Eigen::NoChange);
      both.force->bottomRows(b) = *chunk.force;
    }
    both.line.insert(both.line.end(), chunk.line.begin(), chunk.line.end());
    both.repeated_rows = chunk.repeated_rows;
    both.repeated_rows_removed = chunk.repeated_rows_removed;
    waiting_ = std::move(both);
  }
  take_ready();
}

void RecordingTorqueStream::finish() {
  predictor_->finish(rows_);
  take_ready();
}

void RecordingTorqueStream::take_ready() {
  const Eigen::Index n = rows_.rows(), T = waiting_.time.size();
  if (n > T) throw std::logic_error("RecordingTorqueStream: more torque rows than samples");
  ready_ = get_recording_rows(waiting_, 0, n);
  ready_.repeated_rows = waiting_.repeated_rows;
  ready_.repeated_rows_removed = waiting_.repeated_rows_removed;
  torque_ = rows_;
  Recording rest = get_recording_rows(waiting_, n, T);
  rest.repeated_rows = waiting_.repeated_rows;
  rest.repeated_rows_removed = waiting_.repeated_rows_removed;
  waiting_ = std::move(rest);
}

namespace {
// Samples this many network periods apart or more are interpolated coarsely.
constexpr double kMaxInterpolatedPeriods = 4.0;
}  // namespace

std::string check_sample_period(const TorqueModel& model, const Recording& recording) {
  if (model.kind() != TorqueModelKind::lstm && model.kind() != TorqueModelKind::hybrid) return {};
  if (recording.num_samples() < 3 || model.info().sample_period_s <= 0) return {};
  std::vector<double> dt(recording.num_samples() - 1);
  for (std::size_t i = 0; i + 1 < recording.num_samples(); ++i)
    dt[i] = recording.time(i + 1) - recording.time(i);
  std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
  const double median = dt[dt.size() / 2];
  const double ratio = median / model.info().sample_period_s;
  if (ratio <= kMaxInterpolatedPeriods) return {};
  return fmt::format(
      "{}: sampled at {:.1f} Hz; the {} model's network steps at its training rate of {:.1f} Hz on inputs "
      "interpolated over {:.0f} steps between samples, which are straight lines the arm did not quite follow",
      recording.source, 1.0 / median, to_string(model.kind()), 1.0 / model.info().sample_period_s, ratio);
}

nlohmann::json torque_model_to_json(const TorqueModel& model) {
  nlohmann::json j;
  j["format"] = kFormat;
  j["kind"] = to_string(model.kind());
  j["num_joints"] = model.num_joints();
  j["num_outputs"] = model.num_outputs();
  j["sample_period_s"] = model.info().sample_period_s;
  j["inputs"] = "[q_1..q_N, qdot_1..qdot_N] (rad, m; rad/s, m/s)";
  j["training"] = model.info().training;
  j["regime"] = regime_to_json(model.info().regime);
  j["parameters"] = model.save_parameters();
  return j;
}

std::unique_ptr<TorqueModel> torque_model_from_json(const nlohmann::json& document, const std::string& source) {
  using detail::fail;
  if (!document.is_object()) fail(source, "", "expected a JSON object (rcm torque model)");
  const auto& format = detail::require(document, "format", source, "");
  if (!format.is_string() || format.get<std::string>() != kFormat)
    fail(source, "format", fmt::format("expected \"{}\"", kFormat));
  const auto& kind_j = detail::require(document, "kind", source, "");
  if (!kind_j.is_string()) fail(source, "kind", "expected a string");
  TorqueModelKind kind;
  try {
    kind = parse_torque_model_kind(kind_j.get<std::string>(), "kind");
  } catch (const InputError& e) {
    fail(source, "kind", e.reason());
  }
  TorqueModelInfo info;
  const auto& nj = detail::require(document, "num_joints", source, "");
  const auto& no = detail::require(document, "num_outputs", source, "");
  // Compared as 64-bit: get<int>() of 4294967297 would wrap to a valid-looking 1.
  auto in_range = [](const nlohmann::json& v, std::int64_t lo, std::int64_t hi) {
    if (v.is_number_unsigned()) return v.get<std::uint64_t>() >= static_cast<std::uint64_t>(lo) &&
                                      v.get<std::uint64_t>() <= static_cast<std::uint64_t>(hi);
    return v.is_number_integer() && v.get<std::int64_t>() >= lo && v.get<std::int64_t>() <= hi;
  };
  if (!in_range(nj, 1, 64)) fail(source, "num_joints", "expected an integer in 1..64");
  if (!in_range(no, 1, nj.get<std::int64_t>())) fail(source, "num_outputs", "expected an integer in 1..num_joints");
  info.num_joints = nj.get<int>();
  info.num_outputs = no.get<int>();
  const auto& sp = detail::require(document, "sample_period_s", source, "");
  if (!sp.is_number() || !(sp.get<double>() >= 0)) fail(source, "sample_period_s", "expected a number >= 0");
  info.sample_period_s = sp.get<double>();
  if (document.contains("training")) info.training = document.at("training");
  if (document.contains("regime")) {
    info.regime = regime_from_json(document.at("regime"), source);
    // The first joints, those the model reads (the linear model: 1-3).
    if (!info.regime.empty() && info.regime.num_joints() > info.num_joints)
      fail(source, "regime.position_min", fmt::format("expected at most {} joints (num_joints)", info.num_joints));
  }
  const auto& p = detail::require(document, "parameters", source, "");
  if (kind == TorqueModelKind::linear) return detail::load_linear_parameters(std::move(info), p, source);
  return detail::load_network_parameters(std::move(info), static_cast<int>(kind), p, source);
}

void save_torque_model(const std::filesystem::path& path, const TorqueModel& model) {
  save_json_file(path, torque_model_to_json(model));
}

std::unique_ptr<TorqueModel> load_torque_model(const std::filesystem::path& path) {
  return torque_model_from_json(load_json_file(path), path.string());
}

const OptionChoices<TorqueModelKind>& get_option_choices(OptionTag<TorqueModelKind>) {
  static const OptionChoices<TorqueModelKind> choices = {{"lstm", TorqueModelKind::lstm},
                                                         {"mlp", TorqueModelKind::mlp},
                                                         {"linear", TorqueModelKind::linear},
                                                         {"hybrid", TorqueModelKind::hybrid}};
  return choices;
}

}  // namespace rcm::dynamics
