// rcm_monitor_dds: the online misalignment estimator of `rcm monitor` on a
// live dVRK over ROS 2, without ROS 2: a plain Cyclone DDS participant that
// does on the wire what a ROS 2 node does (DDS topic rt/<arm>/measured_js, type
// sensor_msgs::msg::dds_::JointState_, XCDR1, domain ROS_DOMAIN_ID), so that
// it talks to the dVRK's ROS 2 node whatever DDS that one uses. What to
// publish and log is rcm::MonitorNode (live/, shared with the ROS 1 node).
// This file reads the parameters (a ROS 2 parameters file: dds_params.cpp,
// then the flags) and takes the joint states from Cyclone; the sink that
// writes the outputs is dds_sink.cpp. Topics, QoS, parameters: docs/howto-ros2.md.
//
//   rcm_monitor_dds --session session.json --model-file free_space_model.json [--arm PSM1] [--params-file P.yaml]

#include <CLI/CLI.hpp>
#include <dds/dds.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "dds_params.hpp"
#include "dds_sink.hpp"
#include "rcm/common/command_line.hpp"
#include "rcm/common/error.hpp"
#include "rcm/live/monitor_node.hpp"
#include "support/program_main.hpp"
#include "ros2_msgs.h"

namespace {

using namespace rcm::dds_node;

int run(int argc, char** argv) {
  rcm::MonitorNodeParameters p;
  std::string node_name = "rcm_monitor_dds";
  const std::string params_file = find_params_file(argc, argv);
  for (int i = 1; i < argc; ++i)  // the node name decides which key of the file is read
    if (std::string(argv[i]) == "--node-name" && i + 1 < argc) node_name = argv[i + 1];
  if (!params_file.empty()) read_params_file(params_file, node_name, p);

  CLI::App app{"rcm_monitor_dds: the online RCM misalignment estimator on a live dVRK over ROS 2 (DDS)"};
  std::string joint_names, params_file_flag;
  int domain = -1;
  bool best_effort = false;
  app.add_option("--params-file", params_file_flag, "ROS 2 parameters file (YAML); flags override its values");
  app.add_option("--node-name", node_name, "the node's name: the key read in the parameters file")->capture_default_str();
  app.add_option("--session", p.session, "rcm-session/1 manifest (calibration, q0)");
  app.add_option("--model-file", p.model_file, "saved free-space model (free_space_model.json of rcm run)");
  app.add_option("--tissue-model-file", p.tissue_model_file, "tissue_model.json of rcm setup (default: identified again)");
  app.add_option("--arm", p.arm, "arm namespace: subscribes <arm>/measured_js, publishes <arm>/rcm/...")->capture_default_str();
  app.add_option("--joint-names", joint_names, "joint order of the model, comma separated (default: the first message's)");
  app.add_option("--alarm-force-n", p.alarm_force_n, "force alarm threshold (N)")->capture_default_str();
  app.add_option("--onset-threshold", p.onset_threshold, "onset detector threshold")->capture_default_str();
  app.add_option("--publish-every", p.publish_every, "publish every n-th estimate")->capture_default_str();
  app.add_option("--queue-size", p.queue_size, "history depth of the subscription and the estimate topics")->capture_default_str();
  app.add_option("--base-frame", p.base_frame, "frame_id of incision_force (default <arm>_base)");
  app.add_option("--incision-frame", p.incision_frame, "frame_id of misalignment (default <arm>_incision)");
  app.add_flag("--dedupe", p.dedupe, "drop repeated samples in the session's recordings");
  app.add_option("--seed", p.seed, "seed of the joint method's setup")->capture_default_str();
  app.add_option("--status-period-s", p.status_period_s, "seconds between status lines (0: none)")->capture_default_str();
  app.add_option("--tolerance-m", p.correction.tolerance_m, "correction: aligned within this distance (m)")
      ->capture_default_str();
  app.add_option("--compensate-limit-m", p.correction.compensate_limit_m,
                 "correction: software RCM shifts up to this, beyond it re-docking advice (m)")
      ->capture_default_str();
  app.add_option("--max-shift-rate-m-per-s", p.correction.max_rate_m_per_s,
                 "correction: speed of the software RCM shift (m/s)")
      ->capture_default_str();
  app.add_option("--jump-threshold", p.jump_threshold,
                 "the estimator's change-point test for an incision that jumps (nats; 0: off)")
      ->capture_default_str();
  app.add_flag("--software-rcm", p.software_rcm,
               "the arm shifts its RCM in software: command the shift on <arm>/rcm/shift and take it as in effect");
  app.add_option("--domain", domain, "DDS domain (default: ROS_DOMAIN_ID, else 0)");
  app.add_flag("--best-effort", best_effort,
               "subscribe best-effort (matches best-effort publishers; the dVRK's are reliable)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return rcm::exit_on_parse_error(app, e);
  }
  const std::string source = params_file.empty() ? "command line" : "command line / " + params_file;
  if (!joint_names.empty()) p.joint_names = rcm::parse_joint_names(joint_names, param_location(source, "--joint-names"));
  p.check([&](const std::string& name) { return param_location(source, name); });
  domain = get_domain(domain, source);

  std::string models;
  std::unique_ptr<rcm::OnlinePipeline> pipeline = rcm::make_monitor_pipeline(p, &models);

  const dds_entity_t participant = check(dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr),
                                         "create participant");
  DdsSink sink(participant, p);
  sink.log(rcm::LogLevel::info, "rcm: " + models);
  rcm::MonitorNode node(p, std::move(pipeline), rcm::LiveMonitor::ZeroStamp::invalid, sink);

