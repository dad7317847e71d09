#include <string.h>

#include "check.h"

namespace check {
Case*& registry() {
  static Case* head = nullptr;
  return head;
}
int& failures_in_case() {
  static int n = 0;
  return n;
}
void fail(const char* file, int line, const char* what) {
  ++failures_in_case();
  printf("    %s:%d: CHECK failed: %s\n", file, line, what);
}
}  // namespace check

// Usage: unit_tests [substring]  runs the tests whose name contains the substring (all by default).
int main(int argc, char** argv) {
  const char* filter = argc > 1 ? argv[1] : "";
  int passed = 0, failed = 0;
  for (check::Case* c = check::registry(); c != nullptr; c = c->next) {
    if (strstr(c->name, filter) == nullptr) continue;
    check::failures_in_case() = 0;
    c->fn();
    if (check::failures_in_case() == 0) {
      ++passed;
    } else {
      ++failed;
      printf("FAIL %s\n", c->name);
    }
  }
  for (check::Case* c = check::registry(); c != nullptr;) {
    check::Case* next = c->next;
    delete c;
    c = next;
  }
  printf("firmware unit tests: %d passed, %d failed\n", passed, failed);
  return failed == 0 && passed > 0 ? 0 : 1;
}
