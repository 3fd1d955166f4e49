#pragma once
// Internal to the sim layer: what the bench's files share.

#include <functional>
#include <vector>

namespace rcm::sim::detail {

// Runs jobs on up to `threads` threads; the first exception is rethrown. Stops
// taking jobs once an interrupt is requested (rcm/common/interrupt.hpp).
void run_parallel(std::vector<std::function<void()>>& jobs, int threads);

}  // namespace rcm::sim::detail