  const std::string input = "rt/" + p.get_input_topic();
  const dds_entity_t topic = check(
      dds_create_topic(participant, &sensor_msgs_msg_dds__JointState__desc, input.c_str(), nullptr, nullptr), "topic");
  // The estimator wants every sample: a history as deep as the outputs' lets
  // the node fall behind for a while (another process, a slow disk) without
  // Cyclone overwriting samples it has not taken. DDS reports no sample it
  // overwrote or lost (Cyclone 0.10's sample-lost status stays at zero): the
  // monitor counts them as missing from the stamps (StreamGaps).
  dds_qos_t* qos = make_qos(best_effort ? DDS_RELIABILITY_BEST_EFFORT : DDS_RELIABILITY_RELIABLE, p.queue_size,
                            DDS_DURABILITY_VOLATILE);
  const dds_entity_t reader = check(dds_create_reader(participant, topic, qos, nullptr), "reader");
  dds_delete_qos(qos);
  check(dds_set_status_mask(reader, DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS | DDS_SUBSCRIPTION_MATCHED_STATUS |
                                        DDS_DATA_AVAILABLE_STATUS),
        "status");
  const dds_entity_t waitset = check(dds_create_waitset(participant), "waitset");
  check(dds_waitset_attach(waitset, reader, reader), "attach");
  node.start(input + " (domain " + std::to_string(domain) + (best_effort ? ", best effort)" : ", reliable)"));

  constexpr std::size_t kBatch = 64;
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  JointStateBuffer buffer;
  const rcm::JointStateView view = buffer.view();
  while (!rcm::dds_node::is_stop_requested()) {
    const dds_return_t woke = dds_waitset_wait(waitset, nullptr, 0, DDS_MSECS(100));
    if (woke < 0) dds_fail("wait", woke);
    std::uint32_t status = 0;
    if (dds_take_status(reader, &status, DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS) == DDS_RETCODE_OK && status)
      sink.log(rcm::LogLevel::warn, "rcm: a publisher on " + input + " does not match this subscription's QoS" +
                                        (best_effort ? "" : " (a best-effort publisher? restart with --best-effort)"));
    // Samples sent before the subscription matches their writer are not
    // delivered (VOLATILE): say when the robot's publisher comes and goes.
    dds_subscription_matched_status_t matched;
    if (dds_get_subscription_matched_status(reader, &matched) == DDS_RETCODE_OK && matched.current_count_change != 0)
      sink.log(rcm::LogLevel::info,
               "rcm: " + std::to_string(matched.current_count) + " publisher(s) matched on " + input);
    while (true) {
      for (void*& s : samples) s = nullptr;  // null buffers: Cyclone lends its samples
      const dds_return_t n = dds_take(reader, samples, infos, kBatch, kBatch);
      if (n < 0) dds_fail("take", n);
      for (dds_return_t i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(samples[i]);
        buffer.assign(m);
        const std::int64_t stamp =
            static_cast<std::int64_t>(m.header.stamp.sec) * 1000000000 + static_cast<std::int64_t>(m.header.stamp.nanosec);
        node.compute_message(view, stamp, dds_time());
      }
      if (n > 0) dds_return_loan(reader, samples, n);
      if (n < static_cast<dds_return_t>(kBatch)) break;
    }
  }
  sink.finish();
  std::fputs(node.get_summary().c_str(), stderr);
  std::fputs(sink.get_summary().c_str(), stderr);
  dds_delete(participant);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcm::dds_node::run_program("rcm_monitor_dds", argc, argv, run); }
