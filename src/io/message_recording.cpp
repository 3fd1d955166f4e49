#include "rcm/io/message_recording.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "io/stream_median.hpp"

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

JointStateSampler::JointStateSampler(std::string file, std::string topic, const TopicReadOptions& options,
                                     std::string time_label)
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

bool JointStateSampler::add(std::size_t index, std::int64_t t_ns, const JointStateView& m) {
  check_time_range(file_, topic_, index, t_ns, time_label_);
  const std::int64_t origin = messages_ == 0 ? t_ns : origin_ns_;
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
  const std::size_t N = static_cast<std::size_t>(map_.num_joints());
  values_.resize(3 * N);
  std::copy(ws_.position.begin(), ws_.position.end(), values_.begin());
  std::copy(ws_.velocity.begin(), ws_.velocity.end(), values_.begin() + static_cast<std::ptrdiff_t>(N));
  std::copy(ws_.effort.begin(), ws_.effort.end(), values_.begin() + static_cast<std::ptrdiff_t>(2 * N));
  // Repeated samples, as the CSV reader: position, velocity and effort equal to
  // the previous message's.
  const bool repeated = messages_ > 0 && values_ == previous_;
  previous_ = values_;
  if (messages_ == 0) origin_ns_ = t_ns;
  ++messages_;
  last_ns_ = t_ns;
  if (repeated) {
    ++repeated_;
    if (options_.read.dedupe) return false;
  }
  if (has_kept_ && !(t_ns > kept_ns_)) {
    const bool is_repeat = repeated && !options_.read.dedupe;
    throw InputError(
        locate(file_, describe_message_place(topic_, index, t_ns, origin_ns_) + ": " + time_label_),
        "time must increase strictly: " + format_seconds(seconds_between(t_ns, origin_ns_)) + " s after " +
            format_seconds(seconds_between(kept_ns_, origin_ns_)) + " s in message " + std::to_string(kept_index_) +
            (is_repeat ? " (this message repeats the previous sample; --dedupe drops repeated samples)" : ""));
  }
  has_kept_ = true;
  kept_ns_ = t_ns;
  kept_index_ = index;
  return true;
}

namespace {

// The force topic as it streams past: every message checked, the samples
// around the oldest joint sample still waiting kept for interpolation, the
// span and the median period counted for the tolerance at the ends.
class ForceTrack {
 public:
  ForceTrack(std::string file, std::string topic) : file_(std::move(file)), topic_(std::move(topic)) {}
  void set_time_label(std::string label) { time_label_ = std::move(label); }

  // Throws InputError for a non-finite component, a time outside [0, 2^62) ns
  // or one that does not increase.
  void add(std::size_t index, std::int64_t t_ns, const Eigen::Vector3d& f) {
    check_time_range(file_, topic_, index, t_ns, time_label_);
    const std::int64_t origin = count_ == 0 ? t_ns : front_ns_;
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(f[a]))
        throw InputError(
            locate(file_, describe_message_place(topic_, index, t_ns, origin) + ": wrench.force." + "xyz"[a]),
            "expected a finite number, got " + format_seconds(f[a]));
    if (count_ > 0 && t_ns <= last_ns_)
      throw InputError(locate(file_, describe_message_place(topic_, index, std::nullopt, 0) + ": " + time_label_),
                       "time must increase strictly: " + format_seconds(seconds_between(t_ns, last_ns_)) +
                           " s after the previous message");
    if (count_ == 0) {
      front_ns_ = t_ns;
      front_ = f;
    } else {
      periods_.add(static_cast<double>(t_ns - last_ns_));
    }
    ++count_;
    last_ns_ = t_ns;
    last_ = f;
    window_t_.push_back(t_ns);
    window_f_.push_back(f);
    prune();
  }

  // No joint sample to come is older than t_ns: the samples before the newest
  // at or before it are no longer needed.
  void set_needed(std::int64_t t_ns) {
    needed_ns_ = t_ns;
    has_needed_ = true;
    prune();
  }

  std::size_t size() const { return count_; }
  bool ended() const { return ended_; }
  // True when the force at `t_ns` is known: the topic has passed it or ended.
  bool covers(std::int64_t t_ns) const { return ended_ || (count_ > 0 && last_ns_ > t_ns); }

