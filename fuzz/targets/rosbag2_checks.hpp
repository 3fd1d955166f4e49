#pragma once
// What a caller does with a rosbag2 recording the reader accepted: the
// recording keeps the invariants of every recording, and `rcm inspect`'s
// listing of the same path agrees that the joint topic is there.

#include <algorithm>

#include "csv_checks.hpp"
#include "rcm/io/rosbag2.hpp"

namespace rcm::fuzz {

// The topics rcm reads by default, and the force topic the seeds carry.
inline TopicReadOptions rosbag2_options() {
  TopicReadOptions o;
  o.force_topic = "/PSM1/body/measured_cf";
  o.read.min_joints = 1;
  return o;
}

inline void fuzz_rosbag2_path(const std::filesystem::path& path) {
  Rosbag2Contents contents;
  const bool listed = accepts([&] { contents = list_rosbag2_contents(path); });
  for (const MessageTime time : {MessageTime::header, MessageTime::receive}) {
    TopicReadOptions o = rosbag2_options();
    o.time = time;
    Recording rec;
    Rosbag2ReadInfo info;
    if (!accepts([&] { rec = load_rosbag2_recording(path, o, &info); })) continue;
    RCM_FUZZ_CHECK(info.messages >= rec.num_samples());
    if (listed) {
      const bool has_topic = std::any_of(contents.topics.begin(), contents.topics.end(),
                                         [&](const Rosbag2Contents::Topic& t) { return t.name == o.topic; });
      RCM_FUZZ_CHECK(has_topic);
    }
    check_accepted_recording(rec);
  }
}

}  // namespace rcm::fuzz
