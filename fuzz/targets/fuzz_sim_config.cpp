// Simulator configuration files (load_config: defaults, then the file, then
// validation). An accepted configuration is written out, read back to the
// same JSON, and described as `rcm simulate --help` does.
#include <optional>

#include "fuzz_support.hpp"
#include "rcm/sim/sim_config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  using namespace rcm::sim;
  const auto path = fuzz::write_input("sim_config.json", data, size);
  std::optional<SimConfig> config;
  if (!fuzz::accepts([&] { config.emplace(load_config(path)); })) return 0;
  const nlohmann::json saved = config_to_json(*config);
  SimConfig back = make_default_config();
  if (!fuzz::accepts([&] {
        apply_config_json(back, saved, "saved");
        validate_config(back, "saved");
      }))
    fuzz::fail_property("a saved configuration loads again");
  RCM_FUZZ_CHECK(config_to_json(back) == saved);
  RCM_FUZZ_CHECK(!describe_config(*config).empty());
  return 0;
}
