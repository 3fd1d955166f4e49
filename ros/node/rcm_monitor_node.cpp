// rcm_monitor_node: the online misalignment estimator of `rcm monitor` on a
// live dVRK. Subscribes to the arm's CRTK joint state, steps the saved
// free-space model and the bank of EKFs once per message, and publishes the
// running estimate of the RCM-to-incision offset, the force at the incision,
// the onset of a misalignment and the force alarm. Topics, parameters, frames
// and units: docs/ros.md.
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
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
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

rcm::MonitorNodeParameters read_parameters(const ros::NodeHandle& pnh) {
  rcm::MonitorNodeParameters p;
  pnh.getParam("session", p.session);
  pnh.getParam("model_file", p.model_file);
  pnh.param("arm", p.arm, p.arm);
  p.joint_names = read_joint_names(pnh);
  pnh.param("alarm_force_n", p.alarm_force_n, p.alarm_force_n);
  pnh.param("onset_threshold", p.onset_threshold, p.onset_threshold);
  pnh.param("publish_every", p.publish_every, p.publish_every);
  pnh.param("queue_size", p.queue_size, p.queue_size);
  pnh.param("base_frame", p.base_frame, p.base_frame);
  pnh.param("incision_frame", p.incision_frame, p.incision_frame);
  pnh.param("dedupe", p.dedupe, p.dedupe);
  pnh.param("seed", p.seed, p.seed);
  pnh.param("status_period_s", p.status_period_s, p.status_period_s);
  pnh.param("tolerance_m", p.correction.tolerance_m, p.correction.tolerance_m);
  pnh.param("compensate_limit_m", p.correction.compensate_limit_m, p.correction.compensate_limit_m);
  pnh.param("max_shift_rate_m_per_s", p.correction.max_rate_m_per_s, p.correction.max_rate_m_per_s);
  p.check(param_location);
  return p;
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
