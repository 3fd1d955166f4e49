#pragma once
// Tests that check a statistical property over many simulated sessions or
// seeds (coverage rates, success shares) run the same code paths many times.
// The instrumented run (`make test-sanitize`) sets RCM_STATISTICAL_TESTS=0:
// those paths run there once in the shorter tests, and the property itself is
// checked by the uninstrumented run (`make test`), where it takes a fifth of
// the time.

#include <cstdlib>
#include <cstring>

namespace rcm::test {

inline bool statistical_tests_skipped() {
  const char* env = std::getenv("RCM_STATISTICAL_TESTS");
  return env != nullptr && std::strcmp(env, "0") == 0;
}

}  // namespace rcm::test

// First statement of such a test.
#define RCM_STATISTICAL_TEST()                                                                        \
  do {                                                                                                \
    if (rcm::test::statistical_tests_skipped())                                                       \
      GTEST_SKIP() << "statistical property, checked by the uninstrumented run (RCM_STATISTICAL_TESTS=0)"; \
  } while (false)
