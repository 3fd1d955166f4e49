#include "rcm/ros/bag_reader.hpp"

#include <geometry_msgs/WrenchStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/JointState.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <sstream>

#include "rcm/common/error.hpp"
#include "rcm/ros/joint_state_map.hpp"

namespace rcm {
namespace {

InputLocation locate(const std::filesystem::path& path, const std::string& where) {
  InputLocation loc;
  loc.file = path.string();
  loc.field = where;
  loc.kind = InputLocation::Kind::plain;
  return loc;
}

std::string format_seconds(double s) {
  std::ostringstream o;
  o.precision(9);
  o << s;
  return o.str();
}

// "topic message k (t = 1.234 s)"; t relative to `origin_ns` when known.
std::string message_place(const std::string& topic, std::size_t k, std::optional<std::int64_t> t_ns,
                          std::int64_t origin_ns) {
  std::string s = topic + " message " + std::to_string(k);
  if (t_ns) s += " (t = " + format_seconds(static_cast<double>(*t_ns - origin_ns) * 1e-9) + " s)";
  return s;
}

// The topics of a bag with their types and counts, for "no such topic" errors.
std::string list_topics(const rosbag::Bag& bag) {
  rosbag::View all(bag);
  std::map<std::string, std::pair<std::string, std::size_t>> topics;
  for (const rosbag::ConnectionInfo* c : all.getConnections()) topics[c->topic].first = c->datatype;
  for (const rosbag::MessageInstance& m : all) ++topics[m.getTopic()].second;
  if (topics.empty()) return "the bag has no messages";
  std::string s = "the bag has: ";
  bool first = true;
  for (const auto& [name, t] : topics) {
    if (!first) s += ", ";
    first = false;
    s += name + " (" + t.first + ", " + std::to_string(t.second) + " messages)";
  }
  return s;
}

// Opens `topic` and checks it exists with `datatype`.
void check_topic(const rosbag::Bag& bag, const std::filesystem::path& path, const std::string& topic,
                 const std::string& datatype, const char* what) {
  rosbag::View view(bag, rosbag::TopicQuery(topic));
  if (view.size() == 0)
    throw InputError(locate(path, topic), std::string("no messages on this ") + what + " topic; " + list_topics(bag));
  for (const rosbag::ConnectionInfo* c : view.getConnections())
    if (c->datatype != datatype)
      throw InputError(locate(path, topic), "has type " + c->datatype + ", expected " + datatype);
}

// Header stamp, or the bag time when the topic's stamps are all zero (decided
// by its first message).
struct TimeRule {
  std::optional<bool> use_bag_time;
  std::int64_t get(const std::filesystem::path& path, const std::string& topic, std::size_t k,
                   const ros::Time& stamp, const ros::Time& bag_time) {
    const bool zero = stamp.isZero();
    if (!use_bag_time) use_bag_time = zero;
    if (*use_bag_time && !zero)
      throw InputError(locate(path, message_place(topic, k, std::nullopt, 0) + ": header.stamp"),
                       "non-zero, but the topic's first message has a zero stamp: stamps must be set on every "
                       "message or on none (then the bag's receive time is used)");
    if (!*use_bag_time && zero)
      throw InputError(locate(path, message_place(topic, k, std::nullopt, 0) + ": header.stamp"),
                       "zero, but the topic's first message has a stamp: stamps must be set on every message or on "
                       "none (then the bag's receive time is used)");
    return static_cast<std::int64_t>((*use_bag_time ? bag_time : stamp).toNSec());
  }
};

struct ForceSeries {
  std::vector<std::int64_t> t_ns;
  std::vector<Eigen::Vector3d> f;
};

ForceSeries read_force(const rosbag::Bag& bag, const std::filesystem::path& path, const std::string& topic,
                       BagReadInfo& info) {
  check_topic(bag, path, topic, "geometry_msgs/WrenchStamped", "force");
  ForceSeries out;
  TimeRule rule;
  rosbag::View view(bag, rosbag::TopicQuery(topic));
  std::size_t k = 0;
  for (const rosbag::MessageInstance& mi : view) {
    const auto msg = mi.instantiate<geometry_msgs::WrenchStamped>();
    const std::int64_t t = rule.get(path, topic, k, msg->header.stamp, mi.getTime());
    if (k == 0) info.force_frame_id = msg->header.frame_id;
    const double v[3] = {msg->wrench.force.x, msg->wrench.force.y, msg->wrench.force.z};
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(v[a]))
        throw InputError(locate(path, message_place(topic, k, t, t) + ": wrench.force." + "xyz"[a]),
                         "expected a finite number, got " + format_seconds(v[a]));
    if (!out.t_ns.empty() && t <= out.t_ns.back())
      throw InputError(locate(path, message_place(topic, k, std::nullopt, 0) + ": header.stamp"),
                       "time must increase strictly: " + format_seconds((t - out.t_ns.back()) * 1e-9) +
                           " s after message " + std::to_string(k - 1));
    out.t_ns.push_back(t);
    out.f.emplace_back(v[0], v[1], v[2]);
    ++k;
  }
  info.force_messages = k;
  info.force_bag_time = rule.use_bag_time.value_or(false);
  return out;
}

}  // namespace

