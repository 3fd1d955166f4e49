// rcm_monitor_node: the online misalignment estimator of `rcm monitor` on a
// live dVRK. Subscribes to the arm's CRTK joint state, steps the saved
// free-space model and the bank of EKFs once per message, and publishes the
// running estimate of the RCM-to-incision offset, the force at the incision,
// the onset of a misalignment and the force alarm. Topics, parameters, frames
// and units: docs/howto-ros1.md.
//
//   rcm_monitor_node _session:=/data/bench/session.json _model_file:=/data/bench/free_space_model.json
//
// Setup (loading the session, identifying the tissue model on its calibration)
// happens once before subscribing; what to publish and log is rcm::MonitorNode
// (live/, shared with the DDS node); this file is roscpp's side of it. The
// per-message path does not allocate; roscpp itself allocates to deserialize
// each incoming message and to serialize each published one.

#include <geometry_msgs/Vector3Stamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>
#include <std_msgs/String.h>
#include <std_msgs/UInt64.h>

#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/live/monitor_node.hpp"
#include "rcm/ros/bag_reader.hpp"

namespace {

rcm::InputLocation param_location(const std::string& name) { return rcm::InputLocation::plain("ROS parameter", "~" + name); }

// ~joint_names: a list (launch file, rosparam) or, since roscpp's `_name:=value`
// cannot give lists, a comma-separated string ("outer_yaw,outer_pitch,outer_insertion").
std::vector<std::string> read_joint_names(const ros::NodeHandle& pnh) {
  XmlRpc::XmlRpcValue value;
  if (!pnh.getParam("joint_names", value)) return {};
  if (value.getType() == XmlRpc::XmlRpcValue::TypeString)
    return rcm::parse_joint_names(static_cast<std::string>(value), param_location("joint_names"));
  if (value.getType() != XmlRpc::XmlRpcValue::TypeArray)
    throw rcm::InputError(param_location("joint_names"), "expected a list of joint names or a comma-separated string");
  std::vector<std::string> names;
  for (int i = 0; i < value.size(); ++i) {
    if (value[i].getType() != XmlRpc::XmlRpcValue::TypeString)
      throw rcm::InputError(param_location("joint_names[" + std::to_string(i) + "]"), "expected a joint name (string)");
    names.push_back(static_cast<std::string>(value[i]));
  }
  return names;
}

// The node's private parameters, each once: its name, what it is (with its
// unit), and how it is read into the parameters; `--help` prints this table
// with each default from a default MonitorNodeParameters.
struct Parameter {
  const char* name;
  const char* help;
  std::function<std::string(const rcm::MonitorNodeParameters&)> get_default;
  std::function<void(const ros::NodeHandle&, rcm::MonitorNodeParameters&)> read;
};

template <class T>
Parameter make_parameter(const char* name, const char* help, T& (*field)(rcm::MonitorNodeParameters&)) {
  return {name, help,
          [field](const rcm::MonitorNodeParameters& defaults) {
            rcm::MonitorNodeParameters p = defaults;
            const T value = field(p);
            if constexpr (std::is_same_v<T, std::string>) return value.empty() ? std::string("(none)") : value;
            else if constexpr (std::is_same_v<T, bool>) return std::string(value ? "true" : "false");
            else {
              std::ostringstream out;
              out << value;
              return out.str();
            }
          },
          [name, field](const ros::NodeHandle& pnh, rcm::MonitorNodeParameters& p) {
            T& value = field(p);
            pnh.param(name, value, value);
          }};
}

const std::vector<Parameter>& get_parameters() {
  using P = rcm::MonitorNodeParameters;
  static const std::vector<Parameter> table = {
      make_parameter<std::string>("session", "rcm-session/1 manifest: q0, the calibration, the free-space recordings (required)",
                                  [](P& p) -> std::string& { return p.session; }),
      make_parameter<std::string>("model_file", "saved free-space model: free_space_model.json of `rcm setup` or `rcm run` (required)",
                                  [](P& p) -> std::string& { return p.model_file; }),
      make_parameter<std::string>("tissue_model_file",
                                  "tissue_model.json of `rcm setup` (default: identified again)",
                                  [](P& p) -> std::string& { return p.tissue_model_file; }),
      make_parameter<std::string>("arm", "topic prefix: subscribes <arm>/measured_js, publishes <arm>/rcm/...",
                                  [](P& p) -> std::string& { return p.arm; }),
      {"joint_names", "the model's joint order by name: a list, or a comma-separated string (default: the first message's order)",
       [](const P&) { return std::string("(none)"); },
       [](const ros::NodeHandle& pnh, P& p) { p.joint_names = read_joint_names(pnh); }},
      make_parameter<double>("alarm_force_n", "force alarm threshold at the incision, N",
                             [](P& p) -> double& { return p.alarm_force_n; }),
      make_parameter<double>("onset_threshold", "threshold of the onset test (CUSUM)",
                             [](P& p) -> double& { return p.onset_threshold; }),
      make_parameter<int>("publish_every", "publish the estimate topics every n-th accepted sample",
                          [](P& p) -> int& { return p.publish_every; }),
      make_parameter<int>("queue_size", "queue of the subscription and of the estimate publishers, messages",
                          [](P& p) -> int& { return p.queue_size; }),
      make_parameter<std::string>("base_frame", "frame_id of incision_force and correction (default: <arm>_base)",
                                  [](P& p) -> std::string& { return p.base_frame; }),
      make_parameter<std::string>("incision_frame", "frame_id of misalignment (default: <arm>_incision)",
                                  [](P& p) -> std::string& { return p.incision_frame; }),
      make_parameter<bool>("dedupe", "drop repeated rows of the session's recordings",
                           [](P& p) -> bool& { return p.dedupe; }),
      make_parameter<int>("seed", "seed of the tissue identification", [](P& p) -> int& { return p.seed; }),
      make_parameter<double>("status_period_s", "period of the status line in sample time, s (0: none)",
                             [](P& p) -> double& { return p.status_period_s; }),
      make_parameter<double>("tolerance_m", "correction: the RCM is aligned within this distance of the incision, m",
                             [](P& p) -> double& { return p.correction.tolerance_m; }),
      make_parameter<double>("compensate_limit_m", "correction: software RCM shifts up to this, beyond it re-docking advice, m",
                             [](P& p) -> double& { return p.correction.compensate_limit_m; }),
      make_parameter<double>("max_shift_rate_m_per_s", "correction: speed of a software RCM shift, m/s",
                             [](P& p) -> double& { return p.correction.max_rate_m_per_s; }),
  };
  return table;
}

rcm::MonitorNodeParameters read_parameters(const ros::NodeHandle& pnh) {
  rcm::MonitorNodeParameters p;
  for (const Parameter& parameter : get_parameters()) parameter.read(pnh, p);
  p.check(param_location);
  return p;
}

void print_help() {
  std::printf(
      "rcm_monitor_node: the online RCM misalignment estimator on a live dVRK over ROS 1\n"
      "Usage: rcm_monitor_node _session:=FILE _model_file:=FILE [_NAME:=VALUE ...]\n\n"
      "Subscribes <arm>/measured_js (sensor_msgs/JointState) and publishes <arm>/rcm/misalignment,\n"
      "misalignment_sd, incision_force, correction, onset, alarm, out_of_regime, rejected_samples, advice.\n\n"
      "Private parameters (~NAME; _NAME:=VALUE on the command line, or a launch file), with their defaults:\n");
  const rcm::MonitorNodeParameters defaults;
  for (const Parameter& parameter : get_parameters())
    std::printf("  ~%-24s %-10s %s\n", parameter.name, parameter.get_default(defaults).c_str(), parameter.help);
}

// roscpp's publishers and rosconsole behind the node core's sink.
class RosSink : public rcm::MonitorSink {
 public:
  RosSink(ros::NodeHandle& nh, const rcm::MonitorNodeParameters& p) {
    const std::string prefix = p.get_output_prefix();
    const auto queue = static_cast<std::uint32_t>(p.queue_size);
    misalignment_pub_ = nh.advertise<geometry_msgs::Vector3Stamped>(prefix + "misalignment", queue);
    sd_pub_ = nh.advertise<geometry_msgs::Vector3Stamped>(prefix + "misalignment_sd", queue);
    force_pub_ = nh.advertise<geometry_msgs::WrenchStamped>(prefix + "incision_force", queue);
    onset_pub_ = nh.advertise<std_msgs::Bool>(prefix + "onset", 10, true);
    alarm_pub_ = nh.advertise<std_msgs::Bool>(prefix + "alarm", 10, true);
    rejected_pub_ = nh.advertise<std_msgs::UInt64>(prefix + "rejected_samples", 10, true);
    out_of_regime_pub_ = nh.advertise<std_msgs::Bool>(prefix + "out_of_regime", 10, true);
    correction_pub_ = nh.advertise<geometry_msgs::Vector3Stamped>(prefix + "correction", queue);
    advice_pub_ = nh.advertise<std_msgs::String>(prefix + "advice", 10, true);
    correction_msg_.header.frame_id = p.get_base_frame();
    misalignment_msg_.header.frame_id = p.get_incision_frame();
    sd_msg_.header.frame_id = p.get_incision_frame();
    force_msg_.header.frame_id = p.get_base_frame();
  }

