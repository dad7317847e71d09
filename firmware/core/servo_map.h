// Servo calibration: joint angle -> pulse width, from the settings (docs/firmware.md, "Settings"):
// pulse_us = 1500 + trim_us + s * servo_us_per_rad * angle_rad, s = -1 for a reversed (mirrored)
// servo, +1 otherwise, clamped to what any hobby servo accepts. The angle is clamped to the joint
// limit before it gets here. firmware/README.md says how to calibrate the trims.
#pragma once
#include <stdint.h>

constexpr uint16_t kServoCentreUs = 1500;
constexpr uint16_t kServoMinUs = 500;
constexpr uint16_t kServoMaxUs = 2500;

uint16_t servo_pulse_us(int16_t trim_us, bool reversed, float us_per_rad, float angle_rad);