Recording load_bag_recording(const std::filesystem::path& path, const BagReadOptions& options, BagReadInfo* info_out) {
  BagReadInfo info;
  if (!std::filesystem::exists(path)) throw InputError(locate(path, ""), "no such file");
  rosbag::Bag bag;
  try {
    bag.open(path.string(), rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw InputError(locate(path, ""), std::string("not a readable rosbag: ") + e.what());
  }
  if (options.topic.empty()) throw InputError(locate(path, ""), "no JointState topic given");
  check_topic(bag, path, options.topic, "sensor_msgs/JointState", "joint state");

  const std::string& topic = options.topic;
  rosbag::View view(bag, rosbag::TopicQuery(topic));
  JointStateMap map;
  JointStateMap::Workspace ws;
  if (!options.joint_names.empty()) {
    try {
      map = JointStateMap(options.joint_names);
    } catch (const std::invalid_argument& e) {
      throw InputError(locate(path, "joint names"), e.what());
    }
    ws = map.create_workspace();
  }

  TimeRule rule;
  std::vector<std::int64_t> t_ns;
  std::vector<double> values;  // per sample: position, velocity, effort, num_joints each
  std::vector<std::size_t> message_index;
  std::size_t k = 0;
  for (const rosbag::MessageInstance& mi : view) {
    sensor_msgs::JointState::ConstPtr msg;
    try {
      msg = mi.instantiate<sensor_msgs::JointState>();
    } catch (const std::exception& e) {
      throw InputError(locate(path, message_place(topic, k, std::nullopt, 0)),
                       std::string("cannot be read as sensor_msgs/JointState: ") + e.what());
    }
    if (!msg)
      throw InputError(locate(path, message_place(topic, k, std::nullopt, 0)), "cannot be read as sensor_msgs/JointState");
    const std::int64_t t = rule.get(path, topic, k, msg->header.stamp, mi.getTime());
    const std::int64_t origin = t_ns.empty() ? t : t_ns.front();
    if (map.num_joints() == 0) {
      if (!msg->name.empty()) {
        try {
          map = JointStateMap(msg->name);
        } catch (const std::invalid_argument& e) {
          throw InputError(locate(path, message_place(topic, k, t, origin) + ": name"), e.what());
        }
      } else if (!msg->position.empty()) {
        map = JointStateMap::make_positional(static_cast<int>(msg->position.size()));
      } else {
        throw InputError(locate(path, message_place(topic, k, t, origin) + ": position"),
                         "missing (empty array); the estimator needs position, velocity and effort");
      }
      if (map.num_joints() < options.read.min_joints)
        throw InputError(locate(path, message_place(topic, k, t, origin) + ": position"),
                         "missing: too few joints (" + std::to_string(map.num_joints()) + "), at least " +
                             std::to_string(options.read.min_joints) + " are required");
      ws = map.create_workspace();
    }
    if (const JointStateDefect d = map.compute_sample(ws, *msg))
      throw InputError(locate(path, message_place(topic, k, t, origin)), map.describe(d, *msg));
    t_ns.push_back(t);
    message_index.push_back(k);
    values.insert(values.end(), ws.position.begin(), ws.position.end());
    values.insert(values.end(), ws.velocity.begin(), ws.velocity.end());
    values.insert(values.end(), ws.effort.begin(), ws.effort.end());
    ++k;
  }
  info.messages = k;
  info.bag_time = rule.use_bag_time.value_or(false);
  info.joint_names = map.names();

  const int N = map.num_joints();
  const std::size_t T = t_ns.size();
  const std::size_t stride = 3 * static_cast<std::size_t>(N);
  auto row = [&](std::size_t t) { return values.data() + t * stride; };

  // Repeated samples, as the CSV reader: position, velocity and effort equal to
  // the previous sample's.
  std::vector<char> repeated(T, 0);
  std::size_t repeated_count = 0;
  for (std::size_t t = 1; t < T; ++t)
    if (std::equal(row(t), row(t) + stride, row(t - 1))) {
      repeated[t] = 1;
      ++repeated_count;
    }
  std::vector<std::size_t> keep;
  keep.reserve(T);
  for (std::size_t t = 0; t < T; ++t)
    if (!(options.read.dedupe && repeated[t])) keep.push_back(t);

  const std::int64_t origin = t_ns.front();
  for (std::size_t i = 1; i < keep.size(); ++i) {
    const std::size_t t = keep[i], prev = keep[i - 1];
    if (t_ns[t] <= t_ns[prev]) {
      const bool is_repeat = !options.read.dedupe && repeated[t];
      throw InputError(
          locate(path, message_place(topic, message_index[t], t_ns[t], origin) + ": " +
                           (info.bag_time ? "bag time" : "header.stamp")),
          "time must increase strictly: " + format_seconds((t_ns[t] - origin) * 1e-9) + " s after " +
              format_seconds((t_ns[prev] - origin) * 1e-9) + " s in message " + std::to_string(message_index[prev]) +
              (is_repeat ? " (this message repeats the previous sample; --dedupe drops repeated samples)" : ""));
    }
  }

  Recording rec;
  rec.source = path.string();
  rec.layout = RecordingLayout::rosbag;
  const auto R = static_cast<Eigen::Index>(keep.size());
  rec.time.resize(R);
  rec.position.resize(R, N);
  rec.velocity.resize(R, N);
  rec.effort.resize(R, N);
  for (Eigen::Index i = 0; i < R; ++i) {
    const std::size_t t = keep[static_cast<std::size_t>(i)];
    rec.time[i] = static_cast<double>(t_ns[t] - origin) * 1e-9;
    const double* r = row(t);
    for (int j = 0; j < N; ++j) {
      rec.position(i, j) = r[j];
      rec.velocity(i, j) = r[N + j];
      rec.effort(i, j) = r[2 * N + j];
    }
  }
  rec.repeated_rows = repeated_count;
  rec.repeated_rows_removed = options.read.dedupe && repeated_count > 0;
  info.time_origin_ns = origin;

  if (!options.force_topic.empty()) {
    const ForceSeries force = read_force(bag, path, options.force_topic, info);
    if (force.t_ns.size() >= 2 && info.force_bag_time != info.bag_time)
      throw InputError(locate(path, options.force_topic),
                       std::string("its time is the ") + (info.force_bag_time ? "bag time" : "header stamp") +
                           " but the joint topic's is the " + (info.bag_time ? "bag time" : "header stamp") +
                           ": the two clocks cannot be aligned");
    // Tolerance at the ends: one median force period.
    std::int64_t period = 0;
    if (force.t_ns.size() >= 2) {
      std::vector<std::int64_t> dt(force.t_ns.size() - 1);
      for (std::size_t i = 1; i < force.t_ns.size(); ++i) dt[i - 1] = force.t_ns[i] - force.t_ns[i - 1];
      std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
      period = dt[dt.size() / 2];
    }
    rec.force = Eigen::MatrixXd(R, 3);
    std::size_t s = 0;  // force interval [s, s + 1] holding the sample
    for (Eigen::Index i = 0; i < R; ++i) {
      const std::int64_t t = t_ns[keep[static_cast<std::size_t>(i)]];
      if (t < force.t_ns.front() - period || t > force.t_ns.back() + period)
        throw InputError(locate(path, options.force_topic),
                         "covers " + format_seconds((force.t_ns.front() - origin) * 1e-9) + ".." +
                             format_seconds((force.t_ns.back() - origin) * 1e-9) + " s, but sample at " +
                             format_seconds((t - origin) * 1e-9) + " s (" +
                             message_place(topic, message_index[keep[static_cast<std::size_t>(i)]], std::nullopt, 0) +
                             ") lies outside by more than one force period; trim the bag (rosbag filter) or leave "
                             "the force topic out");
      Eigen::Vector3d f;
      if (t <= force.t_ns.front()) {
        f = force.f.front();
      } else if (t >= force.t_ns.back()) {
        f = force.f.back();
      } else {
        while (force.t_ns[s + 1] <= t) ++s;
        if (force.t_ns[s] == t) {
          f = force.f[s];
        } else {
          const double a = static_cast<double>(t - force.t_ns[s]) / static_cast<double>(force.t_ns[s + 1] - force.t_ns[s]);
          f = force.f[s] + a * (force.f[s + 1] - force.f[s]);
        }
      }
      rec.force->row(i) = f.transpose();
    }
  }
  if (info_out) *info_out = std::move(info);
  return rec;
}

void register_bag_recording_reader(const BagReadOptions& options) {
  register_recording_reader(".bag", [options](const std::filesystem::path& path, const RecordingReadOptions& read) {
    BagReadOptions o = options;
    o.read = read;
    return load_bag_recording(path, o);
  });
}

}  // namespace rcm
