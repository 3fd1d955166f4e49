#pragma once
// Replaces the global operator new with one that counts, so that a test can
// prove a per-sample path allocates nothing (STYLE 7). Include it from exactly
// one source file of a test executable: the definitions below are the
// program's replacement functions and must not be inline.

#include <atomic>
#include <cstdlib>
#include <new>

namespace rcm::test {
inline std::atomic<long> g_allocations{0};
// The largest single allocation since it was last reset: a reader must not
// allocate what a corrupt size field claims.
inline std::atomic<std::size_t> g_largest_allocation{0};
inline long get_allocation_count() { return g_allocations.load(); }
}  // namespace rcm::test

// GCC cannot see that these replacements pair malloc with free.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  ++rcm::test::g_allocations;
  std::size_t seen = rcm::test::g_largest_allocation.load();
  while (n > seen && !rcm::test::g_largest_allocation.compare_exchange_weak(seen, n)) {
  }
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop
