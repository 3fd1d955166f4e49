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

// `receive_time` picks the clock; the targets take it from the input's size,
// so that mutations cover both at the cost of one read per input.
inline void fuzz_rosbag2_path(const std::filesystem::path& path, bool receive_time) {
  Rosbag2Contents contents;
  const bool listed = accepts([&] { contents = list_rosbag2_contents(path); });
  {
    TopicReadOptions o = rosbag2_options();
    o.time = receive_time ? MessageTime::receive : MessageTime::header;
    check_chunked_read([&] { return load_rosbag2_recording(path, o); },
                       [&] { return open_rosbag2_recording(path, o, 3); });
    Recording rec;
    Rosbag2ReadInfo info;
    if (!accepts([&] { rec = load_rosbag2_recording(path, o, &info); })) return;
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