  void publish_estimate(std::int64_t stamp_ns, const rcm::OnlineOutput& out) override {
    const ros::Time stamp = ros::Time().fromNSec(static_cast<std::uint64_t>(stamp_ns));
    misalignment_msg_.header.stamp = stamp;
    misalignment_msg_.vector.x = out.misalignment_m[0];
    misalignment_msg_.vector.y = out.misalignment_m[1];
    misalignment_msg_.vector.z = out.misalignment_m[2];
    sd_msg_.header.stamp = stamp;
    sd_msg_.vector.x = out.sd_m[0];
    sd_msg_.vector.y = out.sd_m[1];
    sd_msg_.vector.z = out.sd_m[2];
    force_msg_.header.stamp = stamp;
    force_msg_.wrench.force.x = out.f_inc_base[0];
    force_msg_.wrench.force.y = out.f_inc_base[1];
    force_msg_.wrench.force.z = out.f_inc_base[2];
    misalignment_pub_.publish(misalignment_msg_);
    sd_pub_.publish(sd_msg_);
    force_pub_.publish(force_msg_);
  }
  void publish_flag(rcm::MonitorFlag flag, bool value) override {
    bool_msg_.data = value;
    (flag == rcm::MonitorFlag::onset   ? onset_pub_
     : flag == rcm::MonitorFlag::alarm ? alarm_pub_
                                       : out_of_regime_pub_)
        .publish(bool_msg_);
  }
  void publish_rejected(std::uint64_t total) override {
    rejected_msg_.data = total;
    rejected_pub_.publish(rejected_msg_);
  }
  void publish_correction(std::int64_t stamp_ns, const rcm::CorrectionOutput& c) override {
    correction_msg_.header.stamp = ros::Time().fromNSec(static_cast<std::uint64_t>(stamp_ns));
    correction_msg_.vector.x = c.move_base[0];
    correction_msg_.vector.y = c.move_base[1];
    correction_msg_.vector.z = c.move_base[2];
    correction_pub_.publish(correction_msg_);
  }
  void publish_advice(const std::string& text) override {
    advice_msg_.data = text;
    advice_pub_.publish(advice_msg_);
  }
  void log(rcm::LogLevel level, const std::string& text, double throttle_s = 0.0) override {
    if (throttle_s > 0) {  // the core throttles one kind of line per period
      const ros::WallTime now = ros::WallTime::now();
      ros::WallTime& last = last_logged_[throttle_s];
      if (!last.isZero() && (now - last).toSec() < throttle_s) return;
      last = now;
    }
    if (level == rcm::LogLevel::info)
      ROS_INFO("%s", text.c_str());
    else if (level == rcm::LogLevel::warn)
      ROS_WARN("%s", text.c_str());
    else
      ROS_ERROR("%s", text.c_str());
  }

