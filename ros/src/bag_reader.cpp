#include "rcm/ros/bag_reader.hpp"

#include <geometry_msgs/WrenchStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/JointState.h>

#include <boost/make_shared.hpp>

#include <map>
#include <optional>

#include "bag_check.hpp"
#include "rcm/common/error.hpp"
#include "rcm/io/message_recording.hpp"

namespace rcm {
namespace {

InputLocation locate(const std::filesystem::path& path, const std::string& where) {
  return InputLocation::plain(path.string(), where);
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
// by its first message); always the bag time under MessageTime::receive.
struct TimeRule {
  std::optional<bool> use_bag_time;
  std::int64_t get(const std::filesystem::path& path, const std::string& topic, std::size_t k,
                   const ros::Time& stamp, const ros::Time& bag_time) {
    const bool zero = stamp.isZero();
    if (!use_bag_time) use_bag_time = zero;
    if (*use_bag_time && !zero)
      throw InputError(locate(path, describe_message_place(topic, k, std::nullopt, 0) + ": header.stamp"),
                       "non-zero, but the topic's first message has a zero stamp: stamps must be set on every "
                       "message or on none (then the bag's receive time is used)");
    if (!*use_bag_time && zero)
      throw InputError(locate(path, describe_message_place(topic, k, std::nullopt, 0) + ": header.stamp"),
                       "zero, but the topic's first message has a stamp: stamps must be set on every message or on "
                       "none (then the bag's receive time is used)");
    return static_cast<std::int64_t>((*use_bag_time ? bag_time : stamp).toNSec());
  }
};

std::int64_t get_time(TimeRule& rule, MessageTime time, const std::filesystem::path& path, const std::string& topic,
                      std::size_t k, const ros::Time& stamp, const ros::Time& bag_time) {
  if (time == MessageTime::receive) {
    rule.use_bag_time = true;
    return static_cast<std::int64_t>(bag_time.toNSec());
  }
  return rule.get(path, topic, k, stamp, bag_time);
}

const char* time_label(bool bag_time) { return bag_time ? "bag time" : "header.stamp"; }

// Walks a serialized message's variable-length fields; false when a length or
// count runs past the message. ROS 1 deserialization resizes a vector to the
// count it reads before it reads the elements (a corrupt count of 2^32 would
// allocate tens of GB), so counts are checked here first.
class SerializedWalk {
 public:
  SerializedWalk(const std::uint8_t* p, std::size_t n) : p_(p), n_(n) {}
  bool skip(std::uint64_t k) {
    if (!ok_ || k > n_ - pos_) return ok_ = false;
    pos_ += k;
    return true;
  }
  std::uint64_t count() {
    if (!skip(4)) return 0;
    return static_cast<std::uint64_t>(p_[pos_ - 4]) | static_cast<std::uint64_t>(p_[pos_ - 3]) << 8 |
           static_cast<std::uint64_t>(p_[pos_ - 2]) << 16 | static_cast<std::uint64_t>(p_[pos_ - 1]) << 24;
  }
  bool header() { return skip(12) && skip(count()); }  // seq, stamp, frame_id
  bool doubles() {
    const std::uint64_t k = count();
    return k <= (n_ - pos_) / 8 && skip(8 * k);
  }
  bool ok() const { return ok_; }

 private:
  const std::uint8_t* p_;
  std::size_t n_, pos_ = 0;
  bool ok_ = true;
};

bool fits(const std::uint8_t* p, std::size_t n, const sensor_msgs::JointState*) {
  SerializedWalk w(p, n);
  if (!w.header()) return false;
  const std::uint64_t names = w.count();
  for (std::uint64_t i = 0; i < names && w.ok(); ++i) w.skip(w.count());
  return w.ok() && w.doubles() && w.doubles() && w.doubles();
}

bool fits(const std::uint8_t* p, std::size_t n, const geometry_msgs::WrenchStamped*) {
  SerializedWalk w(p, n);
  return w.header() && w.skip(6 * 8);
}

// The message as type M when the bag says it is one (null otherwise), its
// lengths checked against its bytes before it is deserialized.
template <class M>
boost::shared_ptr<M> read_message(const rosbag::MessageInstance& mi, std::vector<std::uint8_t>& buffer,
                                  const std::filesystem::path& path, const std::string& topic, std::size_t k) {
  if (!mi.isType<M>()) return nullptr;
  buffer.resize(mi.size());
  ros::serialization::OStream out(buffer.data(), static_cast<std::uint32_t>(buffer.size()));
  mi.write(out);
  if (!fits(buffer.data(), buffer.size(), static_cast<const M*>(nullptr)))
    throw InputError(locate(path, describe_message_place(topic, k, std::nullopt, 0)),
                     "a length or count in the " + std::to_string(buffer.size()) +
                         "-byte serialized message runs past its end");
  auto m = boost::make_shared<M>();
  ros::serialization::IStream in(buffer.data(), static_cast<std::uint32_t>(buffer.size()));
  ros::serialization::deserialize(in, *m);
  return m;
}

Recording read_bag(const std::filesystem::path& path, const BagReadOptions& options, BagReadInfo* info_out) {
  BagReadInfo info;
  std::vector<std::uint8_t> buffer;
  rosbag::Bag bag;
  try {
    bag.open(path.string(), rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw InputError(locate(path, ""), std::string("not a readable rosbag: ") + e.what());
  }
  if (options.topic.empty()) throw InputError(locate(path, ""), "no JointState topic given");
  check_topic(bag, path, options.topic, "sensor_msgs/JointState", "joint state");

  const std::string& topic = options.topic;
  // The clock is known after the first message; the builder words errors with it.
  TimeRule rule;
  std::optional<JointStateRecordingBuilder> builder;
  rosbag::View view(bag, rosbag::TopicQuery(topic));
  std::size_t k = 0;
  for (const rosbag::MessageInstance& mi : view) {
    sensor_msgs::JointState::ConstPtr msg = read_message<sensor_msgs::JointState>(mi, buffer, path, topic, k);
    if (!msg)
      throw InputError(locate(path, describe_message_place(topic, k, std::nullopt, 0)),
                       "cannot be read as sensor_msgs/JointState");
    const std::int64_t t = get_time(rule, options.time, path, topic, k, msg->header.stamp, mi.getTime());
    if (!builder) builder.emplace(path.string(), topic, options, time_label(*rule.use_bag_time));
    builder->add(k, t, view_joint_state(*msg));
    ++k;
  }
  info.messages = k;
  info.bag_time = rule.use_bag_time.value_or(false);
  Recording rec = builder->finish(RecordingLayout::rosbag);
  info.joint_names = builder->joint_names();
  info.time_origin_ns = builder->time_origin_ns();

  if (!options.force_topic.empty()) {
    const std::string& ftopic = options.force_topic;
    check_topic(bag, path, ftopic, "geometry_msgs/WrenchStamped", "force");
    TimeRule frule;
    std::optional<ForceSamples> force;
    rosbag::View fview(bag, rosbag::TopicQuery(ftopic));
    std::size_t n = 0;
    for (const rosbag::MessageInstance& mi : fview) {
      const auto msg = read_message<geometry_msgs::WrenchStamped>(mi, buffer, path, ftopic, n);
      if (!msg)
        throw InputError(locate(path, describe_message_place(ftopic, n, std::nullopt, 0)),
                         "cannot be read as geometry_msgs/WrenchStamped");
      const std::int64_t t = get_time(frule, options.time, path, ftopic, n, msg->header.stamp, mi.getTime());
      if (!force) {
        force.emplace(path.string(), ftopic, time_label(*frule.use_bag_time));
        info.force_frame_id = msg->header.frame_id;
      }
      force->add(n, t, Eigen::Vector3d(msg->wrench.force.x, msg->wrench.force.y, msg->wrench.force.z));
      ++n;
    }
    info.force_messages = n;
    info.force_bag_time = frule.use_bag_time.value_or(false);
    if (n >= 2 && info.force_bag_time != info.bag_time)
      throw InputError(locate(path, ftopic),
                       std::string("its time is the ") + (info.force_bag_time ? "bag time" : "header stamp") +
                           " but the joint topic's is the " + (info.bag_time ? "bag time" : "header stamp") +
                           ": the two clocks cannot be aligned");
    builder->attach_force(rec, *force);
  }
  if (info_out) *info_out = std::move(info);
  return rec;
}

}  // namespace

Recording load_bag_recording(const std::filesystem::path& path, const BagReadOptions& options, BagReadInfo* info_out) {
  if (!std::filesystem::exists(path)) throw InputError(locate(path, ""), "no such file");
  ros1::check_bag_structure(path);
  // What rosbag_storage and roscpp throw for what the structure check cannot
  // see (an unknown connection, a time beyond ros::Time) is bad input too.
  try {
    return read_bag(path, options, info_out);
  } catch (const InputError&) {
    throw;
  } catch (const rosbag::BagException& e) {
    throw InputError(locate(path, ""), std::string("not a readable rosbag: ") + e.what());
  } catch (const ros::Exception& e) {
    throw InputError(locate(path, ""), std::string("corrupt message data: ") + e.what());
  } catch (const std::runtime_error& e) {
    // ros::Time's "out of dual 32-bit range" for an index entry's time, and the like.
    throw InputError(locate(path, ""), std::string("not a readable rosbag: ") + e.what());
  }
}

void register_bag_recording_reader(const BagReadOptions& options) {
  register_recording_reader(".bag", [options](const std::filesystem::path& path, const RecordingReadOptions& read) {
    return load_bag_recording(path, with_session_topics(options, read));
  });
}

}  // namespace rcm
