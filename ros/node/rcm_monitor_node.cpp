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
// happens once before subscribing; the per-message path (rcm::LiveMonitor, the
// pipeline, filling preallocated messages) does not allocate. roscpp itself
// allocates to deserialize each incoming message and to serialize each
// published one.

#include <geometry_msgs/Vector3Stamped.h>
#include <geometry_msgs/WrenchStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>
#include <std_msgs/UInt64.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "rcm/common/error.hpp"
#include "rcm/estimation/online.hpp"
#include "rcm/estimation/study.hpp"
#include "rcm/io/session.hpp"
#include "rcm/ros/bag_reader.hpp"
#include "rcm/ros/live_monitor.hpp"

namespace {

struct Parameters {
  std::string session, model_file;
  std::string arm = "PSM1";
  std::vector<std::string> joint_names;
  double alarm_force_n = 10.0;
  double onset_threshold = rcm::OnlineEstimatorOptions{}.onset_threshold;
  int publish_every = 1;
  int queue_size = 1000;
  std::string base_frame, incision_frame;
  bool dedupe = false;
  int seed = 1;
  double status_period_s = 5.0;
};

rcm::InputLocation param_location(const std::string& name) {
  rcm::InputLocation where;
  where.file = "ROS parameter";
  where.field = "~" + name;
  where.kind = rcm::InputLocation::Kind::plain;
  return where;
}

// ~joint_names: a list (launch file, rosparam) or, since roscpp's `_name:=value`
// cannot give lists, a comma-separated string ("outer_yaw,outer_pitch,outer_insertion").
std::vector<std::string> read_joint_names(const ros::NodeHandle& pnh) {
  XmlRpc::XmlRpcValue value;
  if (!pnh.getParam("joint_names", value)) return {};
  std::vector<std::string> names;
  if (value.getType() == XmlRpc::XmlRpcValue::TypeString) {
    std::string text = static_cast<std::string>(value);
    for (char& c : text)
      if (c == '[' || c == ']' || c == '\'' || c == '"') c = ' ';
    std::size_t start = 0;
    while (start <= text.size()) {
      std::size_t end = text.find(',', start);
      if (end == std::string::npos) end = text.size();
      std::string name = text.substr(start, end - start);
      name.erase(0, name.find_first_not_of(' '));
      name.erase(name.find_last_not_of(' ') + 1);
      names.push_back(name);
      start = end + 1;
    }
  } else if (value.getType() == XmlRpc::XmlRpcValue::TypeArray) {
    for (int i = 0; i < value.size(); ++i) {
      if (value[i].getType() != XmlRpc::XmlRpcValue::TypeString)
        throw rcm::InputError(param_location("joint_names[" + std::to_string(i) + "]"), "expected a joint name (string)");
      names.push_back(static_cast<std::string>(value[i]));
    }
  } else {
    throw rcm::InputError(param_location("joint_names"), "expected a list of joint names or a comma-separated string");
  }
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i].empty())
      throw rcm::InputError(param_location("joint_names[" + std::to_string(i) + "]"), "empty joint name");
    for (std::size_t k = 0; k < i; ++k)
      if (names[k] == names[i])
        throw rcm::InputError(param_location("joint_names[" + std::to_string(i) + "]"),
                              "'" + names[i] + "' given twice");
  }
  return names;
}

Parameters read_parameters(const ros::NodeHandle& pnh) {
  Parameters p;
  if (!pnh.getParam("session", p.session) || p.session.empty())
    throw rcm::InputError(param_location("session"), "missing: the rcm-session/1 manifest (calibration, q0)");
  if (!pnh.getParam("model_file", p.model_file) || p.model_file.empty())
    throw rcm::InputError(param_location("model_file"),
                          "missing: a saved free-space model (free_space_model.json of `rcm run`, or `rcm dynamics fit`)");
  pnh.param("arm", p.arm, p.arm);
  p.joint_names = read_joint_names(pnh);
  pnh.param("alarm_force_n", p.alarm_force_n, p.alarm_force_n);
  pnh.param("onset_threshold", p.onset_threshold, p.onset_threshold);
  pnh.param("publish_every", p.publish_every, p.publish_every);
  pnh.param("queue_size", p.queue_size, p.queue_size);
  pnh.param("base_frame", p.base_frame, p.arm + "_base");
  pnh.param("incision_frame", p.incision_frame, p.arm + "_incision");
  pnh.param("dedupe", p.dedupe, p.dedupe);
  pnh.param("seed", p.seed, p.seed);
  pnh.param("status_period_s", p.status_period_s, p.status_period_s);
  if (!(p.alarm_force_n > 0)) throw rcm::InputError(param_location("alarm_force_n"), "must be > 0");
  if (!(p.onset_threshold > 0)) throw rcm::InputError(param_location("onset_threshold"), "must be > 0");
  if (p.publish_every < 1) throw rcm::InputError(param_location("publish_every"), "must be >= 1");
  if (p.queue_size < 1) throw rcm::InputError(param_location("queue_size"), "must be >= 1");
  if (!(p.status_period_s >= 0)) throw rcm::InputError(param_location("status_period_s"), "must be >= 0");
  if (p.seed < 0) throw rcm::InputError(param_location("seed"), "must be >= 0");
  return p;
}

