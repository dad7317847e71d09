// Build-time constants of the robot and the control stack, in one place.
#pragma once
#include <stdint.h>
#include "protocol_gen.h"

namespace cfg {

constexpr uint8_t kLinks = 6;                   // N: head, four body modules, tail
constexpr uint8_t kJoints = kLinks - 1;         // joint 1 (index 0) is the tail joint
static_assert(kJoints == eelproto::kJoints, "protocol/eelbot.toml n_joints must match the robot");

constexpr uint8_t kFirmwareMajor = 0;
constexpr uint8_t kFirmwareMinor = 1;

// Mechanical range of every joint module; references (and so servo pulses) are clamped to it.
constexpr float kJointLimitRad = 1.2f;

// The control update runs every 10 ms, the twin's physics step, so the twin and the robot sample
// the gait at the same instants.
constexpr uint32_t kControlPeriodUs = 10000UL;
constexpr uint32_t kTelemetryPeriodUs = 100000UL;  // 10 Hz, ~470 B/s of the 5760 B/s link
// Failsafe: with no valid frame for this long while running, stop undulating and straighten.
constexpr uint32_t kLinkTimeoutUs = 1000000UL;
// When straightening (Stop, failsafe) the amplitude and offset move at least this fast, so that a
// tiny configured slew rate cannot keep the robot undulating for long after the link is lost.
constexpr float kStraightenMinRateRadS = 1.0f;

}  // namespace cfg
