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
inline long get_allocation_count() { return g_allocations.load(); }
}  // namespace rcm::test

void* operator new(std::size_t n) {
  ++rcm::test::g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