// Everything `rcm monitor --session S --model-file M` builds before replaying.
std::unique_ptr<rcm::OnlinePipeline> make_pipeline(const Parameters& p) {
  const rcm::Session session = rcm::load_session(p.session);
  rcm::StudyOptions options;
  options.model_file = p.model_file;
  options.fit.seed = static_cast<unsigned>(p.seed);
  options.joint.seed = static_cast<unsigned>(p.seed);
  options.read.dedupe = p.dedupe;
  const rcm::TorqueModelFitter no_fitter = [](rcm::dynamics::TorqueModelKind, const std::vector<rcm::Recording>&,
                                              const rcm::dynamics::FitOptions&) -> rcm::dynamics::FitResult {
    throw rcm::InputError(param_location("model_file"), "the node does not fit free-space models");
  };
  const rcm::MonitorSetup setup = rcm::prepare_monitor(session, options, no_fitter);
  rcm::OnlineEstimatorOptions online = rcm::make_online_options(setup.joint_options);
  online.alarm_force_n = p.alarm_force_n;
  online.onset_threshold = p.onset_threshold;
  ROS_INFO("rcm: free-space model %s (%d joints), tissue model %s: k1 %.1f N/m, k3 %.3g N/m^3, c %.2f N s/m, F %.2f N",
           rcm::dynamics::to_string(setup.free_space.model->kind()).c_str(), setup.free_space.model->num_joints(),
           setup.tissue.family.c_str(), setup.tissue.parameters[0], setup.tissue.parameters[1],
           setup.tissue.parameters[2], setup.tissue.parameters[3]);
  return std::make_unique<rcm::OnlinePipeline>(setup.free_space.model,
                                               rcm::OnlineEstimator(setup.incision, setup.tissue, online));
}

struct TimingStats {
  std::uint64_t count = 0;
  double sum_s = 0.0, max_s = 0.0;
  void add(double s) {
    ++count;
    sum_s += s;
    max_s = std::max(max_s, s);
  }
  double mean_us() const { return count ? 1e6 * sum_s / static_cast<double>(count) : 0.0; }
};

class MonitorNode {
 public:
  MonitorNode(ros::NodeHandle& nh, const Parameters& p)
      : params_(p), pipeline_(make_pipeline(p)), monitor_(*pipeline_, p.joint_names) {
    const std::string ns = p.arm.empty() ? std::string("rcm") : p.arm + "/rcm", prefix = ns + "/";
    const auto queue = static_cast<std::uint32_t>(p.queue_size);
    misalignment_pub_ = nh.advertise<geometry_msgs::Vector3Stamped>(prefix + "misalignment", queue);
    sd_pub_ = nh.advertise<geometry_msgs::Vector3Stamped>(prefix + "misalignment_sd", queue);
    force_pub_ = nh.advertise<geometry_msgs::WrenchStamped>(prefix + "incision_force", queue);
    onset_pub_ = nh.advertise<std_msgs::Bool>(prefix + "onset", 10, true);
    alarm_pub_ = nh.advertise<std_msgs::Bool>(prefix + "alarm", 10, true);
    rejected_pub_ = nh.advertise<std_msgs::UInt64>(prefix + "rejected_samples", 10, true);
    out_of_regime_pub_ = nh.advertise<std_msgs::Bool>(prefix + "out_of_regime", 10, true);
    regime_.known = pipeline_->regime_monitor().known();
    misalignment_msg_.header.frame_id = p.incision_frame;
    sd_msg_.header.frame_id = p.incision_frame;
    force_msg_.header.frame_id = p.base_frame;
    publish_bool(onset_pub_, false);
    publish_bool(alarm_pub_, false);
    publish_rejected();
    publish_bool(out_of_regime_pub_, false);
    if (!regime_.known)
      ROS_WARN("rcm: the free-space model carries no training regime: out_of_regime is never raised (refit it)");
    const std::string topic = p.arm.empty() ? std::string("measured_js") : p.arm + "/measured_js";
    sub_ = nh.subscribe(topic, queue, &MonitorNode::on_joint_state, this,
                        ros::TransportHints().tcpNoDelay());
    ROS_INFO("rcm: listening on %s; publishing %s/{misalignment,misalignment_sd,incision_force,onset,alarm,"
             "rejected_samples,out_of_regime}; alarm above %.1f N",
             sub_.getTopic().c_str(), ros::names::resolve(ns).c_str(), p.alarm_force_n);
  }

