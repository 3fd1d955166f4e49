#include "rcm/io/message_recording.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "rcm/common/error.hpp"

namespace rcm {
namespace {

InputLocation locate(const std::string& file, const std::string& where) { return InputLocation::plain(file, where); }

std::string format_seconds(double s) {
  std::ostringstream o;
  o.precision(9);
  o << s;
  return o.str();
}

double seconds_between(std::int64_t t_ns, std::int64_t origin_ns) { return static_cast<double>(t_ns - origin_ns) * 1e-9; }

// Message times are held to [0, 2^62) ns (1970 to 2116): every difference,
// median period and end tolerance computed from them then fits in int64. A
// stamp outside is a corrupt field (a negative ROS 2 sec, a garbage receive
// time), not a recording of 292 years.
constexpr std::int64_t kMaxTimeNs = std::int64_t{1} << 62;

void check_time_range(const std::string& file, const std::string& topic, std::size_t index, std::int64_t t_ns,
                      const std::string& time_label) {
  if (t_ns >= 0 && t_ns < kMaxTimeNs) return;
  throw InputError(locate(file, describe_message_place(topic, index, std::nullopt, 0) + ": " + time_label),
                   std::to_string(t_ns) + " ns is not a time of a recording (expected 0 to 2^62 ns, 1970 to 2116)");
}

}  // namespace

TopicReadOptions with_session_topics(TopicReadOptions options, const RecordingReadOptions& read, bool keep_topic,
                                     bool keep_force_topic) {
  options.read = read;
  if (!keep_topic && !read.joint_topic.empty()) options.topic = read.joint_topic;
  if (!keep_force_topic && !read.force_topic.empty()) options.force_topic = read.force_topic;
  return options;
}

std::string describe_message_place(const std::string& topic, std::size_t index, std::optional<std::int64_t> t_ns,
                                   std::int64_t origin_ns) {
  std::string s = topic + " message " + std::to_string(index);
  if (t_ns) s += " (t = " + format_seconds(seconds_between(*t_ns, origin_ns)) + " s)";
  return s;
}

ForceSamples::ForceSamples(std::string file, std::string topic, std::string time_label)
    : file_(std::move(file)), topic_(std::move(topic)), time_label_(std::move(time_label)) {}

void ForceSamples::add(std::size_t index, std::int64_t t_ns, const Eigen::Vector3d& f) {
  check_time_range(file_, topic_, index, t_ns, time_label_);
  const std::int64_t origin = t_ns_.empty() ? t_ns : t_ns_.front();
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(f[a]))
      throw InputError(locate(file_, describe_message_place(topic_, index, t_ns, origin) + ": wrench.force." + "xyz"[a]),
                       "expected a finite number, got " + format_seconds(f[a]));
  if (!t_ns_.empty() && t_ns <= t_ns_.back())
    throw InputError(locate(file_, describe_message_place(topic_, index, std::nullopt, 0) + ": " + time_label_),
                     "time must increase strictly: " + format_seconds(seconds_between(t_ns, t_ns_.back())) +
                         " s after the previous message");
  t_ns_.push_back(t_ns);
  force_.push_back(f);
}

JointStateRecordingBuilder::JointStateRecordingBuilder(std::string file, std::string topic,
                                                       const TopicReadOptions& options, std::string time_label)
    : file_(std::move(file)), topic_(std::move(topic)), time_label_(std::move(time_label)), options_(options) {
  if (!options_.joint_names.empty()) {
    try {
      map_ = JointStateMap(options_.joint_names);
    } catch (const std::invalid_argument& e) {
      throw InputError(locate(file_, "joint names"), e.what());
    }
    ws_ = map_.create_workspace();
  }
}

void JointStateRecordingBuilder::add(std::size_t index, std::int64_t t_ns, const JointStateView& m) {
  check_time_range(file_, topic_, index, t_ns, time_label_);
  const std::int64_t origin = t_ns_.empty() ? t_ns : t_ns_.front();
  auto place = [&] { return describe_message_place(topic_, index, t_ns, origin); };
  if (map_.num_joints() == 0) {
    if (!m.name.empty()) {
      try {
        map_ = JointStateMap(m.name);
      } catch (const std::invalid_argument& e) {
        throw InputError(locate(file_, place() + ": name"), e.what());
      }
    } else if (!m.position.empty()) {
      map_ = JointStateMap::make_positional(static_cast<int>(m.position.size()));
    } else {
      throw InputError(locate(file_, place() + ": position"),
                       "missing (empty array); the estimator needs position, velocity and effort");
    }
    if (map_.num_joints() < options_.read.min_joints)
      throw InputError(locate(file_, place() + ": position"),
                       "missing: too few joints (" + std::to_string(map_.num_joints()) + "), at least " +
                           std::to_string(options_.read.min_joints) + " are required");
    ws_ = map_.create_workspace();
  }
  if (const JointStateDefect d = map_.compute_sample(ws_, m))
    throw InputError(locate(file_, place()), map_.describe(d, m));
  t_ns_.push_back(t_ns);
  index_.push_back(index);
  values_.insert(values_.end(), ws_.position.begin(), ws_.position.end());
  values_.insert(values_.end(), ws_.velocity.begin(), ws_.velocity.end());
  values_.insert(values_.end(), ws_.effort.begin(), ws_.effort.end());
}

