// A minimal test harness (no third-party framework on the build machines): TEST registers a
// function, CHECK* record failures with file:line and carry on, main() prints a summary.
#pragma once
#include <math.h>
#include <stdio.h>

namespace check {
struct Case {
  const char* name;
  void (*fn)();
  Case* next;
};
Case*& registry();
int& failures_in_case();
void fail(const char* file, int line, const char* what);
struct Registrar {
  Registrar(const char* name, void (*fn)()) {
    static Case* tail = nullptr;
    Case* c = new Case{name, fn, nullptr};
    if (tail == nullptr) registry() = c; else tail->next = c;
    tail = c;
  }
};
}  // namespace check

#define TEST(name)                                            \
  static void name();                                         \
  static check::Registrar name##_registrar(#name, name);      \
  static void name()

#define CHECK(cond) \
  do { if (!(cond)) check::fail(__FILE__, __LINE__, #cond); } while (0)

#define CHECK_EQ(a, b) \
  do { if (!((a) == (b))) check::fail(__FILE__, __LINE__, #a " == " #b); } while (0)

#define CHECK_NEAR(a, b, tol)                                                   \
  do {                                                                          \
    const double check_a_ = (a), check_b_ = (b);                                \
    if (!(fabs(check_a_ - check_b_) <= (tol))) {                                \
      char check_msg_[256];                                                     \
      snprintf(check_msg_, sizeof check_msg_, "%s ~ %s: %.9g vs %.9g (tol %g)", #a, #b, \
               check_a_, check_b_, static_cast<double>(tol));                   \
      check::fail(__FILE__, __LINE__, check_msg_);                              \
    }                                                                           \
  } while (0)
