#include "servo_map.h"

uint16_t servo_pulse_us(const ServoCalibration& cal, float alpha_rad) {
  const float us = static_cast<float>(cal.centre_us) + cal.us_per_rad * alpha_rad;
  // Compare in float before converting: a float outside uint16_t's range (or NaN) is undefined
  // when converted. NaN fails both comparisons below and lands on the centre.
  if (us >= static_cast<float>(cal.max_us)) return cal.max_us;
  if (us <= static_cast<float>(cal.min_us)) return cal.min_us;
  if (!(us == us)) return cal.centre_us;
  return static_cast<uint16_t>(us + 0.5f);
}
