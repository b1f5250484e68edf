// Minimal check harness shared by the native tests: CHECK records a failure and goes on, so one run
// reports every broken case; main() returns check_exit_code().
#pragma once
#include <cstdio>

inline int& check_failures() {
  static int failures = 0;
  return failures;
}

#define CHECK(cond)                                                                   \
  do {                                                                                \
    if (!(cond)) {                                                                    \
      std::fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);   \
      ++check_failures();                                                             \
    }                                                                                 \
  } while (0)

inline int check_exit_code() {
  if (check_failures()) std::fprintf(stderr, "%d failures\n", check_failures());
  return check_failures() ? 1 : 0;
}
