// ROS 1 bags (load_bag_recording, rcm::ros), with the dVRK's joint topic and
// a force topic, by header stamp or by the bag's receive time.
#include "csv_checks.hpp"
#include "rcm/ros/bag_reader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  const auto path = fuzz::write_input("fuzz.bag", data, size);
  // The clock from the input's size: mutations cover both, one read per input.
  BagReadOptions o;
  o.force_topic = "/PSM1/body/measured_cf";
  o.read.min_joints = 1;
  o.time = size % 2 == 1 ? MessageTime::receive : MessageTime::header;
  fuzz::check_chunked_read([&] { return load_bag_recording(path, o); }, [&] { return open_bag_recording(path, o, 3); });
  Recording rec;
  BagReadInfo info;
  if (!fuzz::accepts([&] { rec = load_bag_recording(path, o, &info); })) return 0;
  RCM_FUZZ_CHECK(info.messages >= rec.num_samples());
  fuzz::check_accepted_recording(rec);
  return 0;
}