 private:
  ros::Publisher misalignment_pub_, sd_pub_, force_pub_, onset_pub_, alarm_pub_, rejected_pub_, out_of_regime_pub_,
      correction_pub_, advice_pub_;
  geometry_msgs::Vector3Stamped misalignment_msg_, sd_msg_, correction_msg_;
  std_msgs::String advice_msg_;
  geometry_msgs::WrenchStamped force_msg_;
  std_msgs::Bool bool_msg_;
  std_msgs::UInt64 rejected_msg_;
  std::map<double, ros::WallTime> last_logged_;
};

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // log lines appear as they come when redirected to a file
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      print_help();
      return 0;
    }
  }
  ros::init(argc, argv, "rcm_monitor");
  ros::NodeHandle nh, pnh("~");
  try {
    rcm::register_bag_recording_reader();  // sessions may name .bag files
    const rcm::MonitorNodeParameters params = read_parameters(pnh);
    std::string models;
    std::unique_ptr<rcm::OnlinePipeline> pipeline = rcm::make_monitor_pipeline(params, &models);
    ROS_INFO("rcm: %s", models.c_str());
    RosSink sink(nh, params);
    rcm::MonitorNode node(params, std::move(pipeline), rcm::LiveMonitor::ZeroStamp::receive_time_when_unstamped, sink);
    ros::Subscriber sub = nh.subscribe<sensor_msgs::JointState>(
        params.get_input_topic(), static_cast<std::uint32_t>(params.queue_size),
        [&node](const sensor_msgs::JointState::ConstPtr& msg) {
          node.compute_message(rcm::view_joint_state(*msg), static_cast<std::int64_t>(msg->header.stamp.toNSec()),
                               static_cast<std::int64_t>(ros::Time::now().toNSec()));
        },
        ros::VoidConstPtr(), ros::TransportHints().tcpNoDelay());
    node.start(sub.getTopic());
    ros::spin();
    // After ros::spin() returns, ros::shutdown() has already shut rosconsole down: plain stderr.
    std::fputs(node.get_summary().c_str(), stderr);
  } catch (const rcm::InputError& e) {
    ROS_FATAL("rcm: error: %s", e.what());
    return 2;
  } catch (const std::invalid_argument& e) {  // e.g. ~joint_names fewer than the model reads
    ROS_FATAL("rcm: error: %s", e.what());
    return 2;
  } catch (const std::exception& e) {
    ROS_FATAL("rcm: error: %s", e.what());
    return 1;
  }
  return 0;
}
