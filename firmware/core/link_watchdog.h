// Failsafe timer and link-loss envelope (docs/firmware.md, "Failsafe"), from the time of the last
// valid frame from the host. Wrap-safe: the robot checks it every control period, far more often
// than the 35-minute horizon of the unsigned comparison.
#pragma once
#include <stdint.h>
#include "config.h"
#include "time_util.h"

class LinkWatchdog {
 public:
  void feed(uint32_t now_us) { last_valid_us_ = now_us; }
  // FAILSAFE is due (while running): cfg::kLinkTimeoutUs without a valid frame.
  bool expired(uint32_t now_us) const {
    return elapsed_us(now_us, last_valid_us_) >= cfg::kLinkTimeoutUs;
  }
  // The largest amplitude and |offset| the gait may have now, rad: unbounded for a while, then
  // closing at cfg::kFadeRateRadS to 0 at cfg::kLinkRestUs after the last valid frame, so that the
  // joints are straight by then however large the gait was.
  float envelope_rad(uint32_t now_us) const {
    const uint32_t quiet_us = elapsed_us(now_us, last_valid_us_);
    if (quiet_us >= cfg::kLinkRestUs) return 0.0f;
    return static_cast<float>(cfg::kLinkRestUs - quiet_us) * (cfg::kFadeRateRadS * 1e-6f);
  }
  uint32_t last_valid_us() const { return last_valid_us_; }

 private:
  uint32_t last_valid_us_ = 0;
};
