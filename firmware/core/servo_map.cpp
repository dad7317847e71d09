#include "servo_map.h"

uint16_t servo_pulse_us(int16_t trim_us, bool reversed, float us_per_rad, float angle_rad) {
  const float centre = static_cast<float>(kServoCentreUs + trim_us);
  const float us = centre + (reversed ? -us_per_rad : us_per_rad) * angle_rad;
  // Compare in float before converting: a float outside uint16_t's range (or NaN) is undefined
  // when converted. NaN fails both comparisons below and lands on the centre.
  if (us >= static_cast<float>(kServoMaxUs)) return kServoMaxUs;
  if (us <= static_cast<float>(kServoMinUs)) return kServoMinUs;
  if (!(us == us)) return static_cast<uint16_t>(kServoCentreUs + trim_us);
  return static_cast<uint16_t>(us + 0.5f);
}