  // Printed after ros::spin() returns, when ros::shutdown() has already shut
  // rosconsole down: plain stderr.
  void print_summary() const {
    const auto& c = monitor_.get_counters();
    std::fprintf(stderr,
                 "rcm: %llu samples accepted, %llu rejected (duplicate stamp %llu, out of order %llu, zero stamp %llu, "
                 "malformed %llu, too few joints %llu)\n",
                 ull(c.accepted), ull(c.get_rejected()), ull(c.duplicate_stamp), ull(c.out_of_order), ull(c.bad_stamp),
                 ull(c.malformed), ull(c.too_few_joints));
    std::fprintf(stderr,
                 "rcm: per sample: model + estimator %.2f us mean, %.1f us max; whole callback with publishing %.2f us "
                 "mean, %.1f us max\n",
                 step_.mean_us(), 1e6 * step_.max_s, callback_.mean_us(), 1e6 * callback_.max_s);
    std::fprintf(stderr, "rcm: regime: %s\n", regime_.to_text().c_str());
    if (monitor_.started()) {
      const rcm::OnlineOutput& o = monitor_.get_output();
      std::fprintf(stderr, "rcm: final estimate dr_x %.2f +- %.2f, dr_y %.2f +- %.2f, D %.2f +- %.2f mm (1 sd); onset %s\n",
                   1e3 * o.misalignment_m[0], 1e3 * o.sd_m[0], 1e3 * o.misalignment_m[1], 1e3 * o.sd_m[1],
                   1e3 * o.misalignment_m[2], 1e3 * o.sd_m[2], o.onset ? "detected" : "not detected");
    }
  }

