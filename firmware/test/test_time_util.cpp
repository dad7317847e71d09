#include "check.h"
#include "time_util.h"

TEST(elapsed_us_is_correct_across_the_micros_wrap) {
  CHECK_EQ(elapsed_us(100u, 0xFFFFFF00u), 356u);
  CHECK_EQ(elapsed_us(5000u, 1000u), 4000u);
}

TEST(deadline_reached_is_correct_across_the_micros_wrap) {
  const uint32_t deadline = 0xFFFFFFF0u + 0x20u;  // wraps to 0x10
  CHECK(!deadline_reached(0xFFFFFFF0u, deadline));
  CHECK(!deadline_reached(0x0Fu, deadline));
  CHECK(deadline_reached(0x10u, deadline));
  CHECK(deadline_reached(0x11u, deadline));
}

TEST(deadline_before_the_wrap_is_reached_after_the_wrap) {
  CHECK(deadline_reached(0x00000005u, 0xFFFFFFF0u));
  CHECK(!deadline_reached(0xFFFFFFE0u, 0xFFFFFFF0u));
}
