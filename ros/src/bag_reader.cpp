#include "rcm/ros/bag_reader.hpp"

#include <geometry_msgs/WrenchStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/JointState.h>

#include <boost/make_shared.hpp>

#include <map>
#include <memory>
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

// A bag's two topics in bag-time order (rosbag::View), for MessageRecordingReader.
class BagSource final : public MessageSource {
 public:
  BagSource(std::shared_ptr<rosbag::Bag> bag, std::filesystem::path path, const BagReadOptions& options,
            BagReadInfo& info, bool force_only)
      : bag_(std::move(bag)), path_(std::move(path)), options_(options), info_(info), force_only_(force_only) {
    std::vector<std::string> topics;
    if (!force_only) topics.push_back(options.topic);
    if (!options.force_topic.empty()) topics.push_back(options.force_topic);
    view_ = std::make_unique<rosbag::View>(*bag_, rosbag::TopicQuery(topics));
    it_ = view_->begin();
  }

  bool next(RecordingMessage& m) override {
    if (started_ && it_ != view_->end()) ++it_;
    started_ = true;
    if (it_ == view_->end()) return false;
    const rosbag::MessageInstance& mi = *it_;
    if (!force_only_ && mi.getTopic() == options_.topic) {
      const std::string& topic = options_.topic;
      const std::size_t k = info_.messages++;
      joint_ = read_message<sensor_msgs::JointState>(mi, buffer_, path_, topic, k);
      if (!joint_)
        throw InputError(locate(path_, describe_message_place(topic, k, std::nullopt, 0)),
                         "cannot be read as sensor_msgs/JointState");
      m.topic = RecordingMessage::Topic::joints;
      m.index = k;
      m.t_ns = get_time(rule_, options_.time, path_, topic, k, joint_->header.stamp, mi.getTime());
      m.joints.emplace(view_joint_state(*joint_));
      info_.bag_time = rule_.use_bag_time.value_or(false);
      return true;
    }
    const std::string& ftopic = options_.force_topic;
    const std::size_t n = info_.force_messages++;
    const auto msg = read_message<geometry_msgs::WrenchStamped>(mi, buffer_, path_, ftopic, n);
    if (!msg)
      throw InputError(locate(path_, describe_message_place(ftopic, n, std::nullopt, 0)),
                       "cannot be read as geometry_msgs/WrenchStamped");
    m.topic = RecordingMessage::Topic::force;
    m.index = n;
    m.t_ns = get_time(frule_, options_.time, path_, ftopic, n, msg->header.stamp, mi.getTime());
    m.force = Eigen::Vector3d(msg->wrench.force.x, msg->wrench.force.y, msg->wrench.force.z);
    if (n == 0) info_.force_frame_id = msg->header.frame_id;
    info_.force_bag_time = frule_.use_bag_time.value_or(false);
    return true;
  }

  std::string get_time_label(RecordingMessage::Topic topic) const override {
    const TimeRule& rule = topic == RecordingMessage::Topic::joints ? rule_ : frule_;
    return time_label(rule.use_bag_time.value_or(false));
  }

  void finish() override {
    if (!options_.force_topic.empty() && info_.force_messages >= 2 && info_.force_bag_time != info_.bag_time)
      throw InputError(locate(path_, options_.force_topic),
                       std::string("its time is the ") + (info_.force_bag_time ? "bag time" : "header stamp") +
                           " but the joint topic's is the " + (info_.bag_time ? "bag time" : "header stamp") +
                           ": the two clocks cannot be aligned");
  }

  std::unique_ptr<MessageSource> reopen_force() const override {
    auto info = std::make_shared<BagReadInfo>();
    return std::make_unique<Owning>(info, std::make_unique<BagSource>(bag_, path_, options_, *info, true));
  }

