// Wrap-safe time arithmetic for a 32-bit microsecond clock (micros() wraps every 71.6 minutes).
// Every comparison of times in the firmware goes through these helpers: an expression such as
// `now_us >= deadline_us` is wrong for a few milliseconds around each wrap.
#pragma once
#include <stdint.h>

// Microseconds from `since_us` to `now_us`, correct across one wrap (valid up to 2^32 - 1 us).
inline uint32_t elapsed_us(uint32_t now_us, uint32_t since_us) { return now_us - since_us; }

// True once `now_us` has reached `deadline_us`, for deadlines within +-35.8 minutes of now.
inline bool deadline_reached(uint32_t now_us, uint32_t deadline_us) {
  return static_cast<int32_t>(now_us - deadline_us) >= 0;
}