Recording JointStateRecordingBuilder::finish(RecordingLayout layout) {
  if (t_ns_.empty()) throw InputError(locate(file_, topic_), "no valid JointState message");
  const int N = map_.num_joints();
  const std::size_t T = t_ns_.size();
  const std::size_t stride = 3 * static_cast<std::size_t>(N);
  auto row = [&](std::size_t t) { return values_.data() + t * stride; };

  // Repeated samples, as the CSV reader: position, velocity and effort equal to
  // the previous sample's.
  std::vector<char> repeated(T, 0);
  std::size_t repeated_count = 0;
  for (std::size_t t = 1; t < T; ++t)
    if (std::equal(row(t), row(t) + stride, row(t - 1))) {
      repeated[t] = 1;
      ++repeated_count;
    }
  kept_.clear();
  kept_.reserve(T);
  for (std::size_t t = 0; t < T; ++t)
    if (!(options_.read.dedupe && repeated[t])) kept_.push_back(t);

  origin_ns_ = t_ns_.front();
  for (std::size_t i = 1; i < kept_.size(); ++i) {
    const std::size_t t = kept_[i], prev = kept_[i - 1];
    if (t_ns_[t] > t_ns_[prev]) continue;
    const bool is_repeat = !options_.read.dedupe && repeated[t];
    throw InputError(
        locate(file_, describe_message_place(topic_, index_[t], t_ns_[t], origin_ns_) + ": " + time_label_),
        "time must increase strictly: " + format_seconds(seconds_between(t_ns_[t], origin_ns_)) + " s after " +
            format_seconds(seconds_between(t_ns_[prev], origin_ns_)) + " s in message " +
            std::to_string(index_[prev]) +
            (is_repeat ? " (this message repeats the previous sample; --dedupe drops repeated samples)" : ""));
  }

  Recording rec;
  rec.source = file_;
  rec.layout = layout;
  const auto R = static_cast<Eigen::Index>(kept_.size());
  rec.time.resize(R);
  rec.position.resize(R, N);
  rec.velocity.resize(R, N);
  rec.effort.resize(R, N);
  for (Eigen::Index i = 0; i < R; ++i) {
    const std::size_t t = kept_[static_cast<std::size_t>(i)];
    rec.time[i] = seconds_between(t_ns_[t], origin_ns_);
    const double* r = row(t);
    for (int j = 0; j < N; ++j) {
      rec.position(i, j) = r[j];
      rec.velocity(i, j) = r[N + j];
      rec.effort(i, j) = r[2 * N + j];
    }
  }
  rec.repeated_rows = repeated_count;
  rec.repeated_rows_removed = options_.read.dedupe && repeated_count > 0;
  return rec;
}

void JointStateRecordingBuilder::attach_force(Recording& rec, const ForceSamples& force) const {
  const auto& ft = force.t_ns_;
  if (ft.empty()) throw InputError(locate(file_, force.topic_), "no valid WrenchStamped message");
  std::int64_t period = 0;  // tolerance at the ends: one median force period
  if (ft.size() >= 2) {
    std::vector<std::int64_t> dt(ft.size() - 1);
    for (std::size_t i = 1; i < ft.size(); ++i) dt[i - 1] = ft[i] - ft[i - 1];
    std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
    period = dt[dt.size() / 2];
  }
  const auto R = static_cast<Eigen::Index>(kept_.size());
  if (rec.num_samples() != kept_.size())
    throw std::logic_error("JointStateRecordingBuilder::attach_force: not the recording finish() made");
  rec.force = Eigen::MatrixXd(R, 3);
  std::size_t s = 0;  // force interval [s, s + 1] holding the sample
  for (Eigen::Index i = 0; i < R; ++i) {
    const std::size_t k = kept_[static_cast<std::size_t>(i)];
    const std::int64_t t = t_ns_[k];
    if (t < ft.front() - period || t > ft.back() + period)
      throw InputError(locate(file_, force.topic_),
                       "covers " + format_seconds(seconds_between(ft.front(), origin_ns_)) + ".." +
                           format_seconds(seconds_between(ft.back(), origin_ns_)) + " s, but sample at " +
                           format_seconds(seconds_between(t, origin_ns_)) + " s (" +
                           describe_message_place(topic_, index_[k], std::nullopt, 0) +
                           ") lies outside by more than one force period; trim the recording or leave the force "
                           "topic out");
    Eigen::Vector3d f;
    if (t <= ft.front()) {
      f = force.force_.front();
    } else if (t >= ft.back()) {
      f = force.force_.back();
    } else {
      while (ft[s + 1] <= t) ++s;
      if (ft[s] == t) {
        f = force.force_[s];
      } else {
        const double a = static_cast<double>(t - ft[s]) / static_cast<double>(ft[s + 1] - ft[s]);
        f = force.force_[s] + a * (force.force_[s + 1] - force.force_[s]);
      }
    }
    rec.force->row(i) = f.transpose();
  }
}

}  // namespace rcm