 private:
  // A second pass's source and the counts it makes, which are not reported.
  class Owning final : public MessageSource {
   public:
    Owning(std::shared_ptr<BagReadInfo> info, std::unique_ptr<BagSource> source)
        : info_(std::move(info)), source_(std::move(source)) {}
    bool next(RecordingMessage& m) override { return source_->next(m); }
    std::string get_time_label(RecordingMessage::Topic t) const override { return source_->get_time_label(t); }
    std::unique_ptr<MessageSource> reopen_force() const override { return source_->reopen_force(); }

   private:
    std::shared_ptr<BagReadInfo> info_;
    std::unique_ptr<BagSource> source_;
  };

  std::shared_ptr<rosbag::Bag> bag_;
  std::filesystem::path path_;
  BagReadOptions options_;
  BagReadInfo& info_;
  bool force_only_;
  std::unique_ptr<rosbag::View> view_;
  rosbag::View::iterator it_;
  bool started_ = false;
  std::vector<std::uint8_t> buffer_;
  sensor_msgs::JointState::ConstPtr joint_;
  // The clock is known after each topic's first message.
  TimeRule rule_, frule_;
};

// What rosbag_storage and roscpp throw for what the structure check cannot
// see (an unknown connection, a time beyond ros::Time) is bad input too.
template <class F>
auto as_input_errors(const std::filesystem::path& path, F&& f) -> decltype(f()) {
  try {
    return f();
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

std::unique_ptr<MessageSource> open_bag_source(const std::filesystem::path& path, const BagReadOptions& options,
                                               BagReadInfo& info) {
  auto bag = std::make_shared<rosbag::Bag>();
  try {
    bag->open(path.string(), rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw InputError(locate(path, ""), std::string("not a readable rosbag: ") + e.what());
  }
  if (options.topic.empty()) throw InputError(locate(path, ""), "no JointState topic given");
  check_topic(*bag, path, options.topic, "sensor_msgs/JointState", "joint state");
  if (!options.force_topic.empty())
    check_topic(*bag, path, options.force_topic, "geometry_msgs/WrenchStamped", "force");
  return std::make_unique<BagSource>(bag, path, options, info, false);
}

}  // namespace

BagRecordingReader::BagRecordingReader(const std::filesystem::path& path, const BagReadOptions& options,
                                       std::size_t chunk_rows, std::unique_ptr<BagReadInfo> info,
                                       std::unique_ptr<MessageSource> source)
    : MessageRecordingReader(path.string(), options, RecordingLayout::rosbag, std::move(source), chunk_rows),
      info_(std::move(info)),
      path_(path) {}

const BagReadInfo& BagRecordingReader::info() const {
  info_->joint_names = joint_names();
  info_->time_origin_ns = time_origin_ns();
  return *info_;
}

std::size_t BagRecordingReader::fill_chunk(Recording& chunk, std::size_t filled) {
  return as_input_errors(path_, [&] { return MessageRecordingReader::fill_chunk(chunk, filled); });
}

std::unique_ptr<BagRecordingReader> open_bag_recording(const std::filesystem::path& path,
                                                       const BagReadOptions& options, std::size_t chunk_rows) {
  if (!std::filesystem::exists(path)) throw InputError(locate(path, ""), "no such file");
  ros1::check_bag_structure(path);
  return as_input_errors(path, [&] {
    auto info = std::make_unique<BagReadInfo>();
    auto source = open_bag_source(path, options, *info);
    return std::unique_ptr<BagRecordingReader>(
        new BagRecordingReader(path, options, chunk_rows, std::move(info), std::move(source)));
  });
}

Recording load_bag_recording(const std::filesystem::path& path, const BagReadOptions& options, BagReadInfo* info_out) {
  const auto reader = open_bag_recording(path, options);
  Recording rec = read_whole_recording(*reader);
  if (info_out) *info_out = reader->info();
  return rec;
}

void register_bag_recording_reader(const BagReadOptions& options) {
  register_recording_stream(".bag", [options](const std::filesystem::path& path, const RecordingReadOptions& read,
                                              std::size_t chunk_rows) -> std::unique_ptr<RecordingReader> {
    return open_bag_recording(path, with_session_topics(options, read), chunk_rows);
  });
}

}  // namespace rcm
