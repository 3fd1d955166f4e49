// The identified tissue law (rcm-tissue-law/1, load_tissue_law). An accepted
// law is evaluated, differentiated and inverted across its range as the
// three-step estimate does, and saved and loaded again.
#include <cmath>

#include <optional>

#include "fuzz_support.hpp"
#include "rcm/tissue/tissue_law.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace rcm;
  const auto path = fuzz::write_input("tissue_law.json", data, size);
  std::optional<TissueLaw> law;
  if (!fuzz::accepts([&] { law.emplace(load_tissue_law(path)); })) return 0;
  RCM_FUZZ_CHECK(law->x_min() < law->x_max());
  for (int k = 0; k <= 8; ++k) {
    const double x = law->x_min() + (law->x_max() - law->x_min()) * k / 8.0;
    const double y = law->evaluate(x);
    (void)law->derivative(x);
    const TissueInverseResult inv = law->compute_inverse(y);
    if (inv.status == TissueInverseStatus::ok) RCM_FUZZ_CHECK(inv.x >= law->x_min() && inv.x <= law->x_max());
  }
  (void)law->to_string();
  TissueLaw back = tissue_law_from_json(to_json(*law), "saved");
  RCM_FUZZ_CHECK(back.x_min() == law->x_min() && back.x_max() == law->x_max());
  RCM_FUZZ_CHECK(back.monotonicity() == law->monotonicity());
  return 0;
}
