// Failsafe timer: expired once no valid frame has been seen for cfg::kLinkTimeoutUs.
// Wrap-safe: the robot checks it every control period, far more often than the 35-minute horizon of
// the unsigned comparison.
#pragma once
#include <stdint.h>
#include "config.h"
#include "time_util.h"

class LinkWatchdog {
 public:
  void feed(uint32_t now_us) { last_valid_us_ = now_us; }
  bool expired(uint32_t now_us) const {
    return elapsed_us(now_us, last_valid_us_) >= cfg::kLinkTimeoutUs;
  }
  uint32_t last_valid_us() const { return last_valid_us_; }

 private:
  uint32_t last_valid_us_ = 0;
};
