// Battery voltage through a divider on an ADC pin, filtered, and the low-voltage stop with
// hysteresis (docs/firmware.md, "Health"). The divider's ratio is the setting battery_divider (0:
// none fitted: no reading, never low).
#pragma once
#include <stdint.h>

#include "protocol_gen.h"

class BatteryMonitor {
 public:
  void reset();
  // One reading of the battery pin (ADC counts, 0..1023 over the 5 V reference), dt_us after the
  // previous one.
  void update(const eelproto::Settings& s, uint16_t counts, uint32_t dt_us);
  // Filtered voltage (time constant 1 s, so that the servos' current peaks do not stop the robot).
  float volts() const { return volts_; }
  // Below battery_low_v, until back above battery_low_v + battery_hysteresis_v.
  bool low() const { return low_; }

 private:
  float volts_ = 0.0f;
  bool primed_ = false;
  bool low_ = false;
};