 private:
  static unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }

  void publish_bool(const ros::Publisher& pub, bool value) {
    bool_msg_.data = value;
    pub.publish(bool_msg_);
  }
  void publish_rejected() {
    rejected_msg_.data = monitor_.get_counters().get_rejected();
    rejected_pub_.publish(rejected_msg_);
  }

  void on_joint_state(const sensor_msgs::JointState::ConstPtr& msg) {
    using clock = std::chrono::steady_clock;
    const auto start = clock::now();
    const rcm::LiveMonitor::Verdict verdict = monitor_.compute_message(*msg, static_cast<std::int64_t>(ros::Time::now().toNSec()));
    const auto stepped = clock::now();
    if (verdict != rcm::LiveMonitor::Verdict::accepted) {
      on_rejected(verdict, *msg);
      return;
    }
    step_.add(std::chrono::duration<double>(stepped - start).count());
    const rcm::OnlineOutput& out = monitor_.get_output();
    if (monitor_.get_counters().accepted == 1) on_first_sample(*msg);

    const ros::Time stamp = ros::Time().fromNSec(static_cast<std::uint64_t>(monitor_.get_last_time_ns()));
    if (++since_publish_ >= params_.publish_every) {
      since_publish_ = 0;
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
    if (out.onset != onset_) {
      onset_ = out.onset;
      publish_bool(onset_pub_, onset_);
      if (onset_) ROS_WARN("rcm: t = %.3f s: ONSET of a misalignment detected", out.onset_time);
    }
    if (out.alarm != alarm_) {
      alarm_ = out.alarm;
      publish_bool(alarm_pub_, alarm_);
      if (alarm_)
        ROS_ERROR("rcm: t = %.3f s: ALARM: incision force %.1f N above %.1f N", out.time, out.force_norm_n,
                  params_.alarm_force_n);
      else
        ROS_WARN("rcm: t = %.3f s: alarm cleared (%.1f N)", out.time, out.force_norm_n);
    }
    regime_.add(out.time, out.regime_flags);
    if (out.out_of_regime != out_of_regime_) {
      out_of_regime_ = out.out_of_regime;
      publish_bool(out_of_regime_pub_, out_of_regime_);
      if (out_of_regime_)
        ROS_WARN_THROTTLE(1.0, "rcm: t = %.3f s: OUT OF REGIME: %s beyond the free-space model's training data",
                          out.time, rcm::dynamics::describe_regime_flags(out.regime_flags).c_str());
    }
    if (params_.status_period_s > 0 && out.time >= next_status_s_) {
      next_status_s_ = out.time + params_.status_period_s;
      ROS_INFO("rcm: t = %.1f s: dr_x %.2f, dr_y %.2f, D %.2f mm (sd %.2f, %.2f, %.2f), |f| %.1f N%s%s%s", out.time,
               1e3 * out.misalignment_m[0], 1e3 * out.misalignment_m[1], 1e3 * out.misalignment_m[2],
               1e3 * out.sd_m[0], 1e3 * out.sd_m[1], 1e3 * out.sd_m[2], out.force_norm_n,
               out.onset ? "" : " (no onset yet)", out.alarm ? " ALARM" : "", out.out_of_regime ? " (out of regime)" : "");
    }
    callback_.add(std::chrono::duration<double>(clock::now() - start).count());
  }

  void on_first_sample(const sensor_msgs::JointState& msg) {
    const rcm::JointStateMap& map = monitor_.get_joint_map();
    std::string order;
    for (const auto& n : map.names()) order += (order.empty() ? "" : ", ") + n;
    ROS_INFO("rcm: first sample at stamp %.6f s: %d joints %s%s%s; time from %s", msg.header.stamp.toSec(), map.num_joints(), map.by_name() ? "by name: " : "by position (the message has no names)",
             order.c_str(), params_.joint_names.empty() && map.by_name() ? " (the first message's order)" : "",
             monitor_.uses_receive_time() ? "the receive time (the stamps are zero)" : "header.stamp");
  }

  void on_rejected(rcm::LiveMonitor::Verdict verdict, const sensor_msgs::JointState& msg) {
    publish_rejected();
    const std::uint64_t n = monitor_.get_counters().get_rejected();
    if (n <= 10)
      ROS_WARN("rcm: sample rejected (%s): %s [%llu rejected so far]", rcm::to_string(verdict),
               monitor_.describe_rejection(verdict, msg).c_str(), ull(n));
    else
      ROS_WARN_THROTTLE(2.0, "rcm: sample rejected (%s): %s [%llu rejected so far]", rcm::to_string(verdict),
                        monitor_.describe_rejection(verdict, msg).c_str(), ull(n));
  }

  Parameters params_;
  std::unique_ptr<rcm::OnlinePipeline> pipeline_;
  rcm::LiveMonitor monitor_;
  ros::Subscriber sub_;
  ros::Publisher misalignment_pub_, sd_pub_, force_pub_, onset_pub_, alarm_pub_, rejected_pub_, out_of_regime_pub_;
  geometry_msgs::Vector3Stamped misalignment_msg_, sd_msg_;
  geometry_msgs::WrenchStamped force_msg_;
  std_msgs::Bool bool_msg_;
  std_msgs::UInt64 rejected_msg_;
  bool onset_ = false, alarm_ = false, out_of_regime_ = false;
  rcm::dynamics::RegimeSummary regime_;
  int since_publish_ = 0;
  double next_status_s_ = 0.0;
  TimingStats step_, callback_;
};

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // log lines appear as they come when redirected to a file
  ros::init(argc, argv, "rcm_monitor");
  ros::NodeHandle nh, pnh("~");
  try {
    rcm::register_bag_recording_reader();  // sessions may name .bag files
    const Parameters params = read_parameters(pnh);
    MonitorNode node(nh, params);
    ros::spin();
    node.print_summary();
  } catch (const rcm::InputError& e) {
    ROS_FATAL("rcm: error: %s", e.what());
    return 2;
  } catch (const std::invalid_argument& e) {  // e.g. ~joint_names repeated, or fewer than the model reads
    ROS_FATAL("rcm: error: %s", e.what());
    return 2;
  } catch (const std::exception& e) {
    ROS_FATAL("rcm: error: %s", e.what());
    return 1;
  }
  return 0;
}