  // The topic has no more messages: its median period, replaying the periods
  // from `again` when the median needs them (a force topic of more than
  // 65,536 distinct periods).
  void end(MessageSource& source) {
    ended_ = true;
    if (count_ == 0) throw InputError(locate(file_, topic_), "no valid WrenchStamped message");
    while (periods_.needs_pass()) {
      periods_.start_pass();
      const auto again = source.reopen_force();
      RecordingMessage m;
      bool has_last = false;
      std::int64_t last = 0;
      while (again->next(m)) {
        if (m.topic != RecordingMessage::Topic::force) continue;
        if (has_last) periods_.add(static_cast<double>(m.t_ns - last));
        last = m.t_ns;
        has_last = true;
      }
    }
    period_ = count_ >= 2 ? static_cast<std::int64_t>(periods_.get()) : 0;
  }

  // Joint sample at t_ns (message `index` of `joint_topic`, times relative
  // to `origin_ns`): its force, or InputError when it lies more than one
  // period outside the topic's span (known once ended()).
  Eigen::Vector3d get_force(std::int64_t t_ns, const std::string& joint_topic, std::size_t index,
                            std::int64_t origin_ns) {
    if (ended_) check_span(t_ns, joint_topic, index, origin_ns);
    if (t_ns <= front_ns_) return front_;
    if (t_ns >= last_ns_) return last_;
    // The newest sample at or before t_ns, and the one after it.
    set_needed(t_ns);
    if (window_t_[0] == t_ns) return window_f_[0];
    const double a = static_cast<double>(t_ns - window_t_[0]) / static_cast<double>(window_t_[1] - window_t_[0]);
    return window_f_[0] + a * (window_f_[1] - window_f_[0]);
  }

  void check_span(std::int64_t t_ns, const std::string& joint_topic, std::size_t index, std::int64_t origin_ns) const {
    if (t_ns >= front_ns_ - period_ && t_ns <= last_ns_ + period_) return;
    throw InputError(locate(file_, topic_),
                     "covers " + format_seconds(seconds_between(front_ns_, origin_ns)) + ".." +
                         format_seconds(seconds_between(last_ns_, origin_ns)) + " s, but sample at " +
                         format_seconds(seconds_between(t_ns, origin_ns)) + " s (" +
                         describe_message_place(joint_topic, index, std::nullopt, 0) +
                         ") lies outside by more than one force period; trim the recording or leave the force "
                         "topic out");
  }

 private:
  void prune() {
    while (has_needed_ && window_t_.size() >= 2 && window_t_[1] <= needed_ns_) {
      window_t_.pop_front();
      window_f_.pop_front();
    }
  }

  std::string file_, topic_, time_label_;
  std::size_t count_ = 0;
  std::int64_t front_ns_ = 0, last_ns_ = 0, period_ = 0;
  Eigen::Vector3d front_ = Eigen::Vector3d::Zero(), last_ = Eigen::Vector3d::Zero();
  // The samples from the newest at or before the oldest waiting joint sample on.
  std::deque<std::int64_t> window_t_;
  std::deque<Eigen::Vector3d> window_f_;
  detail::StreamMedian periods_;
  bool ended_ = false, has_needed_ = false;
  std::int64_t needed_ns_ = 0;
};

}  // namespace

struct MessageRecordingReader::State {
  std::string file;
  TopicReadOptions options;
  std::optional<JointStateSampler> sampler;
  std::optional<ForceTrack> force;
  bool source_done = false;
  // Joint samples waiting for the force topic to pass their time (a ring).
  std::vector<std::int64_t> wait_t;
  std::vector<std::size_t> wait_index;
  std::vector<double> wait_values;
  std::size_t wait_head = 0, wait_size = 0;
  // The first sample, checked against the force topic's span once that is known.
  bool has_first = false, first_checked = false;
  std::int64_t first_t = 0;
  std::size_t first_index = 0;

  std::size_t stride() const { return 3 * static_cast<std::size_t>(sampler->num_joints()); }
  void push_waiting(std::int64_t t, std::size_t index, const std::vector<double>& values) {
    if (wait_size == wait_t.size()) {
      // Grow the ring, oldest first.
      const std::size_t cap = std::max<std::size_t>(16, 2 * wait_t.size()), k = stride();
      std::vector<std::int64_t> t2(cap);
      std::vector<std::size_t> i2(cap);
      std::vector<double> v2(cap * k);
      for (std::size_t n = 0; n < wait_size; ++n) {
        const std::size_t at = (wait_head + n) % wait_t.size();
        t2[n] = wait_t[at];
        i2[n] = wait_index[at];
        std::copy_n(wait_values.begin() + static_cast<std::ptrdiff_t>(at * k), k,
                    v2.begin() + static_cast<std::ptrdiff_t>(n * k));
      }
      wait_t.swap(t2);
      wait_index.swap(i2);
      wait_values.swap(v2);
      wait_head = 0;
    }
    const std::size_t at = (wait_head + wait_size) % wait_t.size();
    wait_t[at] = t;
    wait_index[at] = index;
    std::copy(values.begin(), values.end(), wait_values.begin() + static_cast<std::ptrdiff_t>(at * stride()));
    ++wait_size;
  }
};

