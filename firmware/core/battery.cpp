#include "battery.h"

#include "config.h"

namespace {
constexpr float kFilterTimeConstantS = 1.0f;
}  // namespace

void BatteryMonitor::reset() {
  volts_ = 0.0f;
  primed_ = false;
  low_ = false;
}

void BatteryMonitor::update(const eelproto::Settings& s, uint16_t counts, uint32_t dt_us) {
  if (s.battery_divider <= 0.0f) {
    reset();
    return;
  }
  const float v = static_cast<float>(counts) * (cfg::kAdcReferenceV / 1024.0f) * s.battery_divider;
  float k = static_cast<float>(dt_us) * (1e-6f / kFilterTimeConstantS);
  if (!primed_ || k > 1.0f) k = 1.0f;  // the first reading starts the filter
  volts_ += k * (v - volts_);
  primed_ = true;
  if (volts_ < s.battery_low_v) {
    low_ = true;
  } else if (volts_ > s.battery_low_v + s.battery_hysteresis_v) {
    low_ = false;
  }
}
