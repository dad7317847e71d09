// Servo calibration: joint angle -> pulse width. One entry per joint, joint 1 (tail) first.
// pulse_us = centre_us + us_per_rad * alpha_rad, then clamped to [min_us, max_us].
// A servo mounted mirrored gets a negative us_per_rad. Measure centre_us on each module (the pulse
// that makes the joint straight) and put it here; firmware/README.md says how.
#pragma once
#include <stdint.h>
#include "config.h"

struct ServoCalibration {
  uint16_t centre_us;
  float us_per_rad;   // 2000 us over pi rad for a 500..2500 us, 180 degree hobby servo
  uint16_t min_us;
  uint16_t max_us;
};

// 636.6 us/rad; the joint limit of 1.2 rad gives 736..2264 us; min/max add a margin for the trim.
constexpr ServoCalibration kNominalServo{1500, 636.6f, 700, 2300};

// One row per servo, as mounted on this robot: hardware, so listed by hand.
constexpr ServoCalibration kServoCalibration[] = {
    kNominalServo, kNominalServo, kNominalServo, kNominalServo, kNominalServo,
};
static_assert(sizeof(kServoCalibration) / sizeof(kServoCalibration[0]) == cfg::kJoints,
              "one servo calibration per joint: protocol/eelbot.toml n_joints changed, so add or "
              "remove rows here");

uint16_t servo_pulse_us(const ServoCalibration& cal, float alpha_rad);