MessageRecordingReader::MessageRecordingReader(std::string file, const TopicReadOptions& options,
                                               RecordingLayout layout, std::unique_ptr<MessageSource> source,
                                               std::size_t chunk_rows)
    : RecordingReader(file, layout, chunk_rows, options.read.dedupe),
      source_(std::move(source)),
      state_(std::make_unique<State>()) {
  State& s = *state_;
  s.file = file;
  s.options = options;
  if (!options.force_topic.empty()) s.force.emplace(file, options.force_topic);
  // Up to the first joint sample, so that the recording's joints are known.
  while (!s.source_done && s.wait_size == 0) pull();
  set_shape(s.sampler->num_joints(), s.force.has_value());
}

MessageRecordingReader::~MessageRecordingReader() = default;

const std::vector<std::string>& MessageRecordingReader::joint_names() const { return state_->sampler->joint_names(); }
std::int64_t MessageRecordingReader::time_origin_ns() const { return state_->sampler->time_origin_ns(); }
std::size_t MessageRecordingReader::force_samples() const { return state_->force ? state_->force->size() : 0; }

void MessageRecordingReader::pull() {
  State& s = *state_;
  RecordingMessage m;
  if (!source_->next(m)) {
    s.source_done = true;
    source_->finish();
    if (!s.sampler || s.sampler->messages() == 0)
      throw InputError(locate(s.file, s.options.topic), "no valid JointState message");
    if (s.force) {
      s.force->end(*source_);
      check_first_sample();
    }
    return;
  }
  if (m.topic == RecordingMessage::Topic::force) {
    if (s.force->size() == 0) s.force->set_time_label(source_->get_time_label(m.topic));
    s.force->add(m.index, m.t_ns, m.force);
    return;
  }
  if (!s.sampler) s.sampler.emplace(s.file, s.options.topic, s.options, source_->get_time_label(m.topic));
  const std::size_t repeated = s.sampler->repeated();
  const bool kept = s.sampler->add(m.index, m.t_ns, *m.joints);
  if (s.sampler->repeated() > repeated) count_repeated_row();
  if (!kept) return;
  if (!s.has_first) {
    s.has_first = true;
    s.first_t = m.t_ns;
    s.first_index = m.index;
  }
  if (s.force && s.wait_size == 0) s.force->set_needed(m.t_ns);
  s.push_waiting(m.t_ns, m.index, s.sampler->get_values());
  if (s.force && s.force->ended()) check_first_sample();
}

void MessageRecordingReader::check_first_sample() {
  State& s = *state_;
  if (s.first_checked || !s.has_first || !s.force || !s.force->ended()) return;
  s.first_checked = true;
  s.force->check_span(s.first_t, s.options.topic, s.first_index, s.sampler->time_origin_ns());
}

std::size_t MessageRecordingReader::fill_chunk(Recording& chunk, std::size_t filled) {
  State& s = *state_;
  const std::size_t rows = chunk_rows();
  while (filled < rows) {
    if (s.wait_size > 0 && (!s.force || s.force->covers(s.wait_t[s.wait_head]))) {
      const std::size_t at = s.wait_head, k = s.stride();
      const int N = s.sampler->num_joints();
      const auto t = static_cast<Eigen::Index>(filled);
      const std::int64_t t_ns = s.wait_t[at];
      chunk.time[t] = seconds_between(t_ns, s.sampler->time_origin_ns());
      const double* v = s.wait_values.data() + at * k;
      for (int j = 0; j < N; ++j) {
        chunk.position(t, j) = v[j];
        chunk.velocity(t, j) = v[N + j];
        chunk.effort(t, j) = v[2 * N + j];
      }
      if (s.force)
        chunk.force->row(t) =
            s.force->get_force(t_ns, s.options.topic, s.wait_index[at], s.sampler->time_origin_ns()).transpose();
      s.wait_head = (s.wait_head + 1) % s.wait_t.size();
      --s.wait_size;
      if (s.force && s.wait_size > 0) s.force->set_needed(s.wait_t[s.wait_head]);
      ++filled;
      continue;
    }
    if (s.source_done) {
      end_of_data_ = true;
      break;
    }
    pull();
  }
  return filled;
}
}  // namespace rcm
